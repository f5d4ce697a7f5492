"""Write a joint-space program as G-code for the VERNE controller.

The controller drives the joints directly: ``X Y Z`` are the slider positions rho1, rho2, rho3
(mm), ``A`` the table tilt theta1 and ``C`` the rotary table theta2 (degrees, written as they
accumulate, never wrapped to 0..360); ``B`` is never written. Those letters, the comment style,
the lines around the program and at tool changes, block numbers and M codes are the machine
file's controller profile (:mod:`verne_post.output.controller`); below, the default (LinuxCNC).
The program's first move, from wherever the machine stands, is ``G0``; every other block is
``G1`` in inverse-time mode (``G93``) with an ``F`` word on every block, ``F = 60 / duration``
(1/min), the blocks of moves between cuts (rapids, retracts, tool changes:
verne_post.motion.safe_motion) marked ``(RAPID)``. Layout::

    %
    (PART name)
    (header lines)
    G21 G90 G17 G40 G49 G94                   <- program_start
    (TOOL 1 LENGTH 120.0000 DELTA 0.0000)
    T1 M6                                     <- tool_change, after M1 with optional_stop
    S12000 M3
    M8
    G0 X.. Y.. Z.. A.. C..
    G93
    G1 X.. Y.. Z.. A.. C.. F.. (RAPID)
    ...
    G1 X.. Y.. Z.. A.. C.. F..
    ...
    M5 M9                                     <- program_end
    G94
    M30
    %

Numbers have fixed decimals (``GcodeFormat``), never ``-0``. Motion blocks are formatted with
numpy byte arithmetic, a chunk of blocks at a time, not one Python format call per block.
Output is deterministic (no dates). Checked against LinuxCNC's interpreter (``verne_post.verify.rs274``).
"""

from __future__ import annotations

import contextlib
import itertools
import os
import re
import unicodedata
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import IO

import numpy as np

from verne_post.cl.toolpath import Comment, Coolant, Dwell, Event, Spindle, Stop, ToolChange
from verne_post.errors import CheckError
from verne_post.output.atomic import atomic_write
from verne_post.output.controller import LINUXCNC, Controller, Number, render
from verne_post.output.numbers import fixed_field, scaled_int

__all__ = [
    "MAX_COMMENT_CHARS",
    "RAPID_MARK",
    "RAPID_WORD",
    "FeedRateError",
    "GcodeFormat",
    "GcodeWriter",
    "LineLengthError",
    "Program",
    "comment_text",
    "file_names",
    "format_program",
    "header_end",
    "program_text",
    "tool_spindles",
    "with_header_line",
    "write_files",
    "write_program",
    "write_text",
]

