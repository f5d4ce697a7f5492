"""The controller a program is written for: its dialect and the shop's settings over it.

A :class:`Controller` is plain data that the G-code writer (``output.gcode``) writes with and the
reader (``verify.gcode_reader``) reads with, so that whatever the profile, ``verify`` reads a
program the way it was written. It comes from the ``controller:`` section of the machine file
(``verne_post.machine.ControllerConfig``): a ``dialect`` preset, then the settings that override it.

The presets, each from its vendor's documentation (what a preset does not say, it leaves as the
RS-274 default):

``linuxcnc``
    LinuxCNC G-code reference (linuxcnc.org/docs/html/gcode/g-code.html, m-code.html) and
    "G-code overview" (gcode/overview.html): ``( )`` and ``;`` comments, ``%`` demarcation, G21
    mm, G93 inverse time: "an F word means the move should be completed in [one divided by the
    F number] minutes" (G-codes, "G93, G94, G95"; ``rs274``'s canonical feed rates agree:
    ``verify.rs274.inverse_time_rate``), G49 tool length offset cancel, M3/M4/M5, M7/M8/M9,
    M6 tool change, M1 optional stop, M30 end. O words are subroutine labels, so LinuxCNC has no
    program number line. Lines longer than 252 characters are refused by its interpreter
    (measured with ``rs274`` of LinuxCNC 2.9.0~pre1, Debian 12). Today's output, byte for byte.
``fanuc``
    FANUC Series 16i/18i Operator's Manual (B-63684EN/01), 13 "Program configuration": the
    end-of-block code is written ``;`` in FANUC's listings (so ``;`` is never a comment there),
    comments in ``( )``, sequence numbers N1 to N99999 (N0 must not be used), program number 0
    cannot be used (O1 to O9999 on controls of four digits); FANUC Series 16/18/160/180-MODEL C
    Machining Center Operator's Manual (B-62764EN/01), 5 "Feed functions", inverse time (G93):
    F is 1/time in minutes, 0.001 to 9999.999 (also 30i/31i/32i-A User's Manual B-63944EN/02,
    5.3: "F_ ; Feedrate command (1/min)"). G21 metric input, G49 and G80 cancels, ``T.. M6``,
    M30 end.
``sinumerik``
    SINUMERIK ONE / 840D sl Programming Manual "NC programming" (12/2019, 6FC5398-2EP40-0BA0):
    2.3 "``;`` comment start" (parentheses are arithmetic there); 2.2 a program held by the
    control is named ``_N_NAME_MPF``, ``%`` only in punch-tape transfer files; 2.7 "Inverse-time
    feedrate (G93) ... unit: rpm [1/min]; N10 G93 G01 X100 F2: the programmed path is traversed
    in 0.5 min". G71 metric input. ``TRAFOOF``, "deactivates an active transformation" (840D
    Programming Manual "Job planning", 03/2006, 6FC5398-2BP10-1BA0, 7.8): the program moves
    the machine axes themselves, never a tool tip through TRAORI. Tool change ``T..``, ``M6``
    (the tool-change M code, MD22560 TOOL_CHANGE_M_CODE, "default setting is 6": Function Manual
    Extended Functions 03/2013, 6FC5397-1BP40-3BA1, W3),
    then ``D0`` (the tool change activates a cutting edge, whose length offset would shift the
    axes: the joints already hold the tool), M30 end. Blocks of up to 512 characters (ASSUMPTION: from the 840D manuals'
    block-length note, not found in the 2019 edition; set max_line_length to your control's).
"""

from __future__ import annotations

import re
import string
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from typing import Literal

__all__ = [
    "DIALECTS",
    "JOINT_ORDER",
    "LINUXCNC",
    "PLACEHOLDERS",
    "SAMPLES",
    "Controller",
    "MCodes",
    "ReaderFacts",
    "g_codes",
    "modal_words",
    "placeholders",
    "render",
    "template_problem",
]

#: The joints in the order of a program's columns: sliders rho1..3 (mm), tilt theta1, rotary theta2 (deg).
JOINT_ORDER = ("rho1", "rho2", "rho3", "theta1", "theta2")

#: Letters an axis may be given: the linear X Y Z U V W and rotary A B C addresses of RS-274,
#: FANUC and SINUMERIK; every other letter is a word of its own (G M N F S T O P D ...).
AXIS_LETTERS = "XYZUVWABC"

CommentStyle = Literal["parentheses", "semicolon"]


