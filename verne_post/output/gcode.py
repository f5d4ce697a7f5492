"""Write a joint-space program as G-code for the VERNE controller.

The controller drives the joints directly: ``X Y Z`` are the slider positions rho1, rho2, rho3
(mm), ``A`` the table tilt theta1 and ``C`` the rotary table theta2 (degrees, written as they
accumulate, never wrapped to 0..360); ``B`` is never written. The program's first move, from
wherever the machine stands, is ``G0``; every other block is ``G1`` in inverse-time mode
(``G93``) with an ``F`` word on every block, ``F = 60 / duration`` (1/min), the blocks of moves
between cuts (rapids, retracts, tool changes: verne_post.motion.safe_motion) marked ``(RAPID)``. Layout::

    %
    (PART name)
    (header lines)
    G21 G90 G17 G40 G49 G94
    (TOOL 1 LENGTH 120.0000 DELTA 0.0000)
    T1 M6
    S12000 M3
    M8
    G0 X.. Y.. Z.. A.. C..
    G93
    G1 X.. Y.. Z.. A.. C.. F.. (RAPID)
    ...
    G1 X.. Y.. Z.. A.. C.. F..
    ...
    M5 M9
    G94
    M30
    %

Numbers have fixed decimals (``GcodeFormat``), never ``-0``. Motion blocks are formatted with
numpy byte arithmetic, a chunk of blocks at a time, not one Python format call per block.
Output is deterministic (no dates). Checked against LinuxCNC's interpreter (``verne_post.verify.rs274``).
"""

from __future__ import annotations

import itertools
import os
import re
import unicodedata
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from verne_post.cl.toolpath import Comment, Coolant, Dwell, Event, Spindle, Stop, ToolChange
from verne_post.errors import CheckError
from verne_post.output.atomic import atomic_write
from verne_post.output.numbers import fixed_field, scaled_int

__all__ = [
    "MAX_COMMENT_CHARS",
    "PREAMBLE",
    "RAPID_MARK",
    "FeedRateError",
    "GcodeFormat",
    "GcodeWriter",
    "Program",
    "comment_text",
    "format_program",
    "program_text",
    "with_header_line",
    "write_program",
    "write_text",
]

#: Modal preamble: mm, absolute, XY plane, no cutter compensation, no tool length offset (the
#: tool length is already in the joints), units/min feed until the first feed block selects G93.
PREAMBLE = "G21 G90 G17 G40 G49 G94"

#: Longest comment text written (LinuxCNC rejects lines over 252 characters).
MAX_COMMENT_CHARS = 200

# Blocks formatted per numpy batch: bounds the temporary arrays (a few MB) and lets
# write_program stream a 10^6-block program.
_CHUNK = 1 << 15

# Largest |value| * 10**decimals written: beyond 2**53 a float no longer holds every integer.
_MAX_SCALED = 1e15

# LinuxCNC gives comments starting with these words a meaning ("(MSG, ...)", "(ABORT, ...)",
# "(LOGOPEN, file)", "(PYRUN, ...)", "(PROBEOPEN file)", ...): such free text is neutralised.
_ACTIVE_COMMENT = re.compile(r"^\s*(msg|debug|print|log|abort|py|probe)", re.IGNORECASE)

# Non-ASCII characters common in shop texts that have no ASCII decomposition.
_ASCII_FALLBACK = {
    "ß": "ss",
    "Ø": "O",
    "ø": "o",
    "Æ": "AE",
    "æ": "ae",
    "Œ": "OE",
    "œ": "oe",
    "Ł": "L",
    "ł": "l",
    "Đ": "D",
    "đ": "d",
    "–": "-",
    "—": "-",
    "‘": "'",
    "’": "'",
    "“": '"',
    "”": '"',
    "°": " deg",
    "×": "x",
    "±": "+/-",
    "µ": "u",
    "€": "EUR",
}