#: Longest comment text written (and at most the profile's line length less the delimiters).
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
    """Number formatting and the controller profile, from the machine YAML.

    ``linear_decimals`` for the sliders (mm), ``angular_decimals`` for the tilt and rotary
    (degrees), ``feed_decimals`` for the inverse-time F word (1/min); ``controller``: axis
    letters, comments, the program's structure, block numbers (every block line, not ``%``, the
    program number nor a comment line, starts with ``N<k>``, k = start, start + step, ...).
    """

    linear_decimals: int = 4
    angular_decimals: int = 4
    feed_decimals: int = 5
    controller: Controller = LINUXCNC

    @property
    def block_numbers(self) -> bool:
        return self.controller.block_numbers is not None


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
    - ``tool_spindle``: CL line of a tool change -> the spindle speed (rpm) of that tool, the
      ``{spindle}`` of the controller's tool-change lines (:func:`tool_spindles`).
    - ``name``: ``{name}`` in the controller's lines (default: ``part_name``, else empty).
    - ``tolerance``: ``{tolerance}`` in the controller's lines, mm: the tip tolerance the blocks
      were made to (LinuxCNC's blending tolerance, ``G64 P``).
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
    tool_spindle: dict[int, float] | None = None
    name: str | None = None
    tolerance: float = 0.005


#: The comment that ends a G1 block of a move between cuts: the controller runs it as written
#: (G93, so the planned time), and a reader tells it from a cut (verne_post.verify.gcode_reader).
#: ``(RAPID)`` with parentheses comments, ``; RAPID`` with semicolon comments.
RAPID_WORD = "RAPID"
RAPID_MARK = LINUXCNC.comment_line(RAPID_WORD)


class FeedRateError(CheckError, ValueError):
    """A feed block whose inverse-time F word cannot be written (rounds to 0 or overflows)."""


class LineLengthError(CheckError, ValueError):
    """A line longer than the controller takes (``controller.max_line_length``)."""


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


def _event_lines(event: Event, program: Program, fmt: GcodeFormat, values: dict[str, object],
                 first_tool: bool) -> list[tuple[str, bool]]:
    """G-code lines for one event as ``(text, is_block)``; comment lines are not blocks.

    ``values``: the program's placeholders (``{name}``, ``{program}``); ``first_tool``: this is
    the program's first tool change (no optional stop before it).
    """
    where = f"CL line {event.line}"
    controller, m = fmt.controller, fmt.controller.m_codes
    if isinstance(event, ToolChange):
        tool = int(event.tool)
        if tool < 0:
            raise ValueError(f"{where}: negative tool number {tool}")
        lengths = (program.tool_lengths or {}).get(tool)
        if lengths is None:
            if tool != 0:
                raise ValueError(f"{where}: no tool length given for tool {tool} (Program.tool_lengths)")
            return [(f"T{tool} M{m.tool_change}", True)]
        length, delta = lengths
        if not (np.isfinite(length) and np.isfinite(delta)):
            raise ValueError(f"{where}: tool {tool} length {length} / Delta {delta} is not finite")
        dec = fmt.linear_decimals
        note = (_comment(f"TOOL {tool} LENGTH {_fixed(length, dec)} DELTA {_fixed(delta, dec)}", controller), False)
        spindle = (program.tool_spindle or {}).get(event.line, 0.0)
        here = {**values, "tool": tool, "length": Number(length, dec), "delta": Number(delta, dec),
                "spindle": Number(spindle, None)}
        # Tool 0: the CL file gave tool data but no tool number (and the machine file none:
        # controller.tool_number); T0 M6 would unload the spindle, so it is loaded by hand.
        if tool == 0:
            return [note, *_lines(controller.hand_loaded_lines, here, controller, where)]
        stop = [] if first_tool or not controller.optional_stop else [(f"M{m.optional_stop}", True)]
        return [*stop, note, *_lines(controller.tool_change_lines, here, controller, where)]
    if isinstance(event, Spindle):
        if event.direction == "OFF":
            return [(f"M{m.spindle_off}", True)]
        rpm = float(event.rpm)
        if not (np.isfinite(rpm) and rpm > 0):
            raise ValueError(f"{where}: spindle speed {rpm} rpm must be > 0")
        code = {"CW": m.spindle_cw, "CCW": m.spindle_ccw}.get(event.direction)
        if code is None:
            raise ValueError(f"{where}: unknown spindle direction {event.direction!r}")
        return [(f"S{_plain(rpm)} M{code}", True)]
    if isinstance(event, Coolant):
        code = {"ON": m.coolant_flood, "FLOOD": m.coolant_flood, "THRU": m.coolant_through,
                "MIST": m.coolant_mist, "OFF": m.coolant_off}.get(event.mode)
        if code is None:
            raise ValueError(f"{where}: unknown coolant mode {event.mode!r}")
        return [(f"M{code}", True)]
    if isinstance(event, Comment):
        text = _comment(event.text, controller)
        return [(text, False)] if text else []
    if isinstance(event, Stop):
        return [(f"M{m.optional_stop if event.optional else m.stop}", True)]
    if isinstance(event, Dwell):
        seconds = float(event.seconds)
        if not (np.isfinite(seconds) and seconds >= 0):
            raise ValueError(f"{where}: dwell {seconds} s must be >= 0")
        return [(f"G4 P{_plain(seconds, 3)}", True)]
    raise TypeError(f"unknown event type {type(event).__name__}")


def _comment(text: str, controller: Controller) -> str:
    """A comment line of ``text`` in the controller's style within its line length; empty if
    nothing of ``text`` is left."""
    safe = comment_text(text, min(MAX_COMMENT_CHARS, controller.max_line_length - 2))
    return controller.comment_line(safe) if safe else ""


def _lines(templates: Iterable[str], values: dict[str, object], controller: Controller,
           where: str) -> list[tuple[str, bool]]:
    """Lines of the profile as ``(text, is_block)``: a comment line is no block (no block number)."""
    texts = [_line(t, values, controller, where) for t in templates]
    return [(text, not controller.is_comment(text)) for text in texts]


def _line(template: str, values: dict[str, object], controller: Controller, where: str) -> str:
    """A line of the profile, its placeholders filled, within the controller's line length."""
    text = render(template, values)
    if len(text) > controller.max_line_length - 12:  # room for a block number
        raise LineLengthError(f"{where}: the line '{text[:40]}...' of the controller profile is {len(text)} "
                              f"characters, more than controller.max_line_length allows")
    return text


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
    letters = [f" {letter}".encode("ascii") for letter in fmt.controller.axes]
    for k, (letter, dec) in enumerate(zip(letters, decimals, strict=True)):
        parts.append(fixed_field(scaled_int(joints_out[:, k], dec), dec, letter))
    feed = ~rapid
    if np.any(feed):
        f_field = fixed_field(np.where(feed, f_scaled, 0), fmt.feed_decimals, b" F")
        f_field[rapid] = 0
        parts.append(f_field)
    if between is not None and np.any(between):
        rapid_mark = " " + fmt.controller.comment_line(RAPID_WORD)
        mark = np.zeros((n, len(rapid_mark)), dtype=np.uint8)
        mark[between] = np.frombuffer(rapid_mark.encode("ascii"), dtype=np.uint8)
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
    cap = fmt.controller.max_feed_decimals
    if cap is not None and fmt.feed_decimals > cap:
        raise ValueError(f"GcodeFormat.feed_decimals {fmt.feed_decimals}: {fmt.controller.dialect} takes at most {cap}")
    numbers = fmt.controller.block_numbers
    if numbers is not None and not (numbers[0] >= 0 and numbers[1] >= 1):
        raise ValueError(f"block numbers must start at 0 or more and step by 1 or more, got {numbers!r}")


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
        if fmt.controller.max_inverse_time_feed is not None:  # the controller's largest F: a little slower
            f_real = np.minimum(f_real, fmt.controller.max_inverse_time_feed * 10.0**fmt.feed_decimals)
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
    block numbers, whether ``G93`` was written, the tool changes so far and the placeholders of
    the head, so the text is the same however the blocks are split. A whole :class:`Program` is
    one part (:func:`program_text`)."""

    def __init__(self, fmt: GcodeFormat | None = None) -> None:
        self.fmt = fmt or GcodeFormat()
        _check_format(self.fmt)
        self.numbered = 0  # numbered lines so far
        self.inverse_time = False  # G93 written
        self.tool_changes = 0  # tool changes written
        # split: tool. The body's line where each file starts and its tool; what is in force there.
        self.files: list[tuple[int, int]] = []
        self.body_lines = 0  # lines of the body so far
        self.position: np.ndarray | None = None  # the last block's end (mm, degrees)
        self.in_force: dict[type, str] = {}  # the last spindle and coolant lines
        self.values: dict[str, object] = {"name": "", "program": self.fmt.controller.program_number,
                                          "tolerance": 0.005}

    def _number(self, k: np.ndarray | int) -> np.ndarray | int:
        """The N number of the k-th numbered line (1-based), wrapped to ``start`` beyond the
        controller's largest (FANUC: sequence numbers need not be unique nor ascending)."""
        start, step = self.fmt.controller.block_numbers or (0, 1)
        largest = self.fmt.controller.max_block_number
        return start + (k - 1) * step if largest is None else start + (k - 1) * step % (largest - start + 1)

    def _render(self, lines: list[tuple[str, bool]], first: int | None = None) -> str:
        """``lines`` as text; numbered lines from the ``first``-th on (default: the next)."""
        out = []
        numbered = self.fmt.block_numbers
        k = self.numbered + 1 if first is None else first
        for text, is_block in lines:
            if numbered and is_block:
                out.append(f"N{self._number(k)} {text}\n")
                k += 1
            else:
                out.append(text + "\n")
        if first is None:
            self.numbered = k - 1
        return "".join(out)

    def head(self, program: Program) -> str:
        """``%``, the program number, the part name and the ``header`` of ``program`` as comments,
        the profile's start lines."""
        controller = self.fmt.controller
        name = program.name if program.name is not None else program.part_name or ""
        self.values = {"name": comment_text(name), "program": controller.program_number,
                       "tolerance": program.tolerance}
        head: list[tuple[str, bool]] = [("%", False)] if controller.percent else []
        if controller.program_number_line is not None and controller.program_number is not None:
            head.append((render(controller.program_number_line, self.values), False))
        if program.part_name is not None:
            head.append((_comment(f"PART {program.part_name}", controller), False))
        head.extend((comment, False) for comment in (_comment(h, controller) for h in program.header) if comment)
        head.extend(_lines(controller.program_start, self.values, controller, "program start"))
        return self._render(head)

    def tail(self) -> str:
        """The end of the program (the same text however often asked for)."""
        controller = self.fmt.controller
        numbered = self.numbered
        end = _lines(controller.end_lines, self.values, controller, "program end")
        text = self._render(end) + ("%\n" if controller.percent else "")
        self.numbered = numbered
        return text

    def body(self, program: Program) -> Iterator[str]:
        """Validate the blocks of ``program`` (one part of a program) now, then return a generator
        of text pieces, each one or more ``\\n``-ended lines; events at index M (after the part's
        last block) come last."""
        joints, rapid, f_scaled, line = _prepare(program, self.fmt)
        if program.tool_spindle is None:
            program = replace(program, tool_spindle=tool_spindles(program.events))
        between = None if program.between is None else np.asarray(program.between, bool).reshape(-1) & ~rapid
        if between is not None and between.shape[0] != joints.shape[0]:
            raise ValueError(f"Program.between has {between.shape[0]} entries for {joints.shape[0]} blocks")
        fmt = self.fmt
        m = joints.shape[0]
        # Non-motion lines in output order, grouped by the block they precede: events in source
        # order (stable sort by index), then G93 just before the first feed block of the program.
        groups: dict[int, list[tuple[str, bool]]] = {}
        feed_idx = np.flatnonzero(~rapid)
        splits: dict[int, int] = {}  # index of a block -> the tool whose file starts before it
        restate: dict[int, dict[type, str]] = {}  # what a new file restates after its tool change
        for ev in sorted(program.events, key=lambda e: int(e.index)):
            idx = int(ev.index)
            first_tool = self.tool_changes == 0
            lines = _event_lines(ev, program, fmt, self.values, first_tool)
            if isinstance(ev, ToolChange) and ev.tool != 0:
                self.tool_changes += 1
                if fmt.controller.split == "tool" and idx not in splits:
                    splits[idx] = int(ev.tool)
                    if idx > 0 or self.position is not None:  # a file after the first
                        restate[idx] = dict(self.in_force)
            if isinstance(ev, (Spindle, Coolant)):
                self.in_force[type(ev)] = lines[0][0]
                restate.get(idx, {}).pop(type(ev), None)  # the CL says it again after the tool change
            groups.setdefault(idx, []).extend(lines)
        for idx, restated in restate.items():
            # after its tool change, a file positions where the one before left the machine (a
            # move of length zero when they run in turn) and selects inverse time again
            at = joints[idx - 1] if idx > 0 else self.position
            inverse_time = self.inverse_time or bool(feed_idx.size and feed_idx[0] < idx)
            groups[idx].extend([*((line, True) for line in restated.values()), *self._restart(at, inverse_time)])
        if m:
            self.position = joints[-1]
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

        counting = fmt.controller.split == "tool"

        def emit(piece: str, idx: int | None = None) -> str:
            if counting:
                if idx in splits:  # a file starts at the first line of this group
                    self.files.append((self.body_lines, splits[idx]))
                self.body_lines += piece.count("\n")
            return piece

        def generate() -> Iterator[str]:
            e = 0
            for c0 in range(0, m, _CHUNK):
                c1 = min(c0 + _CHUNK, m)
                numbers = None
                if fmt.block_numbers:
                    numbers = self._number(before + extra[c0:c1] + np.arange(c0, c1, dtype=np.int64) + 1)
                text, off = _motion_text(joints[c0:c1], rapid[c0:c1], f_scaled[c0:c1], numbers, fmt,
                                         None if between is None else between[c0:c1])
                _check_lengths(off, line[c0:c1], c0, fmt.controller)
                prev = c0
                while e < len(events_at) and events_at[e] < c1:
                    idx = events_at[e]
                    if idx > prev:
                        yield emit(text[off[prev - c0] : off[idx - c0]])
                    yield emit(self._render(groups[idx], before + (int(extra[idx - 1]) if idx > 0 else 0) + idx + 1),
                               idx)
                    prev = idx
                    e += 1
                if c1 > prev:
                    yield emit(text[off[prev - c0] : off[c1 - c0]])
            if e < len(events_at):  # events after the last block
                yield emit(self._render(groups[m], before + (int(extra[m - 1]) if m else 0) + m + 1), m)

        return generate()

    def _restart(self, position: np.ndarray, inverse_time: bool) -> list[tuple[str, bool]]:
        """``G0`` to ``position`` (mm, degrees), and ``G93`` if the program was in inverse time."""
        text, _ = _motion_text(position[None], np.ones(1, bool), np.zeros(1, np.int64), None, self.fmt)
        return [(text.rstrip("\n"), True), *((("G93", True),) if inverse_time else ())]


def _check_lengths(offsets: np.ndarray, line: np.ndarray, first: int, controller: Controller) -> None:
    """Refuse a motion block longer than the controller takes (offsets: its lines' starts)."""
    long = np.diff(offsets) - 1 > controller.max_line_length
    if np.any(long):
        k = int(np.argmax(long))
        raise LineLengthError(f"CL line {line[k]}: block {first + k} is {int(np.diff(offsets)[k]) - 1} characters, "
                              f"more than controller.max_line_length {controller.max_line_length}")


def tool_spindles(events: Iterable[Event]) -> dict[int, float]:
    """CL line of each tool change -> the spindle speed (rpm) of that tool: the first programmed
    after it, before the next tool change; else the one in force (the spindle keeps it); 0 if
    none was ever given. The ``{spindle}`` of the controller's tool-change lines."""
    speeds: dict[int, float] = {}
    current: int | None = None
    own = False  # the current tool has a speed of its own
    in_force = 0.0
    for event in sorted(events, key=lambda e: int(e.index)):
        if isinstance(event, ToolChange):
            current, own = event.line, False
            speeds[current] = in_force
        elif isinstance(event, Spindle) and event.direction != "OFF":
            in_force = float(event.rpm)
            if current is not None and not own:
                speeds[current], own = in_force, True
    return speeds


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


def header_end(text: str) -> int:
    """Where the header of program ``text`` ends: the offset of its first line that is neither
    ``%``, a program number (``O1234``) nor a comment, in any profile."""
    at = 0
    while at < len(text):
        end = text.find("\n", at)
        end = len(text) if end < 0 else end + 1
        line = text[at:end].strip()
        if not (line == "%" or line.startswith(("(", ";")) or _PROGRAM_NUMBER.fullmatch(line)):
            return at
        at = end
    return at


_PROGRAM_NUMBER = re.compile(r"O\d+")


def with_header_line(text: str, comment: str, controller: Controller = LINUXCNC) -> str:
    """Program ``text`` with ``comment`` in its header: after the line that names the post (the
    header's first; a comment line of the profile's start lines may follow the header, so its end
    is not where comments end), else at the end of the leading comments (:func:`header_end`)."""
    named = re.search(r"^(?:\(|; )POSTPROCESSOR VERNE-POST\b.*\n", text[:header_end(text)], re.M)
    at = named.end() if named else header_end(text)
    return f"{text[:at]}{_comment(comment, controller)}\n{text[at:]}"


def file_names(path: str | os.PathLike[str], tools: list[int]) -> list[Path]:
    """The files of a program split by tool: ``part_1_T2.nc``, ``part_2_T5.nc``, ... beside ``path``."""
    path = Path(path)
    return [path.with_name(f"{path.stem}_{k}_T{tool}{path.suffix}") for k, tool in enumerate(tools, 1)]


def write_files(head: str, body: IO[str], tail: str, files: list[tuple[int, int]],
                path: str | os.PathLike[str]) -> list[Path]:
    """Write a program split by tool (``controller.split: tool``) beside ``path``, atomically
    together: every file or none. ``files``: the body line where each file starts and its tool
    (:attr:`GcodeWriter.files`); lines before the first go into the first. Each file is the
    ``head``, its lines of the ``body`` and the ``tail``. Returns the files, in order."""
    starts = [line for line, _ in files][1:]
    names = file_names(path, [tool for _, tool in files] or [0])
    with contextlib.ExitStack() as stack:
        handles = [stack.enter_context(atomic_write(name)) for name in names]
        k = 0
        handles[0].write(head)
        for number, text in enumerate(body):
            if k < len(starts) and number == starts[k]:
                handles[k].write(tail)
                k += 1
                handles[k].write(head)
            handles[k].write(text)
        handles[k].write(tail)
    return names


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
