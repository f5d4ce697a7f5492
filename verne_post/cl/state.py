"""The reader's state: poses read so far, modal settings, and the helpers every record family uses.

All lengths inside are in the file's units and in the CL frame of the record that wrote them;
:meth:`ReaderState.result` converts to mm and to the part frame once, over whole arrays.
"""

from __future__ import annotations

import math
import re
from array import array
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from verne_post.cl.toolpath import MOTION_KINDS, Event
from verne_post.errors import CheckError, InputError

from .dialects import Dialect

MM_PER_INCH = 25.4
MAX_COORD = 1e7  # |coordinate| limit in file units: anything larger is corrupt data
MAX_TOOL_NUMBER = 999_999_999
MAX_EXPANDED_POSES = 20_000_000  # arcs, splines and cycles may not expand a file beyond this
AXIS_LEN_TOL = 0.01  # a tool axis may be off unit length by this much (rounded CL output)

_NUM_RE = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\Z")
_WORD_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-]*\Z")
MOTION = {name: code for code, name in enumerate(MOTION_KINDS)}

Units = Literal["mm", "inch"]
Token = float | str
UNIT_WORDS: dict[str, Units] = {
    "MM": "mm", "MILLIMETERS": "mm", "MILLIMETRES": "mm", "INCH": "inch", "INCHES": "inch", "IN": "inch",
}  # fmt: skip


def parse_number(tok: str, what: str, src: str, line: int) -> float:
    """Strict APT number (``25.``, ``.5``, ``-1.E+02``); NaN, inf, overflow and anything else raise."""
    t = tok.strip()
    if _NUM_RE.match(t):
        value = float(t)
        if math.isinf(value):
            raise InputError(f"number {t} out of range in {what}", source=src, line=line)
        return value
    low = t.lower().lstrip("+-")
    if low == "nan":
        raise InputError(f"NaN in {what}", source=src, line=line)
    if low in ("inf", "infinity"):
        raise InputError(f"infinite value in {what}", source=src, line=line)
    if not t:
        raise InputError(f"empty field in {what}", source=src, line=line)
    raise InputError(f"'{t}' is not a number", source=src, line=line)


@dataclass
class Warnings:
    """Warnings grouped by kind: one line each, with the first line and how often it occurred."""

    src: str
    kinds: dict[str, list[Any]] = field(default_factory=dict)  # kind -> [first line, text, count]

    def add(self, line: int | None, text: str, kind: str | None = None) -> None:
        entry = self.kinds.setdefault(kind or text, [line, text, 0])
        entry[2] += 1

    def lines(self) -> tuple[str, ...]:
        out = []
        for line, text, count in self.kinds.values():
            where = f"{self.src}:{line}: " if line is not None else f"{self.src}: "
            more = f" ({count} records like this, the first here)" if count > 1 else ""
            out.append(f"{where}{text}{more}")
        return tuple(out)


class PoseRows:
    """Rows of six floats (x, y, z, i, j, k) appended one by one, held as one packed buffer (8
    bytes a number, not a Python list of float objects)."""

    def __init__(self) -> None:
        self.data = array("d")

    def __len__(self) -> int:
        return len(self.data) // 6

    def append(self, row: list[float]) -> None:
        self.data.extend(row)

    def extend(self, rows: np.ndarray) -> None:
        self.data.frombytes(np.ascontiguousarray(rows, dtype=float).tobytes())

    def __getitem__(self, k: int) -> list[float]:
        k = k % len(self)
        return self.data[6 * k:6 * k + 6].tolist()

    def array(self) -> np.ndarray:
        """(N, 6), a view of the buffer (valid until the next append)."""
        return np.frombuffer(self.data, dtype=float).reshape(-1, 6)


@dataclass
class Clearance:
    """The clearance surface of a CLEARP / CLRSRF record (file units, in the CL frame ``frame``): the
    plane normal · x = distance, or the plane through ``point`` normal to the tool axis at the
    retract, or neither (a form the reader does not use)."""

    line: int
    frame: int
    normal: np.ndarray | None = None
    distance: float = 0.0
    point: np.ndarray | None = None


@dataclass
class Arc:
    """An arc's record for the direction check: pose indices and its centre and unit axis (file units)."""

    start: int  # pose index of the arc's start point
    end: int  # pose index of its end point
    centre: np.ndarray
    axis: np.ndarray
    line: int


