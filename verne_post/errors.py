"""User-facing errors: each carries the file, line and reason and prints as one line."""

from __future__ import annotations

import re
import unicodedata

#: Longest quoted token kept whole in a message (characters after escaping); longer ones are cut.
MAX_TOKEN_CHARS = 40

#: Longest reason kept whole: a message stays one line whatever the input held. The project's own
#: reasons (with their remedies) stay well within it; input in them is cut as a quoted token is.
MAX_REASON_CHARS = 1000

# A token quoted in a message: 'text' not inside a word (so "machine's" does not open one).
_QUOTED = re.compile(r"(?<!\w)'(.*?)'(?!\w)", re.DOTALL)

# Characters that would break a message over lines or act on a terminal: C0/C1 controls,
# the Unicode line and paragraph separators and the bidirectional/format controls.
_UNPRINTABLE_CATEGORIES = ("Cc", "Zl", "Zp", "Cf", "Cs", "Co", "Cn")


def _escape_char(ch: str) -> str:
    if unicodedata.category(ch) not in _UNPRINTABLE_CATEGORIES:
        return ch
    code = ord(ch)
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}" if code < 0x10000 else f"\\U{code:08x}"


def _escaped(text: str, limit: int | None = None) -> str:
    """``text`` with every unprintable character escaped, cut to ``limit`` characters with '...'."""
    pieces = [_escape_char(ch) for ch in text]
    if limit is None or sum(map(len, pieces)) <= limit:
        return "".join(pieces)
    kept, size = [], 0
    for piece in pieces:  # never cut inside an escape sequence
        if size + len(piece) > limit - 3:
            break
        kept.append(piece)
        size += len(piece)
    return "".join(kept) + "..."


def one_line(text: str, limit: int | None = None) -> str:
    """``text`` as one printable line: control and line-separator characters escaped (a newline
    reads ``\\x0a``), each quoted token cut to :data:`MAX_TOKEN_CHARS`, the whole to ``limit``
    by its middle: the start says what and where, the end what to do about it."""
    out, position = [], 0
    for match in _QUOTED.finditer(text):
        out.append(_escaped(text[position:match.start()]))
        out.append(f"'{_escaped(match.group(1), MAX_TOKEN_CHARS)}'")
        position = match.end()
    out.append(_escaped(text[position:]))
    line = "".join(out)
    if limit is None or len(line) <= limit:
        return line
    head = (limit - 5) // 2
    return f"{line[:head]} ... {line[len(line) - (limit - 5 - head):]}"


def quote(token: object) -> str:
    """``token`` in single quotes for a message (shortened and escaped by :func:`one_line`)."""
    return f"'{_escaped(str(token), MAX_TOKEN_CHARS)}'"


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
        return _escaped(where) + one_line(self.reason, MAX_REASON_CHARS)


class InputError(UserError):
    """Malformed input data (CL file, CSV, YAML, command-line values): exit code 2."""


class OutputError(UserError):
    """An output cannot be written (missing or read-only folder, full disk): exit code 2."""


class CheckError(UserError):
    """The program is well-formed but the machine cannot run it (limits, reach): exit code 3."""

    exit_code = 3


class HelperError(UserError):
    """A helper process of the pipeline stopped before its work was done (killed, out of memory):
    nothing is written; exit code 1, as for an aborted run."""

    exit_code = 1