@dataclass(frozen=True)
class GcodeFormat:
    """Number formatting and block numbering, from the machine YAML.

    ``linear_decimals`` for X Y Z (mm), ``angular_decimals`` for A C (degrees), ``feed_decimals``
    for the inverse-time F word (1/min). With ``block_numbers`` every block line (not ``%`` nor a
    pure comment line) starts with ``N<k>``, k = step, 2*step, ...
    """

    linear_decimals: int = 4
    angular_decimals: int = 4
    feed_decimals: int = 5
    block_numbers: bool = False
    block_number_step: int = 10


@dataclass(frozen=True)
class Program:
    """A joint-space program, one entry per output block.

    - ``joints`` (M, 5): end position of each block: rho1, rho2, rho3 in mm, theta1, theta2 in
      radians.
    - ``rapid`` (M,) bool: the block is a G0 (else a G1 block in inverse time): positioning
      from where the machine stands, at the controller's speeds.
    - ``duration`` (M,) s: duration of each G1 block, > 0 (ignored on G0).
    - ``between`` (M,) bool or None: G1 blocks of a move between cuts, planned at the joint limits
      (a rapid kept on its CL line, a retract, reorientation or approach), marked ``(RAPID)``.
    - ``line`` (M,): CL source line of each block, for error messages.
    - ``events``: non-motion records; ``event.index`` is the block they precede (M: at the end).
    - ``header``: provenance comment lines (no dates), e.g. ``"MACHINE verne.yaml"``.
    - ``tool_lengths``: tool -> (tool length mm, Delta mm), for the tool-change comment.
    """

    joints: np.ndarray
    rapid: np.ndarray
    duration: np.ndarray
    line: np.ndarray
    events: tuple[Event, ...] = ()
    part_name: str | None = None
    header: tuple[str, ...] = ()
    tool_lengths: dict[int, tuple[float, float]] | None = None
    between: np.ndarray | None = None


#: The comment that ends a G1 block of a move between cuts: the controller runs it as written
#: (G93, so the planned time), and a reader tells it from a cut (verne_post.verify.gcode_reader).
RAPID_MARK = "(RAPID)"


class FeedRateError(CheckError, ValueError):
    """A feed block whose inverse-time F word cannot be written (rounds to 0 or overflows)."""


# --------------------------------------------------------------------------------------------
# scalar helpers (events, comments)


def comment_text(text: str, max_chars: int = MAX_COMMENT_CHARS) -> str:
    """``text`` made safe inside a G-code ``( )`` comment.

    ASCII only (accents dropped, a few shop characters such as ``Ø ß – °`` spelled out, any other
    character becomes ``?``), parentheses become ``[ ]``,
    control characters and runs of white space become one space, at most ``max_chars``
    characters, and a leading word LinuxCNC would act on (MSG, DEBUG, PRINT, LOG..., ABORT,
    PY..., PROBE...) is prefixed with ``- `` so the comment stays a comment.
    """
    kept: list[str] = []
    for ch in text:
        if ch.isascii():
            kept.append(ch)
            continue
        fallback = _ASCII_FALLBACK.get(ch)
        if fallback is not None:
            kept.append(fallback)
            continue
        decomposed = unicodedata.normalize("NFKD", ch).encode("ascii", "ignore").decode("ascii")
        kept.append(decomposed or ("" if unicodedata.combining(ch) else "?"))
    ascii_text = "".join(kept)
    cleaned = ascii_text.replace("(", "[").replace(")", "]")
    cleaned = " ".join("".join(c if c.isprintable() else " " for c in cleaned).split())
    if _ACTIVE_COMMENT.match(cleaned):
        cleaned = "- " + cleaned
    if len(cleaned) > max_chars:
        cleaned = cleaned[: max_chars - 3].rstrip() + "..."
    return cleaned


def _fixed(value: float, decimals: int) -> str:
    """``value`` with exactly ``decimals`` decimals, ``-0`` written as ``0``."""
    text = f"{value:.{decimals}f}"
    if text.startswith("-") and not text.strip("-0."):
        text = text[1:]
    return text


