"""Read a joint-space RS-274 program the way the VERNE controller (LinuxCNC) runs it.

Independent of the writer (``gcode.py``): any plain RS-274 with the words this machine uses is
accepted, whoever wrote it. ``X Y Z`` are the sliders rho1..3 (mm, or inch under G20), ``A`` the
tilt theta1 and ``C`` the rotary theta2 (degrees); G0/G1 (modal), G93/G94, F, S, T, M codes,
N numbers, ``( )`` and ``;`` comments, spaces anywhere, any letter case, blank lines, ``%``
demarcation. That is the default controller profile (LinuxCNC); another
(:class:`~verne_post.output.controller.Controller`, the machine file's) gives other axis letters,
comment styles, metric and inch codes, the tool-change and end M codes, FANUC's ``O`` program
number, SINUMERIK's ``D0`` and ``TRAFOOF``: the program is read as that controller runs it.
The ``(TOOL n LENGTH l DELTA d)`` comment gives the length (mm) of tool n, and the
header comments ``(WORK OFFSET x y z MM ...)`` and ``(TOLERANCE t MM a DEG ...)`` what the
program was made for. Anything this reader cannot interpret exactly (arcs, incremental
distances, tool length offsets, parameters, expressions, other axes) is an
:class:`~verne_post.errors.InputError` naming the line.

Semantics follow the LinuxCNC documentation: a block's feed mode is set before its F word,
motion comes after tool change, M2/M30 end the program after the block's motion and nothing
after them runs; G94 resets the feed rate to zero; in G93 every G1 needs its own F. Block
durations (s): G93 ``60 / F``; G94 the XYZ length over F, or the AC length (degrees) over F when
X, Y and Z do not move (the RS-274/NGC feed rule).
"""

from __future__ import annotations

import functools
import re
from collections.abc import Iterable
from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError
from ..kinematics.rows import any_of, norms
from ..output.controller import LINUXCNC, Controller

__all__ = ["GcodeProgram", "ReadState", "ToolNote", "read_gcode"]

MM_PER_INCH = 25.4

_NUMBER = r"[+-]?(?:\d+\.?\d*|\.\d+)"
_WORD = re.compile(rf"([A-Z])({_NUMBER})")
_BLOCK = re.compile(rf"(?:[A-Z]{_NUMBER})*")
_BLOCK_NUMBER = re.compile(r"^N\d+")
# A parenthesised comment, or a ";" comment to the end of the line, whichever comes first.
#: The comment that marks a G1 block as a move between cuts (a rapid planned at the joint limits,
#: run in inverse time as written): verne-post writes ``(RAPID)`` at the end of such blocks.
RAPID_WORD = "RAPID"
_COMMENT = re.compile(r"\(([^()]*)\)|;(.*)")
_TOOL_NOTE = re.compile(rf"^\s*TOOL\s+(\d+)\s+LENGTH\s+({_NUMBER})\s+DELTA\s+({_NUMBER})\s*$", re.IGNORECASE)
_WORK_OFFSET = re.compile(rf"^\s*WORK\s+OFFSET\s+({_NUMBER})\s+({_NUMBER})\s+({_NUMBER})\b", re.IGNORECASE)
_TOLERANCE = re.compile(rf"^\s*TOLERANCE\s+({_NUMBER})\s+MM\s+({_NUMBER})\s+DEG\b", re.IGNORECASE)
_RAPID_TOLERANCE = re.compile(rf"\bRAPIDS\s+({_NUMBER})\s+MM\b", re.IGNORECASE)

@dataclass(frozen=True)
class ToolNote:
    """A ``(TOOL n LENGTH l DELTA d)`` comment: G-code line, tool, length and Delta (mm)."""

    line: int
    tool: int
    length: float
    delta: float


