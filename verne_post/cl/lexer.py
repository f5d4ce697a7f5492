"""Logical records of an APT / CLSF file: continuations joined, comments removed, line numbers kept.

The lexer knows the *syntax* every CAM family shares and nothing of what a record means:

- ``WORD/args`` (``WORD / args`` with any spaces or TABs); a record without a slash
  (``RAPID``, ``END``, ``GOHOME``) has empty args; multi-word names (``TOOL PATH``) are folded
  to single spaces and upper-cased.
- ``$$`` starts a comment that runs to the end of the line. A ``$`` at the end of the remaining
  text continues the record on the next line (blank and comment-only lines inside are skipped).
- Comment records that end in ``$`` continue too: Creo's ``$$-> CSYS / ... $`` runs onto plain
  lines of numbers that belong to the comment, not to a record of their own.
- ``PPRINT``, ``PARTNO`` and ``INSERT`` carry free text, taken literally (a ``$`` or ``$$`` in it is
  text); Pro/ENGINEER writes ``PARTNO`` with a space instead of the slash.
- NX "Information listing" headers (before the first record) and ``Tool Path Listing has N lines``
  trailers are skipped; their fields are TAB- or space-separated.
- A plain line of numbers after a ``GOTO`` (or after another such line) is one more point of it:
  PTC Creo help, "CL Output for Circular Interpolation": ``GOTO / x, y, z`` then lines ``x, y, z``,
  "the last line specifying the arc end point". It is yielded as a ``GOTO`` record with
  ``follows_goto`` set, so the reader can keep such points on the arc they belong to.

Each record is yielded as a :class:`Record` (word, argument text, 1-based first line);
:func:`record_runs` yields the same records with runs of plain one-line ``GOTO/`` records
gathered into a :class:`GotoRun` (most of any file), for the reader's bulk route.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator
from typing import NamedTuple

__all__ = ["TEXT_RECORDS", "GotoRun", "Record", "iter_lines", "record_runs", "records", "split_lines"]

TEXT_RECORDS = frozenset({"PPRINT", "PARTNO", "INSERT"})

# NX "Information listing" header lines (only before the first APT record) and trailer lines.
_HEADER_RE = re.compile(
    r"(?:=+|-{3,}|Information listing created by\s*:.*|(?:Date|Current work part|Node name)\s*:.*)\Z",
    re.IGNORECASE,
)
_TRAILER_RE = re.compile(r"(?:Tool Path Listing has \d+ lines\.?|=+)\Z", re.IGNORECASE)
_TEXT_HEAD_RE = re.compile(r"(PPRINT|PARTNO|INSERT)(?:[ \t]*/|[ \t]+|\Z)", re.IGNORECASE)
_NUMBER = r"[ \t]*[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?[ \t]*"
_POINT_RE = re.compile(rf"{_NUMBER}(?:,{_NUMBER}){{2,}}\Z")  # a line of three or more numbers


class Record(NamedTuple):
    """One logical record: ``word`` upper-case (``"GOTO"``, ``"TOOL PATH"``), ``args`` after the
    slash; ``follows_goto``: a point on a plain line of numbers after a GOTO (module docstring)."""

    word: str
    args: str
    line: int
    follows_goto: bool = False


class GotoRun(NamedTuple):
    """Consecutive one-line ``GOTO/`` records (only blank, comment or skipped lines between them):
    their argument texts and line numbers."""

    args: list[str]
    lines: list[int]

    def records(self, start: int = 0) -> Iterator[Record]:
        """Its records from the ``start``-th on."""
        return (Record("GOTO", a, n) for a, n in zip(self.args[start:], self.lines[start:], strict=True))


#: GOTO records gathered into one run at most (memory stays bounded on a file of millions).
_RUN = 4096

#: Characters of text split into lines at once (:func:`iter_lines`).
_BLOCK = 1 << 20


def iter_lines(text: str) -> Iterator[str]:
    """Lines of ``text`` with LF, CRLF or CR line ends, without a trailing empty line, a block of
    text at a time (the lines of a large file are never all in memory at once)."""
    start = 0
    while start < len(text):
        cut = text.find("\n", start + _BLOCK)
        end = len(text) if cut < 0 else cut + 1
        block = text[start:end]
        if "\r" in block:
            block = block.replace("\r\n", "\n").replace("\r", "\n")
        lines = block.split("\n")
        if lines[-1] == "":  # the block ends with its last line's newline
            lines.pop()
        yield from lines
        start = end


def split_lines(text: str) -> list[str]:
    """Lines of ``text`` with CRLF or CR line ends, without a trailing empty line."""
    return list(iter_lines(text))


def _make(body: str, line: int) -> Record | None:
    s = body.strip()
    if not s:
        return None
    head, _sep, args = s.partition("/")
    return Record(" ".join(head.split()).upper(), args, line)


def records(lines: Iterable[str]) -> Iterator[Record]:
    """The logical records of ``lines`` in file order (see the module docstring)."""
    for item in record_runs(lines):
        if isinstance(item, GotoRun):
            yield from item.records()
        else:
            yield item


def record_runs(lines: Iterable[str]) -> Iterator[Record | GotoRun]:
    """:func:`records`, with the plain one-line GOTOs gathered into runs (:class:`GotoRun`)."""
    pending: list[str] | None = None  # parts of a record continued with '$'
    pending_line = 0
    in_comment = False  # a '$$' comment continued with '$'
    seen_record = False
    run_args: list[str] = []
    run_lines: list[int] = []
    after_goto = False  # the last record was a GOTO (or one of its points)
    for lineno, raw in enumerate(lines, 1):
        if in_comment:
            # Creo continues a '$$->' comment onto plain lines of numbers; a record ends it.
            s = raw.strip()
            if not s or s[0] in "0123456789+-.":
                in_comment = s.endswith("$")
                continue
            in_comment = False
        if pending is None and raw[:5] == "GOTO/" and "$" not in raw:
            seen_record = after_goto = True
            run_args.append(raw[5:])  # the common case, kept cheap
            run_lines.append(lineno)
            if len(run_args) >= _RUN:
                yield GotoRun(run_args, run_lines)
                run_args, run_lines = [], []
            continue
        record = None
        if pending is None:
            s = raw.strip()
            if not s:
                continue
            if s.startswith("$$"):
                in_comment = s.endswith("$") and not s.endswith("$$")
                continue
            text = _TEXT_HEAD_RE.match(s)
            if text is not None:
                record = Record(text.group(1).upper(), s[text.end():].strip(), lineno)
            elif _TRAILER_RE.match(s) or (not seen_record and _HEADER_RE.match(s)):
                continue
        if record is None:
            cut = raw.find("$$")
            body = (raw if cut < 0 else raw[:cut]).rstrip()
            if body.endswith("$"):
                if pending is None:
                    pending, pending_line = [], lineno
                pending.append(body[:-1])
                continue
            line = lineno
            if pending is not None:
                if not body.strip():
                    continue  # blank or comment-only line inside a continued record
                pending.append(body)
                body, line, pending = "".join(pending), pending_line, None
            if after_goto and line == lineno and _POINT_RE.match(body):
                record = Record("GOTO", body.strip(), line, follows_goto=True)
            else:
                record = _make(body, line)
            if record is None:
                continue
        seen_record = True
        after_goto = record.word == "GOTO"
        if run_args:  # the GOTOs before this record first
            yield GotoRun(run_args, run_lines)
            run_args, run_lines = [], []
        yield record
    if run_args:
        yield GotoRun(run_args, run_lines)
    if pending is not None:
        yield Record("$", "", pending_line)  # an unfinished continuation: the reader reports it