def _plain(value: float, decimals: int = 2) -> str:
    """``value`` rounded to ``decimals``, trailing zeros and point dropped (spindle speed)."""
    text = _fixed(value, decimals)
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    return text


def _event_lines(event: Event, program: Program, fmt: GcodeFormat) -> list[tuple[str, bool]]:
    """G-code lines for one event as ``(text, is_block)``; comment lines are not blocks."""
    where = f"CL line {event.line}"
    if isinstance(event, ToolChange):
        tool = int(event.tool)
        if tool < 0:
            raise ValueError(f"{where}: negative tool number {tool}")
        lengths = (program.tool_lengths or {}).get(tool)
        if lengths is None:
            if tool != 0:
                raise ValueError(f"{where}: no tool length given for tool {tool} (Program.tool_lengths)")
            return [(f"T{tool} M6", True)]
        length, delta = lengths
        if not (np.isfinite(length) and np.isfinite(delta)):
            raise ValueError(f"{where}: tool {tool} length {length} / Delta {delta} is not finite")
        dec = fmt.linear_decimals
        note = (f"(TOOL {tool} LENGTH {_fixed(length, dec)} DELTA {_fixed(delta, dec)})", False)
        # Tool 0: the CL file gave tool data but no tool number; T0 M6 would unload the spindle.
        return [note] if tool == 0 else [note, (f"T{tool} M6", True)]
    if isinstance(event, Spindle):
        if event.direction == "OFF":
            return [("M5", True)]
        rpm = float(event.rpm)
        if not (np.isfinite(rpm) and rpm > 0):
            raise ValueError(f"{where}: spindle speed {rpm} rpm must be > 0")
        code = {"CW": "M3", "CCW": "M4"}.get(event.direction)
        if code is None:
            raise ValueError(f"{where}: unknown spindle direction {event.direction!r}")
        return [(f"S{_plain(rpm)} {code}", True)]
    if isinstance(event, Coolant):
        code = {"ON": "M8", "FLOOD": "M8", "THRU": "M8", "MIST": "M7", "OFF": "M9"}.get(event.mode)
        if code is None:
            raise ValueError(f"{where}: unknown coolant mode {event.mode!r}")
        return [(code, True)]
    if isinstance(event, Comment):
        text = comment_text(event.text)
        return [(f"({text})", False)] if text else []
    if isinstance(event, Stop):
        return [("M1" if event.optional else "M0", True)]
    if isinstance(event, Dwell):
        seconds = float(event.seconds)
        if not (np.isfinite(seconds) and seconds >= 0):
            raise ValueError(f"{where}: dwell {seconds} s must be >= 0")
        return [(f"G4 P{_plain(seconds, 3)}", True)]
    raise TypeError(f"unknown event type {type(event).__name__}")


# --------------------------------------------------------------------------------------------
# vectorised number formatting


def _motion_text(
    joints_out: np.ndarray,
    rapid: np.ndarray,
    f_scaled: np.ndarray,
    block_numbers: np.ndarray | None,
    fmt: GcodeFormat,
    between: np.ndarray | None = None,
) -> tuple[str, np.ndarray]:
    """Motion blocks of one chunk as one string (lines ending in ``\\n``) and line offsets.

    ``joints_out`` (n, 5) in mm / degrees; ``f_scaled`` (n,) F * 10**feed_decimals (ignored on
    rapids); ``block_numbers`` (n,) or None. Returns the text and (n + 1,) start offsets.
    """
    n = joints_out.shape[0]
    parts: list[np.ndarray] = []
    if block_numbers is not None:
        parts.append(fixed_field(block_numbers, 0, b"N"))
        parts.append(np.full((n, 1), ord(" "), dtype=np.uint8))
    code = np.empty((n, 2), dtype=np.uint8)
    code[:, 0] = ord("G")
    code[:, 1] = np.where(rapid, ord("0"), ord("1"))
    parts.append(code)
    decimals = (fmt.linear_decimals,) * 3 + (fmt.angular_decimals,) * 2
    for k, (letter, dec) in enumerate(zip((b" X", b" Y", b" Z", b" A", b" C"), decimals, strict=True)):
        parts.append(fixed_field(scaled_int(joints_out[:, k], dec), dec, letter))
    feed = ~rapid
    if np.any(feed):
        f_field = fixed_field(np.where(feed, f_scaled, 0), fmt.feed_decimals, b" F")
        f_field[rapid] = 0
        parts.append(f_field)
    if between is not None and np.any(between):
        mark = np.zeros((n, len(RAPID_MARK) + 1), dtype=np.uint8)
        mark[between] = np.frombuffer((" " + RAPID_MARK).encode("ascii"), dtype=np.uint8)
        parts.append(mark)
    parts.append(np.full((n, 1), ord("\n"), dtype=np.uint8))
    mat = np.concatenate(parts, axis=1)
    keep = mat != 0
    packed = mat[keep]
    offsets = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.count_nonzero(keep, axis=1), out=offsets[1:])
    return packed.tobytes().decode("ascii"), offsets