@dataclass(frozen=True)
class GcodeProgram:
    """The motion blocks of a program as the controller runs them (M blocks).

    - ``joints`` (M, 5): end of each block: rho1..3 in mm, theta1, theta2 in radians (NaN for an
      axis never programmed so far).
    - ``rapid`` (M,): G0, or a G1 marked ``(RAPID)`` (a move between cuts, timed by its F);
      ``inverse_time`` (M,): G93 in force.
    - ``feed`` (M,): F in force: 1/min under G93, mm/min (deg/min for rotary-only moves) under
      G94; NaN where the controller has none (G93 block without F, G94 before any F).
    - ``duration`` (M,) s: how long the controller takes for a G1 block at its F (NaN on G0,
      without a feed, or for a first block whose start is unknown).
    - ``line`` (M,): 1-based line of each block in the file.
    - ``tool`` (M,): tool in the spindle (-1 none); ``tool_length`` (M,) mm from the TOOL
      comment of that tool in force, NaN if none.
    - ``work_offset`` (mm) and ``tolerance`` (mm, deg, and the rapids' mm or NaN) from the
      header, if it gives them.
    - ``end_line``: line of M2/M30, None if the program never ends; ``last_line``: the last
      non-blank line read.
    - ``problems``: (line, reason) for what the controller would refuse while running.
    """

    source: str
    joints: np.ndarray
    rapid: np.ndarray
    inverse_time: np.ndarray
    feed: np.ndarray
    duration: np.ndarray
    line: np.ndarray
    tool: np.ndarray
    tool_length: np.ndarray
    tool_notes: tuple[ToolNote, ...]
    work_offset: tuple[float, float, float] | None
    tolerance: tuple[float, float, float] | None
    end_line: int | None
    last_line: int
    problems: tuple[tuple[int, str], ...]
    state: ReadState | None = None  # where the reading stands after this text (to read on: read_gcode)

    def __len__(self) -> int:
        return len(self.line)


# Byte classes for the fast route: anything else sends the line down the word-by-word route.
_OTHER, _SPACE, _DIGITS, _LETTER = 0, 1, 2, 3


@dataclass(frozen=True)
class _Words:
    """The words of a controller's programs: ``columns`` those of a row (motion mode, the five
    axes in joint order, feed), ``column_of`` a byte's column (7: none, N), ``byte_kind`` the
    fast route's byte classes."""

    letters: frozenset[str]
    columns: str
    column_of: np.ndarray
    byte_kind: np.ndarray

    @staticmethod
    def of(controller: Controller) -> _Words:
        axes = "".join(controller.axes)
        columns = f"G{axes}F"
        column_of = np.full(256, 7, np.int64)
        column_of[np.frombuffer(columns.encode(), np.uint8)] = np.arange(len(columns))
        byte_kind = np.zeros(256, np.uint8)
        byte_kind[np.frombuffer(b" \t\n", np.uint8)] = _SPACE
        byte_kind[np.frombuffer(b"0123456789.+-", np.uint8)] = _DIGITS
        byte_kind[np.frombuffer(f"NG{axes}F".encode(), np.uint8)] = _LETTER
        facts = controller.reader
        letters = frozenset("NGMFSTP" + axes + ("D" if facts.cutting_edge_off else "")
                            + ("O" if facts.program_number else ""))
        return _Words(letters, columns, column_of, byte_kind)


def _code(value: str) -> int:
    """G/M number in tenths (G61.1 -> 611), the way LinuxCNC tells decimal codes apart."""
    return round(float(value) * 10)


@dataclass(frozen=True)
class _State:
    """Modal state that only the word-by-word route changes, shared by the blocks it applies to."""

    scale: float = 1.0  # mm per program length unit (G20 / G21)
    inverse_time: bool = False
    feed_epoch: int = 0  # counts G93/G94 words: an F stays in force only within one epoch
    tool: int = -1  # tool in the spindle
    tool_length: float = np.nan  # mm, from its TOOL comment


@dataclass(frozen=True)
class ReadState:
    """Where the reading of a program stands after some of its lines: the next line's number,
    the modal state, and the last motion mode, position (mm, degrees) and feed given."""

    lines: int  # lines read
    modal: _State
    lengths: dict[int, float]  # tool -> length (mm) of the TOOL comments read
    selected: int  # the tool of the last T word
    work_offset: tuple[float, float, float] | None
    tolerance: tuple[float, float, float] | None
    opened: bool  # the program starts with '%'
    end_line: int | None  # M2/M30
    stop_line: int | None  # M2/M30 or the closing '%': nothing after it runs
    last_line: int  # the last non-blank line
    motion: float  # G0 / G1 in force (NaN: none yet)
    position: np.ndarray  # (5,) X Y Z mm, A C degrees (NaN: never given)
    feed: float  # the last F word given, within feed-mode epoch ``feed_epoch``
    feed_epoch: int


