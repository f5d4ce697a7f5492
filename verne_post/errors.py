"""User-facing errors: each carries the file, line and reason and prints as one line."""

from __future__ import annotations


class UserError(Exception):
    """A mistake in the user's input (file, option or configuration), never a bug.

    The CLI prints ``str(error)`` as one line on stderr and exits with ``exit_code``.
    """

    exit_code = 2

    def __init__(self, reason: str, source: str | None = None, line: int | None = None) -> None:
        self.reason = reason
        self.source = source
        self.line = line
        super().__init__(self.__str__())

    def __str__(self) -> str:
        where = ""
        if self.source is not None:
            where = f"{self.source}:{self.line}: " if self.line is not None else f"{self.source}: "
        return f"{where}{self.reason}"


class InputError(UserError):
    """Malformed input data (CL file, CSV, YAML, command-line values): exit code 2."""


class CheckError(UserError):
    """The program is well-formed but the machine cannot run it (limits, reach): exit code 3."""

    exit_code = 3