# --------------------------------------------------------------------------------------------
# program assembly


def _check_format(fmt: GcodeFormat) -> None:
    for name in ("linear_decimals", "angular_decimals", "feed_decimals"):
        value = getattr(fmt, name)
        if not (isinstance(value, (int, np.integer)) and 0 <= value <= 9):
            raise ValueError(f"GcodeFormat.{name} must be an integer 0..9, got {value!r}")
    if fmt.block_numbers and not (
        isinstance(fmt.block_number_step, (int, np.integer)) and fmt.block_number_step >= 1
    ):
        raise ValueError(f"GcodeFormat.block_number_step must be >= 1, got {fmt.block_number_step!r}")


def _prepare(program: Program, fmt: GcodeFormat) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Validate ``program``; return joints in mm/deg, rapid mask, scaled F words and CL lines."""
    _check_format(fmt)
    joints = np.asarray(program.joints, dtype=float)
    if joints.ndim != 2 or joints.shape[1] != 5:
        raise ValueError(f"Program.joints must have shape (M, 5), got {joints.shape}")
    m = joints.shape[0]
    rapid = np.asarray(program.rapid, dtype=bool).reshape(-1)
    duration = np.asarray(program.duration, dtype=float).reshape(-1)
    line = np.asarray(program.line).reshape(-1)
    for name, arr in (("rapid", rapid), ("duration", duration), ("line", line)):
        if arr.shape[0] != m:
            raise ValueError(f"Program.{name} has {arr.shape[0]} entries for {m} blocks")

    out = np.empty_like(joints)
    out[:, :3] = joints[:, :3]
    out[:, 3:] = np.degrees(joints[:, 3:])
    limits = np.array(
        [_MAX_SCALED / 10.0**fmt.linear_decimals] * 3 + [_MAX_SCALED / 10.0**fmt.angular_decimals] * 2
    )
    bad = ~np.all(np.isfinite(out) & (np.abs(out) < limits), axis=1)
    if np.any(bad):
        k = int(np.argmax(bad))
        raise ValueError(f"CL line {line[k]}: block {k} has a non-finite or huge joint position {joints[k]}")

    feed = ~rapid
    bad = feed & ~(np.isfinite(duration) & (duration > 0))
    if np.any(bad):
        k = int(np.argmax(bad))
        raise ValueError(f"CL line {line[k]}: feed block {k} has duration {duration[k]} s (must be > 0)")
    f_scaled = np.zeros(m, dtype=np.int64)
    if np.any(feed):
        with np.errstate(over="ignore", divide="ignore"):
            f_real = 60.0 / duration[feed] * 10.0**fmt.feed_decimals
        too_big = ~(f_real < _MAX_SCALED)
        if np.any(too_big):
            k = int(np.flatnonzero(feed)[np.argmax(too_big)])
            raise FeedRateError(
                f"CL line {line[k]}: feed block {k} lasts {duration[k]:.3g} s: inverse-time F "
                f"{60.0 / duration[k]:.3g} /min is too large to write"
            )
        q = np.rint(f_real).astype(np.int64)
        zero = q < 1
        if np.any(zero):
            k = int(np.flatnonzero(feed)[np.argmax(zero)])
            raise FeedRateError(
                f"CL line {line[k]}: feed block {k} lasts {duration[k]:.6g} s: inverse-time F "
                f"{60.0 / duration[k]:.3g} /min rounds to 0 at {fmt.feed_decimals} decimals"
            )
        f_scaled[feed] = q
    for ev in program.events:
        if not (0 <= int(ev.index) <= m):
            raise ValueError(f"CL line {ev.line}: event index {ev.index} outside 0..{m}")
    return out, rapid, f_scaled, line


class GcodeWriter:
    """The G-code of a program a piece at a time: :meth:`head`, then :meth:`body` of one part of the
    blocks after another, then :meth:`tail`. The writer carries what runs across parts: the
    block numbers and whether ``G93`` was written, so the text is the same however the blocks
    are split. A whole :class:`Program` is one part (:func:`program_text`)."""

    def __init__(self, fmt: GcodeFormat | None = None) -> None:
        self.fmt = fmt or GcodeFormat()
        _check_format(self.fmt)
        self.numbered = 0  # numbered lines so far: the next one gets N (numbered + 1) * step
        self.inverse_time = False  # G93 written

    def _render(self, lines: list[tuple[str, bool]]) -> str:
        out = []
        step = int(self.fmt.block_number_step)
        for text, is_block in lines:
            if self.fmt.block_numbers and is_block:
                self.numbered += 1
                out.append(f"N{self.numbered * step} {text}\n")
            else:
                out.append(text + "\n")
        return "".join(out)

    def head(self, program: Program) -> str:
        """``%``, the part name and the ``header`` of ``program`` as comments, the preamble."""
        head: list[tuple[str, bool]] = [("%", False)]
        if program.part_name is not None:
            head.append((f"({comment_text(f'PART {program.part_name}')})", False))
        head.extend((f"({comment_text(h)})", False) for h in program.header if comment_text(h))
        head.append((PREAMBLE, True))
        return self._render(head)

    def tail(self) -> str:
        """The end of the program (the same text however often asked for)."""
        numbered = self.numbered
        text = self._render([("M5 M9", True), ("G94", True), ("M30", True)]) + "%\n"
        self.numbered = numbered
        return text

    def body(self, program: Program) -> Iterator[str]:
        """Validate the blocks of ``program`` (one part of a program) now, then return a generator
        of text pieces, each one or more ``\\n``-ended lines; events at index M (after the part's
        last block) come last."""
        joints, rapid, f_scaled, _ = _prepare(program, self.fmt)
        between = None if program.between is None else np.asarray(program.between, bool).reshape(-1) & ~rapid
        if between is not None and between.shape[0] != joints.shape[0]:
            raise ValueError(f"Program.between has {between.shape[0]} entries for {joints.shape[0]} blocks")
        fmt = self.fmt
        m = joints.shape[0]
        step = int(fmt.block_number_step)
        # Non-motion lines in output order, grouped by the block they precede: events in source
        # order (stable sort by index), then G93 just before the first feed block of the program.
        groups: dict[int, list[tuple[str, bool]]] = {}
        for ev in sorted(program.events, key=lambda e: int(e.index)):
            groups.setdefault(int(ev.index), []).extend(_event_lines(ev, program, fmt))
        feed_idx = np.flatnonzero(~rapid)
        if feed_idx.size and not self.inverse_time:
            groups.setdefault(int(feed_idx[0]), []).append(("G93", True))
            self.inverse_time = True
        # Block numbers: a motion block i is preceded by the numbered lines before this part,
        # i motion blocks and extra[i] numbered event lines of this part.
        counts = np.zeros(m + 1, dtype=np.int64)
        for idx, lines in groups.items():
            counts[idx] = sum(1 for _, is_block in lines if is_block)
        extra = np.cumsum(counts)  # extra[i]: numbered event lines at indices <= i
        before = self.numbered
        self.numbered += m + int(extra[-1]) if fmt.block_numbers else 0
        events_at = sorted(groups)

        def render(lines: list[tuple[str, bool]], first: int) -> str:
            out = []
            for text, is_block in lines:
                if fmt.block_numbers and is_block:
                    out.append(f"N{first * step} {text}\n")
                    first += 1
                else:
                    out.append(text + "\n")
            return "".join(out)

        def generate() -> Iterator[str]:
            e = 0
            for c0 in range(0, m, _CHUNK):
                c1 = min(c0 + _CHUNK, m)
                numbers = None
                if fmt.block_numbers:
                    i = np.arange(c0, c1, dtype=np.int64)
                    numbers = (before + extra[c0:c1] + i + 1) * step
                text, off = _motion_text(joints[c0:c1], rapid[c0:c1], f_scaled[c0:c1], numbers, fmt,
                                         None if between is None else between[c0:c1])
                prev = c0
                while e < len(events_at) and events_at[e] < c1:
                    idx = events_at[e]
                    if idx > prev:
                        yield text[off[prev - c0] : off[idx - c0]]
                    yield render(groups[idx], before + (int(extra[idx - 1]) if idx > 0 else 0) + idx + 1)
                    prev = idx
                    e += 1
                if c1 > prev:
                    yield text[off[prev - c0] : off[c1 - c0]]
            if e < len(events_at):  # events after the last block
                yield render(groups[m], before + (int(extra[m - 1]) if m else 0) + m + 1)

        return generate()


def _pieces(program: Program, fmt: GcodeFormat) -> Iterator[str]:
    """Validate now, then return a generator of text pieces, each one or more ``\\n``-ended lines."""
    writer = GcodeWriter(fmt)
    head = writer.head(program)
    body = writer.body(program)
    tail = writer.tail()
    return itertools.chain((head,), body, (tail,))


def format_program(program: Program, fmt: GcodeFormat | None = None) -> Iterator[str]:
    """The G-code of ``program`` line by line (no newline characters).

    Validation runs before the first line is produced: raises ``ValueError`` for malformed input
    (shapes, non-finite joints, feed block duration <= 0, unknown tool length) and
    :class:`FeedRateError` (also a ``ValueError``) when an F word would round to 0.
    """
    pieces = _pieces(program, fmt or GcodeFormat())

    def lines() -> Iterator[str]:
        for piece in pieces:
            yield from piece[:-1].split("\n")

    return lines()


def program_text(program: Program, fmt: GcodeFormat | None = None) -> str:
    """The whole G-code of ``program`` as one string (lines end in ``\\n``); raises like
    :func:`format_program`."""
    return "".join(_pieces(program, fmt or GcodeFormat()))


def with_header_line(text: str, comment: str) -> str:
    """Program ``text`` with ``(comment)`` as the last header line, just before the preamble."""
    at = text.index(PREAMBLE)
    at = text.rfind("\n", 0, at) + 1  # the start of the preamble line, before its N number if any
    return f"{text[:at]}({comment_text(comment)})\n{text[at:]}"


def write_text(text: str, path: str | os.PathLike[str]) -> None:
    """Write program ``text`` to ``path`` atomically (see :func:`write_program`)."""
    with atomic_write(path) as handle:
        handle.write(text)


def write_program(program: Program, fmt: GcodeFormat | None, path: str | os.PathLike[str]) -> None:
    """Write the G-code of ``program`` to ``path`` atomically.

    The text goes to a temporary file in the same directory, which replaces ``path`` only once
    it is complete: on any error ``path`` is left as it was (absent or the previous file) and the
    temporary file is removed. Raises like :func:`format_program`.
    """
    pieces = _pieces(program, fmt or GcodeFormat())  # validates before touching the disk
    with atomic_write(path) as handle:
        for piece in pieces:
            handle.write(piece)