def read_gcode(text: str | Iterable[str], source: str = "<program>", state: ReadState | None = None,
               final: bool = True, controller: Controller = LINUXCNC) -> GcodeProgram:
    """Read program text (one string, or its lines) into motion blocks; see the module docstring.

    A long program may be read a part at a time: ``state`` is the ``.state`` of the program read
    from the text before (whole lines: the text before ends in a newline), and ``final`` False
    for every part but the last (the end of the program is looked for in the last one).

    Lines of only N, G0/G1, X Y Z A C and F words (nearly all of a program) are tokenised and
    their numbers parsed with numpy, all at once; every other line goes word by word through
    :class:`_Interpreter`, in order. Positions, motion modes and feeds are then resolved for all
    blocks together.
    """
    if not isinstance(text, str):
        text = "\n".join(text)
    text = text.replace("\r\n", "\n").replace("\r", "\n")
    lines = text.split("\n")
    offset = state.lines if state is not None else 0
    read = offset + len(lines) - (1 if text.endswith("\n") else 0)
    if state is not None and state.stop_line is not None:  # the program has ended: nothing more runs
        return _resolve(source, np.zeros((0, 7)), np.zeros(0, np.int64), np.zeros(0, np.int64),
                        _Interpreter(source, 0, controller, state), [], state.last_line, read, state)
    words = _words(controller)
    fast_line, fast_rows, blank, slow = _fast_rows(np.frombuffer(text.encode("utf-8", "replace"), np.uint8),
                                                   len(lines), words)
    first = int(np.argmax(~blank)) if (~blank).any() else len(lines)
    reader = _Interpreter(source, -1 if state is not None else first, controller, state)
    for k in np.flatnonzero(slow):
        if not reader.read(offset + int(k) + 1, lines[k]):
            break
    stop = reader.stop_line or offset + len(lines)
    keep = offset + fast_line + 1 <= stop
    line = np.concatenate([offset + fast_line[keep] + 1, np.asarray(reader.row_line, dtype=np.int64)])
    table = np.concatenate([fast_rows[keep], np.asarray(reader.rows, dtype=float).reshape(-1, 7)])
    order = np.argsort(line, kind="stable")
    line, table = line[order], table[order]
    # the state of a block is the one left by the last word-by-word line before it
    changes = np.asarray(reader.change_line, dtype=np.int64)
    rows_state = np.searchsorted(changes, line, side="right")
    nonblank = np.flatnonzero(~blank[:stop - offset])
    last_line = offset + int(nonblank[-1]) + 1 if nonblank.size else state.last_line if state is not None else 0
    problems = []
    if final and reader.end_line is None and reader.opened and not reader.closed:
        problems.append((last_line, "the program starts with '%' but has no closing '%'"))
    return _resolve(source, table, line, rows_state, reader, problems, last_line, read, state)


@functools.lru_cache(maxsize=8)
def _words(controller: Controller) -> _Words:
    return _Words.of(controller)