@dataclass(frozen=True)
class MCodes:
    """The M codes the program writes (numbers: ``3`` is written ``M3``)."""

    spindle_cw: int = 3
    spindle_ccw: int = 4
    spindle_off: int = 5
    coolant_flood: int = 8
    coolant_mist: int = 7
    coolant_through: int = 8  # through the spindle; a shop with its own code sets it
    coolant_off: int = 9
    stop: int = 0
    optional_stop: int = 1
    tool_change: int = 6
    end: int = 30


@dataclass(frozen=True)
class ReaderFacts:
    """What a dialect's words mean to the reader, beyond RS-274's G0/G1/G93/G94/M/T/S/F/N.

    G codes in tenths (G61.1 is 611), as :mod:`verne_post.verify.gcode_reader` counts them.
    """

    metric: frozenset[int] = frozenset({210})  # G21
    inch: frozenset[int] = frozenset({200})  # G20
    # Codes that change nothing a joint-space program needs: plane, cutter compensation off, tool
    # length offset off, canned cycle off, path control, absolute distance.
    harmless: frozenset[int] = frozenset({170, 180, 190, 400, 490, 610, 611, 640, 800, 900})
    # Codes that select a work offset (G54 to G59, G59.1 to G59.3, FANUC's G54.1): the axis words
    # would be shifted by it, and a joint-space program's words are the joints' own positions.
    work_offsets: frozenset[int] = frozenset({540, 541, 550, 560, 570, 580, 590, 591, 592, 593})
    parenthesis_comments: bool = True
    semicolon_comments: bool = True
    program_number: bool = False  # an O word names the program (before its first block)
    cutting_edge_off: bool = False  # a D0 word (no tool offset) may stand in a block
    keywords: frozenset[str] = frozenset()  # whole-line words that change nothing here (TRAFOOF)


@dataclass(frozen=True)
class Controller:
    """A controller profile, everything resolved (see the module docstring and ``machine.ControllerConfig``).

    - ``axes``: the address letter of each joint, in :data:`JOINT_ORDER`;
    - ``comment``: how comments are written;
    - ``percent``: ``%`` on the first and last lines;
    - ``program_number`` and ``program_number_line`` (a template with ``{program}``, None where
      the dialect has no program number line);
    - ``program_start``, ``program_end``, ``tool_change``: line templates (:data:`PLACEHOLDERS`);
    - ``block_numbers``: ``(start, step)`` or None;
    - ``optional_stop``: an optional stop before every tool change but the first;
    - ``max_line_length``: characters per line, end of line not counted;
    - ``max_block_number``: block numbers wrap to ``start`` beyond it (FANUC: five digits);
    - ``max_inverse_time_feed`` (1/min) and ``max_feed_decimals``: the inverse-time F words the
      controller takes; a block too short for the largest F is written at it, a little slower;
    - ``program_numbers``: the range of ``program_number`` (FANUC: O1 to O9999, O0 is refused);
    - ``split``: ``"tool"`` writes one file per tool (``output.gcode.write_files``);
    - ``m_codes``, and ``reader``: what the dialect's words mean when the program is read back.
    """

    dialect: str
    axes: tuple[str, str, str, str, str] = ("X", "Y", "Z", "A", "C")
    comment: CommentStyle = "parentheses"
    percent: bool = True
    program_number: int | None = None
    program_number_line: str | None = None
    program_start: tuple[str, ...] = ("G21 G90 G17 G40 G49 G94",)
    program_end: tuple[str, ...] | None = None  # None: from the M codes (spindle and coolant off, G94, end)
    tool_change: tuple[str, ...] | None = None  # None: T{tool} M<tool change>
    block_numbers: tuple[int, int] | None = None
    optional_stop: bool = False
    max_line_length: int = 252
    block_time: float = 0.0  # s: the least time a block takes (block processing time); 0: not modelled
    max_block_number: int | None = None  # beyond it, block numbers wrap to ``start``
    max_inverse_time_feed: float | None = None  # 1/min: a shorter block is written at this F (slower)
    max_feed_decimals: int | None = None  # of the inverse-time F word
    program_numbers: tuple[int, int] | None = None  # the range a program number must lie in
    split: Literal["tool"] | None = None
    m_codes: MCodes = field(default_factory=MCodes)
    reader: ReaderFacts = field(default_factory=ReaderFacts)

    @property
    def end_lines(self) -> tuple[str, ...]:
        m = self.m_codes
        return self.program_end if self.program_end is not None else (
            f"M{m.spindle_off} M{m.coolant_off}", "G94", f"M{m.end}")

    @property
    def tool_change_lines(self) -> tuple[str, ...]:
        return self.tool_change if self.tool_change is not None else (f"T{{tool}} M{self.m_codes.tool_change}",)

    @property
    def hand_loaded_lines(self) -> tuple[str, ...]:
        """The tool-change lines for a tool without a number, loaded by hand: without the words
        that hold ``{tool}`` or the tool-change M code, and without comments but whole comment
        lines free of ``{tool}`` (what is left, SINUMERIK's ``D0``, still puts the controller in
        the state the program needs)."""
        change = re.compile(rf"M0*{self.m_codes.tool_change}", re.IGNORECASE)
        lines = []
        for line in self.tool_change_lines:
            if self.is_comment(line):
                kept = "" if "tool" in placeholders(line) else line
            else:
                code = re.sub(r"\([^()]*\)|;.*", " ", line)  # a comment of the line, perhaps of {tool}
                kept = " ".join(word for word in code.split() if "{tool" not in word and not change.fullmatch(word))
            if kept:
                lines.append(kept)
        return tuple(lines)

    def is_comment(self, line: str) -> bool:
        """Whether ``line`` is a comment and nothing else, as this controller reads it (no block number)."""
        text = line.strip()
        return bool((self.reader.semicolon_comments and text.startswith(";")) or (
            self.reader.parenthesis_comments and re.fullmatch(r"(\([^()]*\)\s*)+", text)))

    def comment_line(self, text: str) -> str:
        """``text`` (already made safe: ``output.gcode.comment_text``) as a comment in this style."""
        return f"({text})" if self.comment == "parentheses" else f"; {text}"