class ReaderState:
    """Poses, modal state and shared helpers; record handlers (the family modules) act on it."""

    def __init__(self, src: str, units: Units, units_given: bool, tol_mm: float, dialect: Dialect,
                 warnings: Warnings, default_feed: float | None = None) -> None:
        self.src = src
        self.units: Units = units
        self.units_given = units_given
        self.scale = MM_PER_INCH if units == "inch" else 1.0
        self.tol = tol_mm / self.scale  # chordal tolerance in file units
        self.dialect = dialect
        self.arc_direction = dialect.arc_direction or "ccw"  # a provisional reading where undocumented
        self.warnings = warnings
        # poses: rows of [x, y, z, i, j, k] in the CL frame of their run, file units
        self.rows = PoseRows()
        self.lines = array("q")
        self.motion: dict[int, int] = {}  # pose index -> MOTION code where not a plain feed move
        self.feed_override: dict[int, float] = {}
        # modal runs: (first pose index, feed mm/min or 1/min, inverse time, tool, frame id)
        # --feed (mm/min): the feed of the feed moves before the first FEDRAT (CAM output such as
        # NCL's APT source may have no FEDRAT at all)
        self.default_feed = default_feed
        self.first_fedrat: int | None = None  # pose count at the first FEDRAT with a feed
        start_feed = math.nan if default_feed is None else default_feed
        self.runs: list[tuple[int, float, bool, int, int]] = [(0, start_feed, False, 0, 0)]
        self.events: list[Event | None] = []
        self.frames: list[tuple[np.ndarray, np.ndarray]] = [(np.eye(3), np.zeros(3))]
        self.frame_id = 0
        self.frame_declared = False  # a frame record has been read
        self.index: tuple[int, int, float] | None = None  # ROTATE: (axis 0-2, the frame indexed, angle deg)
        self.arcs: list[Arc] = []
        self.axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
        self.rapid_next = False
        self.feed_val = start_feed
        self.inverse = False
        self.feed_problem = "feed move before any FEDRAT: the file gives no feed here; give one with --feed MM/MIN"
        self.fpr: float | None = None  # feed per revolution, mm/rev
        self.rpm: float | None = None
        self.spindle_dir: Literal["CW", "CCW"] = "CW"
        self.spindle_on = False
        self.tool = 0
        self.multax: bool | None = None
        self.locked_axis_line: int | None = None  # a MULTAX/OFF that left the tool axis undecided (dialects)
        self.cycle: Any = None  # the active drilling cycle, (cycles.CycleSpec, feed mm/min), or None
        self.last_cycle: Any = None
        self.last_cycle_tokens: list[Any] = []  # the record that defined last_cycle, for CYCLE/ON changes
        self.cycle_start: np.ndarray | None = None  # the tool tip when the cycle began (RTRCTO,AUTO)
        self.curve: Any = None  # a CIRCLE/MOVARC waiting for its end GOTO, or a NURBS being read
        self.skip_goto: np.ndarray | None = None  # a GOTO repeating this point (a spline's end) adds nothing
        self.home: tuple[int, np.ndarray, np.ndarray] | None = None  # FROM pose: (frame id, tip, axis) in it
        self.clearance: Clearance | None = None  # the surface RETRCT withdraws to
        self.homeless: int | None = None  # the line of a GOHOME with no FROM: only the program's end may follow
        self.indirv: tuple[np.ndarray, int, int] | None = None  # INDIRV: (unit direction, pose count, line)
        self.last_arc: Any = None  # (curves.PendingArc, pose count) of the arc the last GOTO ended
        self.part_name: str | None = None
        self.units_seen: tuple[Units, int] | None = None
        self.cutcom_warned = False
        self.done = False
        self.tools: Any = None  # tools.ToolHeader: tool loads and data of the current operation header
        # A malformed machine-function record (CATIA's user-typed SPINDL/900CCLW) waiting for a valid
        # one of its word to replace it before any motion: word -> (its line, its text, the error)
        self.malformed: dict[str, tuple[int, str, InputError]] = {}
        self.pp_words: dict[str, int] = {}  # CATIA PP words typed by the user (not CL records): text -> first line

    # ------------------------------------------------------------------ messages

    def fail(self, reason: str, line: int | None) -> InputError:
        return InputError(reason, source=self.src, line=line)

    def other_machine(self, reason: str, line: int | None) -> CheckError:
        """A well-formed program for another kind of machine (a lathe, several heads): exit code 3,
        as for any program this machine cannot run."""
        return CheckError(reason, source=self.src, line=line)

    def warn(self, line: int | None, text: str, kind: str | None = None) -> None:
        self.warnings.add(line, text, kind)

    # ------------------------------------------------------------------ tokens

    def number(self, tok: str, what: str, line: int) -> float:
        return parse_number(tok, what, self.src, line)

    def numbers(self, args: str, what: str, line: int) -> list[float]:
        if not args.strip():
            return []
        return [self.number(t, what, line) for t in args.split(",")]

    def tokens(self, args: str, what: str, line: int) -> list[Token]:
        """Split ``args`` into numbers (float) and upper-case words (str, e.g. ``1STPECK``)."""
        out: list[Token] = []
        if not args.strip():
            return out
        for tok in args.split(","):
            t = tok.strip()
            if _NUM_RE.match(t):
                out.append(self.number(t, what, line))
            elif t.lower().lstrip("+-") in ("nan", "inf", "infinity") or not t:
                self.number(t, what, line)  # raises with the right message
            elif _WORD_RE.match(t):
                out.append(t.upper())
            else:
                raise self.fail(f"'{t}' is not a number or a word in {what}", line)
        return out

    def coordinate(self, values: list[float], what: str, line: int) -> None:
        if any(abs(v) > MAX_COORD for v in values):
            raise self.fail(f"coordinate out of range in {what} (|value| > {MAX_COORD:g})", line)

    def check_axis(self, a: list[float] | tuple[float, ...], what: str, line: int) -> None:
        n = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
        if n < 1e-6:
            raise self.fail(f"{what} has zero length", line)
        if abs(n - 1.0) > AXIS_LEN_TOL:
            raise self.fail(f"{what} has length {n:.6g}, expected a unit vector", line)

    # ------------------------------------------------------------------ poses and modal state

    def fast_goto_ok(self) -> bool:
        """True when a plain GOTO needs nothing but appending (the reader's fast path)."""
        return (
            not self.rapid_next
            and self.feed_val == self.feed_val  # a feed is programmed (not NaN)
            and self.cycle is None
            and self.curve is None
            and self.skip_goto is None
            and (self.tools is None or not self.tools.open)
            and self.multax is not False
            and self.homeless is None
            and not self.malformed
        )

    def push_state(self) -> None:
        state = (len(self.lines), self.feed_val, self.inverse, self.tool, self.frame_id)
        last = self.runs[-1]
        same_feed = last[1] == state[1] or (last[1] != last[1] and state[1] != state[1])
        if same_feed and last[2:] == state[2:]:
            return
        if last[0] == state[0]:
            self.runs[-1] = state
        else:
            self.runs.append(state)

    def carried_axis(self, what: str, line: int) -> None:
        """Refuse a motion that needs the carried tool axis where MULTAX/OFF left it undecided."""
        if self.locked_axis_line is not None:
            a = ", ".join(f"{v:.6g}" for v in self.axis)
            raise self.fail(f"{what} after MULTAX/OFF (line {self.locked_axis_line}), which followed the tilted tool "
                            f"axis ({a}): {self.dialect.name} does not document whether the axis stays so (as CATIA's "
                            "does) or returns to (0,0,1) (as Fusion's does); give TLAXIS/i,j,k after MULTAX/OFF", line)

    def add_pose(self, p: list[float] | np.ndarray, a: tuple[float, ...] | np.ndarray, line: int, rapid: bool,
                 feed: float | None = None, motion: str = "feed") -> None:
        self.skip_goto = None  # only the motion right after a spline may repeat its end
        if self.homeless is not None:
            raise self.fail("GOHOME without a FROM position (the machine's home is not known here), and motion "
                            "after it", self.homeless)
        if self.malformed:
            self.motion_after_malformed()
        if self.tools is not None and self.tools.open:
            self.tools.close(self)
        if not rapid and feed is None and self.feed_val != self.feed_val:
            raise self.fail(self.feed_problem, line)
        idx = len(self.lines)
        self.rows.append([float(p[0]), float(p[1]), float(p[2]), float(a[0]), float(a[1]), float(a[2])])
        self.lines.append(line)
        code = MOTION["rapid"] if rapid else MOTION[motion]
        if code:
            self.motion[idx] = code
        if feed is not None and not rapid:
            self.feed_override[idx] = feed

    def add_poses(self, points: np.ndarray, axes: np.ndarray, line: int, rapid: bool, motion: str) -> None:
        """Append expanded curve poses (N, 3) at once, all carrying ``line``."""
        if not len(points):
            return
        if len(self.lines) + len(points) > MAX_EXPANDED_POSES:
            raise self.fail(f"the expanded toolpath exceeds {MAX_EXPANDED_POSES:,} poses: a larger --arc-tol, or "
                            "split the program", line)
        self.add_pose(points[0], axes[0], line, rapid, motion=motion)
        start = len(self.lines)
        self.rows.extend(np.hstack([points[1:], axes[1:]]))
        self.lines.extend([line] * (len(points) - 1))
        code = MOTION["rapid"] if rapid else MOTION[motion]
        if code:
            self.motion.update(dict.fromkeys(range(start, len(self.lines)), code))

    def motion_after_malformed(self) -> None:
        """Motion while a malformed machine-function record is in force: its error, as for any record."""
        _line, _text, error = min(self.malformed.values(), key=lambda m: m[0])
        raise error

    def take_rapid(self) -> bool:
        r = self.rapid_next
        self.rapid_next = False
        return r

    def frame_of_pose(self, idx: int) -> int:
        for start, _f, _i, _t, frame in reversed(self.runs):
            if start <= idx:
                return frame
        return 0

    def to_part(self, p: np.ndarray, a: np.ndarray, frame: int) -> tuple[np.ndarray, np.ndarray]:
        R, o = self.frames[frame]
        return o + R @ p, R @ a

    def from_part(self, p: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R, o = self.frames[self.frame_id]
        return R.T @ (p - o), R.T @ a

    def to_current(self, p: np.ndarray, a: np.ndarray, frame: int) -> tuple[np.ndarray, np.ndarray]:
        """A point and a direction given in CL frame ``frame``, in the current CL frame (file units)."""
        return self.from_part(*self.to_part(p, a, frame))

    def current_pose(self, what: str, line: int) -> tuple[np.ndarray, np.ndarray]:
        """Last pose (tip, unit axis) expressed in the current CL frame."""
        if not self.rows:
            raise self.fail(f"{what} with no current position (no GOTO or FROM before it)", line)
        row = np.array(self.rows[-1], dtype=float)
        p, a = row[:3], row[3:] / np.linalg.norm(row[3:])
        frame = self.frame_of_pose(len(self.rows) - 1)
        if frame != self.frame_id:
            p, a = self.to_current(p, a, frame)
        return p, a

    # ------------------------------------------------------------------ result


#: Poses validated at once (bounds the temporary arrays of a long toolpath).
_VALIDATE_CHUNK = 1 << 16


def validate_poses(tip: np.ndarray, axis: np.ndarray, line: np.ndarray, src: str, what: str) -> None:
    """Raise for the first (by line) pose with a non-finite value or a non-unit / zero tool axis."""
    bad = np.concatenate([_bad_poses(tip[k:k + _VALIDATE_CHUNK], axis[k:k + _VALIDATE_CHUNK]) + k
                          for k in range(0, len(tip), _VALIDATE_CHUNK)] or [np.zeros(0, np.int64)])
    if not bad.size:
        return
    k = int(bad[np.argmin(line[bad])])
    row = np.concatenate([tip[k], axis[k]])
    norm = float(np.sqrt(np.sum(np.where(np.isfinite(axis[k]), axis[k], 0.0) ** 2)))
    if np.isnan(row).any():
        reason = f"NaN in {what}"
    elif not np.isfinite(row).all():
        reason = f"infinite value in {what}"
    elif (np.abs(tip[k]) > MAX_COORD).any():
        reason = f"coordinate out of range in {what} (|value| > {MAX_COORD:g})"
    elif norm < 1e-6:
        reason = "tool axis has zero length"
    else:
        reason = f"tool axis has length {norm:.6g}, expected a unit vector"
    raise InputError(reason, source=src, line=int(line[k]))


def _bad_poses(tip: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Indices of the poses with a non-finite value, a coordinate out of range, or an axis not of unit length."""
    finite = np.isfinite(tip).all(axis=1) & np.isfinite(axis).all(axis=1)
    safe = np.where(np.isfinite(axis), axis, 0.0)
    norms = np.sqrt(np.einsum("ij,ij->i", safe, safe))
    huge = (np.abs(np.where(np.isfinite(tip), tip, 0.0)) > MAX_COORD).any(axis=1)
    return np.flatnonzero(~finite | huge | (norms < 1e-6) | (np.abs(norms - 1.0) > AXIS_LEN_TOL))