def _fast_rows(data: np.ndarray, n_lines: int, words: _Words) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Lines made only of N, G0/G1, X Y Z A C and F words, read from the text's bytes at once.

    Returns the 0-based indices of those with a G, axis or F word, their rows (G, X, Y, Z, A, C,
    F; NaN where a word is absent), and per-line masks of blank lines and of lines left over for
    the word-by-word route (comments, other letters, lower case, a space after a letter, a word
    twice, G other than 0/1), which also reports what is wrong with a line. Letters become
    spaces and numpy parses the numbers; if their count is not one per letter (a malformed
    number), every line is left over.
    """
    ends = np.flatnonzero(data == 10)  # line k is data[starts[k]:ends[k]]
    starts = np.r_[0, ends + 1]
    ends = np.r_[ends, len(data)]
    kind = words.byte_kind[data]
    if data.size == 0:
        return np.zeros(0, np.int64), np.zeros((0, 7)), np.ones(n_lines, bool), np.zeros(n_lines, bool)
    blank = ~np.logical_or.reduceat(kind != _SPACE, np.minimum(starts, len(data) - 1))
    blank |= starts == ends
    slow = np.zeros(n_lines, bool)
    slow[np.searchsorted(ends, np.flatnonzero(kind == _OTHER))] = True
    letters = np.flatnonzero(kind == _LETTER)
    attached = words.byte_kind[data[np.minimum(letters + 1, len(data) - 1)]] == _DIGITS
    slow[np.searchsorted(ends, letters[~attached | (letters + 1 == len(data))])] = True
    letters = letters[~slow[np.searchsorted(ends, letters)]]
    numbers = data.copy()
    numbers[letters] = 32
    for k in np.flatnonzero(slow):
        numbers[starts[k]:ends[k]] = 32
    try:
        values = np.fromstring(numbers.tobytes(), sep=" ")
    except ValueError:
        values = np.zeros(0)
    if values.size != letters.size:
        return np.zeros(0, np.int64), np.zeros((0, 7)), blank, ~blank
    word, word_line = data[letters], np.searchsorted(ends, letters)
    first = np.r_[True, word_line[1:] != word_line[:-1]]
    row = np.cumsum(first) - 1
    cell = row * 8 + words.column_of[word]  # N words have their own column 7
    twice = np.bincount(cell, minlength=8 * (row[-1] + 1) if row.size else 0) > 1
    slow[word_line[twice[cell]]] = True  # a word twice in a block
    slow[word_line[(word == ord("G")) & (values != 0) & (values != 1)]] = True
    ok = ~slow[word_line] & (word != ord("N"))
    lines_with_words, row = np.unique(word_line[ok], return_inverse=True)
    rows = np.full((lines_with_words.size, 7), np.nan)
    rows[row, words.column_of[word[ok]]] = values[ok]
    return lines_with_words, rows, blank, slow & ~blank


class _Interpreter:
    """The word-by-word route: comments, M/T/S words, G codes other than G0/G1, any spacing/case.

    ``read`` takes one line (1-based number) and returns False once the program has ended
    (M2/M30, or a closing '%'). ``states[i]`` is the modal state after ``change_line[i - 1]``.
    """

    def __init__(self, source: str, opened_at: int, controller: Controller, state: ReadState | None = None) -> None:
        self.source = source
        self.controller, self.facts, self.words = controller, controller.reader, _words(controller)
        m = controller.m_codes
        self.tool_change_code = 10 * m.tool_change
        self.end_codes = {20, 300, 10 * m.end}
        self.first_line = opened_at + 1
        self.rows: list[list[float]] = []
        self.row_line: list[int] = []
        self.states: list[_State] = [_State() if state is None else state.modal]
        self.change_line: list[int] = []
        self.notes: list[ToolNote] = []
        self.lengths: dict[int, float] = {} if state is None else dict(state.lengths)
        self.selected = -1 if state is None else state.selected
        self.work_offset: tuple[float, float, float] | None = None if state is None else state.work_offset
        self.tolerance: tuple[float, float, float] | None = None if state is None else state.tolerance
        self.end_line: int | None = None if state is None else state.end_line
        self.stop_line: int | None = None if state is None else state.stop_line
        self.opened = state is not None and state.opened
        self.closed = False
        self.marked: list[int] = []  # lines of G1 blocks marked as moves between cuts

    def fail(self, number: int, reason: str) -> InputError:
        return InputError(reason, self.source, number)

    def read(self, number: int, raw: str) -> bool:
        text = raw.strip()
        state = self.states[-1]
        if text == "%":
            if number == self.first_line:
                self.opened = True
                return True
            self.closed = True
            self.stop_line = number
            return False
        code = text
        if "(" in text or ")" in text or ";" in text:
            comments: list[str] = []
            code = _COMMENT.sub(lambda match: comments.append(self._comment_text(number, match)) or "", text)
            if "(" in code or ")" in code:
                raise self.fail(number, "unbalanced or nested parenthesis in a comment")
            for comment in comments:
                state = self._comment(number, comment, state)
            if any(c.strip().upper() == RAPID_WORD for c in comments):
                self.marked.append(number)
        code = "".join(code.split()).upper()
        if self.facts.keywords and _BLOCK_NUMBER.sub("", code) in self.facts.keywords:
            return True
        if code.startswith("/"):
            raise self.fail(number, "block delete '/' is not supported: whether the block runs depends on a switch")
        if not _BLOCK.fullmatch(code):
            bad = _BLOCK.match(code)
            rest = code[bad.end():] if bad else code
            raise self.fail(number, f"cannot read '{rest[:20]}': only plain words (letter and number) are supported")
        g_codes, m_codes, values, unknown = [], [], {}, []
        for letter, value in _WORD.findall(code):
            if letter == "G":
                g_codes.append(_code(value))
            elif letter == "M":
                m_codes.append(_code(value))
            elif letter not in self.words.letters:
                unknown.append(letter + value)
            elif letter in values:
                raise self.fail(number, f"two {letter} words in one block")
            else:
                values[letter] = float(value)
        for g in g_codes:
            if g in (0, 10):
                values["G"] = g / 10
            elif g in (930, 940):  # LinuxCNC also sets the feed rate to zero on every G94
                state = replace(state, inverse_time=g == 930, feed_epoch=state.feed_epoch + 1)
            elif g in self.facts.metric or g in self.facts.inch:
                state = replace(state, scale=MM_PER_INCH if g in self.facts.inch else 1.0)
            elif g == 40:
                if "P" not in values:
                    raise self.fail(number, "G4 dwell without P")
            elif g in self.facts.work_offsets:
                raise self.fail(number, f"G{g / 10:g} selects a work offset, which would shift the joints' "
                                        f"positions (the part's offset is the post's: work_offset, --work-offset)")
            elif g not in self.facts.harmless:
                raise self.fail(number, f"G{g / 10:g} is not supported: a joint-space program uses G0/G1 in "
                                        f"absolute distance (G90) without offsets")
        if 640 in g_codes or 51 in g_codes:  # G64 P Q (LinuxCNC's blend and naive-CAM tolerances), FANUC's
            unknown = [word for word in unknown if word[0] != "Q"]  # G05.1 Q1: path control only
        if unknown:  # after the G codes: "G2 is not supported" says more than "I1"
            raise self.fail(number, f"word {unknown[0]}: the VERNE controller has no such word here (axes "
                                    f"{' '.join(self.controller.axes)}; G0/G1 motion)")
        if values.get("D", 0) != 0:
            raise self.fail(number, f"D{values['D']:g}: a tool offset would shift the axes, whose positions already "
                                    f"hold the tool (D0 only)")
        if "T" in values:
            self.selected = int(values["T"])
        if self.tool_change_code in m_codes:
            state = replace(state, tool=self.selected, tool_length=self.lengths.get(self.selected, np.nan))
        if state is not self.states[-1]:
            self.states.append(state)
            self.change_line.append(number)
        row = [values.get(letter, np.nan) for letter in self.words.columns]
        if not all(np.isnan(row)):
            self.rows.append(row)
            self.row_line.append(number)
        if self.end_codes.intersection(m_codes):
            self.end_line = self.stop_line = number
            return False
        return True

    def _comment_text(self, number: int, match: re.Match[str]) -> str:
        """The text of a comment the controller takes as one."""
        if match.group(1) is not None and not self.facts.parenthesis_comments:
            raise self.fail(number, f"parentheses are not a comment on {self.controller.dialect}: "
                                    f"its comments start with ';'")
        if match.group(1) is None and not self.facts.semicolon_comments:
            raise self.fail(number, f"';' is not a comment on {self.controller.dialect}: its comments are in ( )")
        return match.group(1) if match.group(1) is not None else match.group(2)

    def _comment(self, number: int, comment: str, state: _State) -> _State:
        """Tool lengths and the header's work offset and tolerances."""
        note = _TOOL_NOTE.match(comment)
        if note:
            tool = int(note.group(1))
            self.notes.append(ToolNote(number, tool, float(note.group(2)), float(note.group(3))))
            self.lengths[tool] = self.notes[-1].length
            if tool == state.tool or tool == 0:  # tool 0: tool data without a number, for the spindle's tool
                return replace(state, tool=tool, tool_length=self.notes[-1].length)
        elif self.work_offset is None and (match := _WORK_OFFSET.match(comment)):
            self.work_offset = (float(match.group(1)), float(match.group(2)), float(match.group(3)))
        elif self.tolerance is None and (match := _TOLERANCE.match(comment)):
            rapids = _RAPID_TOLERANCE.search(comment)
            self.tolerance = (float(match.group(1)), float(match.group(2)),
                              float(rapids.group(1)) if rapids else np.nan)
        return state


