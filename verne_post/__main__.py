"""``python -m verne_post`` is the ``verne-post`` command."""

from .cli import main

main()
