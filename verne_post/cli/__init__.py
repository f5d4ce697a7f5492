"""Command line: ``verne-post part.cls -o part.nc`` and the other commands, one module each.

A thin layer: parse options, call the library, print. mm and degrees at this interface
(``--radians`` switches angles to radians); user mistakes exit with a one-line message.
Importing a command's module registers it on :func:`main`.
"""

from . import batch, calibrate, check, kinematics, linuxcnc, machine, place, post, toolpath, verify, workspace  # noqa: F401  (registers the commands)
from .main import main

__all__ = ["main"]