def _resolve(source: str, table: np.ndarray, line: np.ndarray, state: np.ndarray, reader: _Interpreter,
             problems: list[tuple[int, str]], last_line: int, read: int, before: ReadState | None) -> GcodeProgram:
    """Modal positions, motion modes and feeds of all rows at once (``state``: index into
    ``reader.states`` per row; ``before``: the reading of the text before); keep the moves."""
    # Row 0: what was given before this text (mm and degrees already), so that modal values carry on.
    given = np.full(7, np.nan) if before is None else np.r_[before.motion, before.position, before.feed]
    table, line, state = np.r_[given[None], table], np.r_[0, line], np.r_[0, state]

    def of_state(name: str, dtype: type) -> np.ndarray:
        return np.array([getattr(s, name) for s in reader.states], dtype=dtype)[state]

    scale, inverse_time, epoch = of_state("scale", float), of_state("inverse_time", bool), of_state("feed_epoch", int)
    scale[0], epoch[0] = 1.0, -1 if before is None else before.feed_epoch
    everywhere = np.zeros(len(table), np.int64)
    axes = any_of(~np.isnan(table[:, 1:6]))
    moves = axes | ~np.isnan(table[:, 0])  # a G0/G1 word alone is a move of length zero (as LinuxCNC does)
    moves[0] = False
    motion = _last_given(table[:, 0], everywhere)
    orphan = axes & np.isnan(motion)
    if orphan.any():
        raise InputError("axis words without a motion mode (G0 or G1)", source, int(line[np.argmax(orphan)]))
    position = table[:, 1:6].copy()
    position[:, :3] *= scale[:, None]
    position = np.column_stack([_last_given(position[:, k], everywhere) for k in range(5)])
    # G93: the F word is not modal; G94: the last F since the last G93/G94 word.
    given_feed = _last_given(table[:, 6], epoch)
    feed = np.where(inverse_time, table[:, 6], given_feed)
    positioning = motion == 0
    feed[positioning] = np.nan
    # a G1 marked (RAPID) is a move between cuts: timed as written, judged as a rapid
    rapid = positioning | np.isin(line, np.asarray(reader.marked, dtype=np.int64))
    keep = np.flatnonzero(moves)
    for k in keep[~positioning[keep] & ~(feed[keep] > 0)]:
        problems.append((int(line[k]), "G1 in inverse time (G93) without an F word" if inverse_time[k] else
                         "G1 with no feed rate (no F since the start or since G94)" if np.isnan(feed[k]) else
                         f"G1 with feed rate F{feed[k]:g}"))
    joints = position[keep]
    duration = _durations(joints, scale[keep], positioning[keep], inverse_time[keep], feed[keep], position[0])
    joints[:, 3:] = np.radians(joints[:, 3:])
    after = ReadState(read, reader.states[-1], reader.lengths, reader.selected, reader.work_offset,
                      reader.tolerance, reader.opened, reader.end_line, reader.stop_line, last_line, motion[-1],
                      position[-1], given_feed[-1], int(epoch[-1]))
    return GcodeProgram(
        source=source, joints=joints, rapid=rapid[keep], inverse_time=inverse_time[keep], feed=feed[keep],
        duration=duration, line=line[keep], tool=of_state("tool", int)[keep],
        tool_length=of_state("tool_length", float)[keep], tool_notes=tuple(reader.notes),
        work_offset=reader.work_offset, tolerance=reader.tolerance, end_line=reader.end_line, last_line=last_line,
        problems=tuple(sorted(problems)), state=after,
    )


def _last_given(values: np.ndarray, group: np.ndarray) -> np.ndarray:
    """The last non-NaN value at or before each row within its group (groups are runs of equal,
    non-decreasing numbers); NaN where there is none."""
    rows = np.arange(len(values))
    source = np.maximum.accumulate(np.where(np.isnan(values), -1, rows)) if len(values) else rows
    start = np.searchsorted(group, group, side="left")
    return np.where(source >= start, values[np.maximum(source, 0)], np.nan)


def _durations(position: np.ndarray, scale: np.ndarray, rapid: np.ndarray, inverse_time: np.ndarray,
               feed: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Seconds of each G1 block (positions mm / deg, F as programmed in units of ``scale`` mm;
    ``start``: the position before the first, NaN where unknown)."""
    step = np.diff(position, axis=0, prepend=start[None])
    linear = norms(step[:, :3])
    with np.errstate(divide="ignore", invalid="ignore"):
        per_minute = np.where(any_of(step[:, :3] != 0), linear / (feed * scale),
                              norms(step[:, 3:]) / feed)
        minutes = np.where(inverse_time, 1.0 / feed, per_minute)
    minutes[rapid | ~(feed > 0)] = np.nan
    return 60.0 * minutes
