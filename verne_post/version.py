"""The version of verne-post, in a module of its own: the modules that write it into their
outputs (the G-code header, the JSON report) import it without importing the whole package."""

__version__ = "0.2.0"