# LinuxCNC 2.9's default G64 blends corners with no tolerance: a blend may take half a block
# (measured: the tip 1.2-2.8 mm off the moves between cuts). G64 P bounds the blend's deviation in
# the X Y Z words (here the sliders; A and C are blended unbounded); Q0 turns off the naive-CAM
# merging of collinear blocks, which merges only blocks whose A and C do not move (src/emc/rs274ngc
# interp_convert.cc convert_control_mode; src/emc/task/emccanon.cc SET_MOTION_CONTROL_MODE).
LINUXCNC = Controller("linuxcnc", program_start=("G21 G90 G17 G40 G49 G94", "G64 P{tolerance:.4f} Q0"))

DIALECTS: Mapping[str, Controller] = {
    "linuxcnc": LINUXCNC,
    "fanuc": Controller(
        "fanuc",
        program_number_line="O{program:04d}",
        program_start=("G21 G90 G17 G40 G49 G80 G94",),
        max_block_number=99999,
        max_inverse_time_feed=9999.999,
        max_feed_decimals=3,
        program_numbers=(1, 9999),
        # G05.1 Q1 / Q0: AI contour control on / off; G08 P1 / P0: advanced preview control (look-ahead)
        # on / off (FANUC Series 30i/31i/32i-MODEL A Operator's Manual B-63944EN, "AI contour control",
        # "Advanced preview control"): path control, written in program_start where the shop wants it.
        reader=replace(ReaderFacts(), semicolon_comments=False, program_number=True,
                       harmless=ReaderFacts().harmless | {51, 80}),
    ),
    "sinumerik": Controller(
        "sinumerik",
        comment="semicolon",
        percent=False,
        program_start=("TRAFOOF", "G71 G90 G17 G40 G94"),
        tool_change=("T{tool}", "M6", "D0"),
        max_line_length=512,
        # Path control, written in program_start where the shop wants it (docs/controllers.md):
        # G64 continuous path, G642/G645 rounding within the axes' tolerances of machine data, G60
        # exact stop; COMPON/COMPCURV/COMPCAD/COMPOF the NC block compressor, SOFT/BRISK jerk
        # limitation (SINUMERIK 840D Programming Manual "Job planning", 03/2006, 6FC5398-2BP10-1BA0,
        # 5.4 "Compressor (COMPOF/ON, COMPCURV, COMPCAD)"; Function Manual Basic Functions B1
        # "Continuous-path mode, exact stop, LookAhead", 09/2011, 6FC5397-0BP40-2BA0).
        reader=ReaderFacts(metric=frozenset({710, 7100}), inch=frozenset({700, 7000}),
                           harmless=frozenset({170, 180, 190, 400, 600, 640, 900, 6420, 6450}),
                           # G54 to G57, G500 and G505 to G599: settable frames ("NC programming" 12/2019,
                           # "Settable zero offset"); the frame of G500 need not be zero
                           work_offsets=frozenset({540, 550, 560, 570, 5000, *range(5050, 6000, 10)}),
                           parenthesis_comments=False, cutting_edge_off=True,
                           keywords=frozenset({"TRAFOOF", "COMPON", "COMPCURV", "COMPCAD", "COMPOF", "SOFT",
                                               "BRISK"})),
    ),
}

#: The placeholders each list of lines may use, and what they stand for: ``{tool}`` the tool
#: number, ``{length}`` its gauge length (mm), ``{delta}`` the platform centre to its tip (mm,
#: the paper's Delta), ``{spindle}`` its spindle speed (rpm: ``output.gcode.tool_spindles``),
#: ``{name}`` the part's name, ``{program}`` the program number, ``{tolerance}`` the tip tolerance
#: the blocks were made to (mm, the post's --tol).
PLACEHOLDERS: Mapping[str, frozenset[str]] = {
    "program_start": frozenset({"name", "program", "tolerance"}),
    "program_end": frozenset({"name", "program"}),
    "tool_change": frozenset({"tool", "length", "delta", "spindle", "name", "program"}),
    "program_number_line": frozenset({"program"}),
}

#: Values the placeholders are tried with when a machine file is read: a format that fails on
#: them (``{name:d}``) fails on every program.
SAMPLES = {"tool": 1, "length": 100.0, "delta": 100.0, "spindle": 10000.0, "name": "PART", "program": 1,
           "tolerance": 0.005}


def g_codes(line: str) -> list[int]:
    """The G codes of a profile line in tenths (G61.1 is 611), as the reader counts them; comments
    (either style) and placeholders left out."""
    code = re.sub(r"\([^()]*\)|;.*|\{[^{}]*\}", " ", line).upper()
    return [round(float(value) * 10) for value in re.findall(r"(?<![A-Z_])G\s*(\d+(?:\.\d*)?)", code)]


def modal_words(lines: Iterable[str], reader: ReaderFacts) -> dict[str, str]:
    """The modes a profile's lines set: each G code, and the keywords (TRAFOOF), by a key that
    any metric code shares (``"metric"``), to how the line writes it."""
    words: dict[str, str] = {}
    for line in lines:
        if line.strip().upper() in reader.keywords:
            words.setdefault(line.strip().upper(), line.strip().upper())
        for g in g_codes(line):
            words.setdefault("metric" if g in reader.metric else str(g), f"G{g / 10:g}")
    return words


def placeholders(template: str) -> set[str]:
    """The placeholder names of a line that :func:`template_problem` accepted."""
    return {name for _, name, _, _ in string.Formatter().parse(template) if name}


def template_problem(template: str, allowed: frozenset[str]) -> str | None:
    """Why the line ``template`` cannot be written (None if it can): a placeholder other than
    ``allowed``, a malformed ``{``, a format that does not suit its value, a line break."""
    if "\n" in template or "\r" in template:
        return "a line break inside a line"
    try:
        names = [name for _, name, _, _ in string.Formatter().parse(template) if name is not None]
    except ValueError as exc:
        return f"malformed placeholder ({exc}); write {{{{ and }}}} for literal braces"
    for name in names:
        if name not in allowed:
            known = " ".join(f"{{{p}}}" for p in sorted(allowed))
            return f"unknown placeholder {{{name}}} (here: {known})"
    try:
        template.format(**SAMPLES)
    except (ValueError, TypeError, IndexError, KeyError, AttributeError) as exc:
        return f"cannot be written: {exc}"
    return None


class Number(float):
    """A number for a placeholder, written as the program writes it when the line gives no format:
    with ``decimals`` decimals, or (None) to 2 decimals without trailing zeros (a spindle speed)."""

    decimals: int | None

    def __new__(cls, value: float, decimals: int | None) -> Number:
        number = super().__new__(cls, value)
        number.decimals = decimals
        return number

    def __format__(self, spec: str) -> str:
        if spec:
            return format(float(self), spec)
        text = f"{float(self):.{2 if self.decimals is None else self.decimals}f}"
        if text.startswith("-") and not text.strip("-0."):
            text = text[1:]
        return text.rstrip("0").rstrip(".") if self.decimals is None and "." in text else text


def render(template: str, values: Mapping[str, object]) -> str:
    """The line ``template`` with its placeholders filled (checked at load: :func:`template_problem`)."""
    return template.format(**values)
