"""Read APT / CLSF cutter-location files and CSV pose lists into a :class:`~verne_post.toolpath.Toolpath`.

Units and frames
----------------
Every output position (tip points, tool lengths and diameters) is in **mm** and every feed in
**mm/min** (inverse-time feeds in 1/min), whatever the source units: inch files are scaled by
25.4. Tips and tool axes are in the **part frame**: the active ``MSYS``/``CSYS`` (origin + rotation
of the CL frame expressed in the part frame) is applied as ``tip = origin + R @ p`` and
``axis = R @ a`` (X and Y must be unit and orthogonal within 1e-3; they are then
orthonormalised and Z = X x Y). Tool axes are unit vectors pointing from the tip towards the
spindle: axes within 1 % of unit length (rounded CAM output) are normalised, zero or clearly
non-unit axes are rejected. Each pose keeps the 1-based line where its record starts.
``Toolpath.units`` records the *source* units (``"mm"`` or ``"inch"``).

Source units are decided before parsing, in this order: the ``units=`` argument; else the
``UNITS/`` (or ``UNIT/``) record; else the first per-minute / per-rev feed word (``IPM``/``IPR``
mean inch, ``MMPM``/``MMPR`` mean mm) of a ``FEDRAT`` or ``CYCLE`` record; else mm. The last two
cases add a warning. A file whose ``UNITS`` records disagree with each other is rejected.

Records
-------
Motion: ``GOTO/x,y,z[,i,j,k]`` (3 numbers carry the last tool axis, initially (0,0,1); any other
count, e.g. 7+ numbers, is an error because no CAM format we know defines it), ``FROM/``
(a rapid pose, remembered for ``GOHOME``), ``GOHOME`` (rapid back to the ``FROM`` pose),
``GODLTA/d`` (along the tool axis) and ``GODLTA/dx,dy,dz``, ``CIRCLE/xc,yc,zc,i,j,k,r[,...]``
(the next ``GOTO`` ends the arc; the arc runs counter-clockwise about the circle axis and is
interpolated into poses within ``chordal_tolerance`` mm, at least 2 segments of at most 90 deg,
with the tool axis slerped; helical arcs are allowed), ``RAPID``
(next motion only), ``FEDRAT`` (``MMPM``/``IPM``/``MMPR``/``IPR``/``INVERS`` before or after the
value, or bare = file units per minute; modal), ``MULTAX/ON|OFF`` (``OFF`` resets the axis to
(0,0,1) and forbids 6-number ``GOTO``), ``TLAXIS/i,j,k`` (sets the carried axis),
``MSYS``/``CSYS``, ``UNITS``/``UNIT``.

Events: ``LOAD/TOOL,n[,ADJUST,h]``, ``LOADTL/n[,LENGTH,l][,ADJUST,h]`` and ``SELECT/TOOL,n`` (a
load only when the operation header has no ``LOAD``/``LOADTL``; otherwise a pre-selection) give one
:class:`ToolChange` per load. ``TLDATA/MILL|DRILL,dia,r,length,...`` and ``CUTTER/dia[,...]``
in the same header (the records between two motions) are merged into that load, before or after
it. Without any load in the header they produce a ToolChange for the current tool number (0 if
none was ever loaded, with a warning) when the geometry differs from the active one.
``SPINDL`` -> :class:`Spindle`, ``COOLNT`` -> :class:`Coolant`, ``STOP``/``OPSTOP`` ->
:class:`Stop`, ``PPRINT``, ``TOOL PATH`` (operation name), ``INSERT`` (with a warning: it is not
executed) and later ``PARTNO`` records -> :class:`Comment`; the first ``PARTNO`` is the part name.
``PPRINT``/``PARTNO``/``INSERT`` text is taken literally (no ``$$`` or ``$`` processing).

Ignored: ``$$`` comments, display and CAM-setup records (``PAINT``, ``DISPLY``, ``PEN``, ...),
``END-OF-PATH``, ``END``, ``CUTCOM/OFF``; parsing stops at ``FINI``. NX "Information listing"
header lines (``====``, ``Information listing created by :``, ``Date :``, ``Current work part :``,
``Node name :``) before the first record, and ``Tool Path Listing has N lines.`` anywhere, are
skipped. Any other record gives the warning ``file:line: unknown record 'WORD' ignored``, except
records that would change the geometry and cannot be honoured (``ORIGIN``, ``TRANS``, ``INDEX``,
``COPY``, ``GOFWD``..., ``CUTCOM/LEFT|RIGHT``, constant-surface-speed ``SPINDL``): those raise.

Drilling cycles
---------------
Only plain drilling is expanded: ``CYCLE/DRILL`` with the depth given positionally, as
``DEPTH,d`` or as ``FEDTO,d`` (NX writes it negative; its magnitude is used), the feed as
``[FEDRAT,]MMPM|IPM|MMPR|IPR,f``, ``f,UNIT`` or ``FEDRAT,f`` (file units/min; if absent the
active ``FEDRAT``), and the clearance as ``CLEAR,c`` and/or ``RAPTO,r`` (plus optional
``RTRCTO,AUTO|v``). For every ``GOTO`` until ``CYCLE/OFF`` (the hole top, tool axis as usual)
three poses are emitted: rapid to top + approach * axis (``RAPTO``, else ``CLEAR``), feed to
top - depth * axis, rapid to top + retract * axis (the largest of ``CLEAR``/``RAPTO``/``RTRCTO``).
``CYCLE/ON`` re-activates the last cycle. Peck drilling (``CYCLE/DEEP``, ``CYCLE/DRILL,DEEP``),
chip breaking (``BRKCHP``), dwell (``DWELL``), tapping, boring, reaming and every other cycle are
rejected with an :class:`~verne_post.errors.InputError`: expanding them as plain drilling would
not cut what the CAM programmed.

Errors are :class:`~verne_post.errors.InputError` with the file name as given and the 1-based
line where the offending record starts.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import numpy as np

from verne_post.errors import InputError
from verne_post.tables import read_table
from verne_post.toolpath import Comment, Coolant, Event, Spindle, Stop, ToolChange, Toolpath

__all__ = ["read_cl", "read_pose_csv", "read_toolpath"]

Units = Literal["mm", "inch"]

MM_PER_INCH = 25.4

_NUM_RE = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\Z")
_WORD_RE = re.compile(r"[A-Za-z][A-Za-z0-9_.\-]*\Z")
_CTRL_RE = re.compile(r"[\x00-\x08\x0b\x0e-\x1f\x7f]")
_UNITS_RE = re.compile(r"^[ \t]*UNITS?[ \t]*/[ \t]*([A-Za-z]+)", re.IGNORECASE | re.MULTILINE)
_FEED_UNIT_RE = re.compile(
    r"^[ \t]*(?:FEDRAT|CYCLE)[ \t]*/[^\n$]*?\b(IPM|IPR|MMPM|MMPR)\b", re.IGNORECASE | re.MULTILINE
)
# NX "Information listing" header lines (only before the first APT record) and trailer lines.
_HEADER_RE = re.compile(
    r"(?:=+|-{3,}|Information listing created by\s*:.*|(?:Date|Current work part|Node name)\s*:.*)\Z",
    re.IGNORECASE,
)
_TRAILER_RE = re.compile(r"(?:Tool Path Listing has \d+ lines\.?|=+)\Z", re.IGNORECASE)

_UNIT_WORDS: dict[str, Units] = {
    "MM": "mm",
    "MILLIMETERS": "mm",
    "MILLIMETRES": "mm",
    "INCH": "inch",
    "INCHES": "inch",
    "IN": "inch",
}
_FEED_WORDS = {"MMPM", "IPM", "MMPR", "IPR"}
_TEXT_RECORDS = {"PPRINT", "PARTNO", "INSERT"}
_IGNORED = {
    "PAINT", "DISPLY", "PEN", "AUTOPS", "CLRSRF", "OPERATION", "TPRINT", "PPLOT", "TOLER",
    "INTOL", "OUTTOL", "MACHIN", "SEQNO", "END-OF-PATH", "END", "PLABEL", "CLEARP",
}  # fmt: skip
_REJECTED = {
    "ORIGIN": "ORIGIN (coordinate shift) is not supported; output the CL data in one MSYS",
    "TRANS": "TRANS (coordinate transformation) is not supported; output the CL data in one MSYS",
    "REFSYS": "REFSYS (reference system) is not supported; use MSYS",
    "INDEX": "INDEX/COPY (repeated motion) is not supported; output the motion explicitly",
    "COPY": "INDEX/COPY (repeated motion) is not supported; output the motion explicitly",
    "GOFWD": "motion record GOFWD is not supported: the CL file must contain explicit GOTO points",
    "GOLFT": "motion record GOLFT is not supported: the CL file must contain explicit GOTO points",
    "GORGT": "motion record GORGT is not supported: the CL file must contain explicit GOTO points",
    "GOBACK": "motion record GOBACK is not supported: the CL file must contain explicit GOTO points",
    "GOUP": "motion record GOUP is not supported: the CL file must contain explicit GOTO points",
    "GODOWN": "motion record GODOWN is not supported: the CL file must contain explicit GOTO points",
    "GO": "motion record GO is not supported: the CL file must contain explicit GOTO points",
    "INDIRV": "INDIRV is not supported: the CL file must contain explicit GOTO points",
    "INDIRP": "INDIRP is not supported: the CL file must contain explicit GOTO points",
}
_CYCLE_REJECTED = {
    "DEEP": "peck drilling (DEEP)",
    "BRKCHP": "chip-breaking drilling (BRKCHP)",
    "DWELL": "drilling with dwell (DWELL)",
    "TAP": "tapping (TAP)",
    "BORE": "boring (BORE)",
    "REAM": "reaming (REAM)",
    "CSINK": "countersinking (CSINK)",
    "FACE": "spot facing (FACE)",
    "THRU": "through-drilling (THRU)",
    "MILL": "milling cycle (MILL)",
}
_ANG_TOL = 1e-3  # tolerance on unit length / orthogonality of MSYS and CSYS axes
_AXIS_LEN_TOL = 0.01  # a tool axis may be off unit length by this much (rounded CL output)
_MAX_COORD = 1e7  # |coordinate| limit in source units: larger values are corrupt data


def _parse_number(tok: str, what: str, src: str, line: int) -> float:
    """Strict APT number (``25.``, ``.5``, ``-1.E+02``); NaN, inf and anything else raise."""
    t = tok.strip()
    if _NUM_RE.match(t):
        return float(t)
    low = t.lower().lstrip("+-")
    if low == "nan":
        raise InputError(f"NaN in {what}", source=src, line=line)
    if low in ("inf", "infinity"):
        raise InputError(f"infinite value in {what}", source=src, line=line)
    if not t:
        raise InputError(f"empty field in {what}", source=src, line=line)
    raise InputError(f"'{t}' is not a number", source=src, line=line)


def _same_state(a: tuple[float, bool, int, int], b: tuple[float, bool, int, int]) -> bool:
    """Equal modal states, NaN feeds comparing equal."""
    return a[1:] == b[1:] and (a[0] == b[0] or (a[0] != a[0] and b[0] != b[0]))


def _source(path: str | os.PathLike[str]) -> str:
    return os.fspath(path)


def _read_text(path: str | os.PathLike[str], src: str) -> str:
    """Read a text file; reject binary data (NUL bytes, undecodable or control characters)."""
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        raise InputError("file not found", source=src) from None
    except IsADirectoryError:
        raise InputError("is a directory, not a file", source=src) from None
    except OSError as exc:
        raise InputError(f"cannot read file: {exc.strerror or exc}", source=src) from None
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):  # UTF-16 with BOM (Windows "Unicode" text)
        try:
            text = data.decode("utf-16")
        except UnicodeDecodeError:
            raise InputError("not a text CL file (undecodable UTF-16)", source=src) from None
    elif b"\x00" in data:
        raise InputError("not a text CL file (contains NUL bytes)", source=src)
    else:
        try:
            text = data.decode("utf-8-sig")
        except UnicodeDecodeError:
            try:
                text = data.decode("cp1252")
            except UnicodeDecodeError:
                raise InputError("not a text CL file (undecodable bytes)", source=src) from None
    text = text.rstrip("\x1a")  # DOS end-of-file marker
    bad = _CTRL_RE.search(text)
    if bad is not None:
        line = text.count("\n", 0, bad.start()) + 1
        raise InputError(f"not a text CL file (control character {bad.group()!r})", source=src, line=line)
    return text


def _split_lines(text: str) -> list[str]:
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    return lines


def _check_units_arg(units: str | None) -> Units | None:
    if units is None or units in ("mm", "inch"):
        return units  # type: ignore[return-value]
    raise InputError(f"units must be 'mm' or 'inch', got {units!r}")


def _decide_units(text: str, override: Units | None, src: str, warnings: list[str]) -> Units:
    """Source units of a CL file (see module docstring for the order of precedence)."""
    if override is not None:
        return override
    m = _UNITS_RE.search(text)
    if m is not None:
        word = m.group(1).upper()
        if word not in _UNIT_WORDS:
            line = text.count("\n", 0, m.start()) + 1
            raise InputError(f"unknown UNITS '{m.group(1)}' (expected MM or INCHES)", source=src, line=line)
        return _UNIT_WORDS[word]
    m = _FEED_UNIT_RE.search(text)
    if m is not None:
        word = m.group(1).upper()
        units: Units = "inch" if word in ("IPM", "IPR") else "mm"
        line = text.count("\n", 0, m.start()) + 1
        warnings.append(f"{src}:{line}: no UNITS record: {units} inferred from {word} feed")
        return units
    warnings.append(f"{src}: no UNITS record and no IPM/MMPM feed: assuming mm")
    return "mm"


class _Parser:
    """State machine over the logical records of one CL file (all lengths in file units inside)."""

    def __init__(self, src: str, units: Units, override: bool, tol_mm: float, warnings: list[str]) -> None:
        self.src = src
        self.units: Units = units
        self.units_override = override
        self.scale = MM_PER_INCH if units == "inch" else 1.0
        self.tol = tol_mm / self.scale  # chordal tolerance in file units
        self.warnings = warnings
        # poses: rows of [x, y, z, i, j, k] in the CL frame of their run, file units
        self.rows: list[list[float]] = []
        self.lines: list[int] = []
        self.rapid_idx: list[int] = []
        self.feed_override: dict[int, float] = {}
        # modal state runs: (first pose index, feed mm/min or 1/min, inverse, tool, frame id)
        self.runs: list[tuple[int, float, bool, int, int]] = [(0, math.nan, False, 0, 0)]
        self.events: list[Event | None] = []
        self.frames: list[tuple[np.ndarray, np.ndarray]] = [(np.eye(3), np.zeros(3))]
        self.frame_id = 0
        self.axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
        self.rapid_next = False
        self.feed_val = math.nan
        self.inverse = False
        self.feed_problem = "feed move before any FEDRAT"
        self.fpr: float | None = None  # feed per revolution, mm/rev
        self.rpm: float | None = None  # last programmed speed
        self.spindle_dir: Literal["CW", "CCW"] = "CW"
        self.spindle_on = False
        self.tool = 0
        self.active_geom: tuple[float | None, float | None] | None = None
        self.header_open = False
        self.h_loads: list[dict[str, Any]] = []
        self.h_geoms: list[dict[str, Any]] = []
        self.h_select: dict[str, Any] | None = None
        self.multax: bool | None = None
        self.cycle: dict[str, Any] | None = None
        self.last_cycle: dict[str, Any] | None = None
        self.circle: tuple[np.ndarray, np.ndarray, float, int] | None = None
        self.home: tuple[np.ndarray, np.ndarray] | None = None  # FROM pose in the part frame
        self.part_name: str | None = None
        self.units_seen: tuple[Units, int] | None = None
        self.seen_record = False
        self.done = False
        self.pending: list[str] | None = None  # continuation parts
        self.pending_line = 0
        self.handlers: dict[str, Callable[[str, int], None]] = {
            "GOTO": self._goto,
            "FROM": self._from,
            "GOHOME": self._gohome,
            "GODLTA": self._godlta,
            "RAPID": self._rapid,
            "FEDRAT": self._fedrat,
            "CIRCLE": self._circle,
            "CYCLE": self._cycle,
            "MULTAX": self._multax,
            "TLAXIS": self._tlaxis,
            "MSYS": self._msys,
            "CSYS": self._csys,
            "UNITS": self._units,
            "UNIT": self._units,
            "TOOL PATH": self._toolpath,
            "TLDATA": self._tldata,
            "CUTTER": self._cutter,
            "LOAD": self._load,
            "LOADTL": self._loadtl,
            "SELECT": self._select,
            "SPINDL": self._spindl,
            "COOLNT": self._coolnt,
            "STOP": self._stop,
            "OPSTOP": self._opstop,
            "CUTCOM": self._cutcom,
            "FINI": self._fini,
        }

    # ------------------------------------------------------------------ helpers

    def fail(self, reason: str, line: int | None) -> InputError:
        return InputError(reason, source=self.src, line=line)

    def warn(self, line: int, text: str) -> None:
        self.warnings.append(f"{self.src}:{line}: {text}")

    def _fast_ok(self) -> bool:
        return (
            not self.rapid_next
            and self.feed_val == self.feed_val  # a feed is programmed (not NaN)
            and self.cycle is None
            and self.circle is None
            and not self.header_open
            and self.multax is not False
            and self.pending is None
        )

    def _number(self, tok: str, what: str, line: int) -> float:
        return _parse_number(tok, what, self.src, line)

    def _numbers(self, args: str, what: str, line: int) -> list[float]:
        if not args.strip():
            return []
        return [self._number(t, what, line) for t in args.split(",")]

    def _tokens(self, args: str, what: str, line: int) -> list[float | str]:
        """Split ``args`` into numbers (float) and upper-case words (str)."""
        out: list[float | str] = []
        if not args.strip():
            return out
        for tok in args.split(","):
            t = tok.strip()
            if _NUM_RE.match(t):
                out.append(float(t))
            elif t.lower().lstrip("+-") in ("nan", "inf", "infinity") or not t:
                self._number(t, what, line)  # raises with the right message
            elif _WORD_RE.match(t):
                out.append(t.upper())
            else:
                raise self.fail(f"'{t}' is not a number", line)
        return out

    def _check_axis(self, a: list[float] | tuple[float, ...], what: str, line: int) -> None:
        n = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
        if n < 1e-6:
            raise self.fail(f"{what} has zero length", line)
        if abs(n - 1.0) > _AXIS_LEN_TOL:
            raise self.fail(f"{what} has length {n:.6g}, expected a unit vector", line)

    def _point_axis(self, args: str, what: str, line: int) -> tuple[list[float], tuple[float, float, float]]:
        vals = self._numbers(args, what, line)
        if len(vals) not in (3, 6):
            raise self.fail(f"{what} needs 3 or 6 numbers, got {len(vals)}", line)
        if len(vals) == 6:
            if self.multax is False:
                raise self.fail(f"{what} has a tool axis (6 numbers) but MULTAX/OFF is in effect", line)
            self._check_axis(vals[3:], "tool axis", line)
            return vals[:3], (vals[3], vals[4], vals[5])
        return vals, self.axis

    def _push_state(self) -> None:
        state = (len(self.lines), self.feed_val, self.inverse, self.tool, self.frame_id)
        if _same_state(self.runs[-1][1:], state[1:]):
            return
        if self.runs[-1][0] == state[0]:
            self.runs[-1] = state
        else:
            self.runs.append(state)

    def _add_pose(
        self, p: list[float], a: tuple[float, ...], line: int, rapid: bool, feed: float | None = None
    ) -> None:
        if self.header_open:
            self._close_header()
        if not rapid and feed is None and self.feed_val != self.feed_val:
            raise self.fail(self.feed_problem, line)
        idx = len(self.lines)
        self.rows.append([p[0], p[1], p[2], a[0], a[1], a[2]])
        self.lines.append(line)
        if rapid:
            self.rapid_idx.append(idx)
        elif feed is not None:
            self.feed_override[idx] = feed

    def _take_rapid(self) -> bool:
        r = self.rapid_next
        self.rapid_next = False
        return r

    def _frame_of_pose(self, idx: int) -> int:
        for start, _f, _i, _t, frame in reversed(self.runs):
            if start <= idx:
                return frame
        return 0

    def _to_part(self, p: np.ndarray, a: np.ndarray, frame: int) -> tuple[np.ndarray, np.ndarray]:
        R, o = self.frames[frame]
        return o + R @ p, R @ a

    def _from_part(self, p: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R, o = self.frames[self.frame_id]
        return R.T @ (p - o), R.T @ a

    def _current_pose(self, what: str, line: int) -> tuple[np.ndarray, np.ndarray]:
        """Last pose (tip, unit axis) expressed in the current CL frame."""
        if not self.rows:
            raise self.fail(f"{what} with no current position (no GOTO or FROM before it)", line)
        row = np.array(self.rows[-1], dtype=float)
        p, a = row[:3], row[3:] / np.linalg.norm(row[3:])
        frame = self._frame_of_pose(len(self.rows) - 1)
        if frame != self.frame_id:
            p, a = self._from_part(*self._to_part(p, a, frame))
        return p, a

    # ------------------------------------------------------------------ main loop

    def parse(self, lines: list[str]) -> None:
        rows = self.rows
        out_lines = self.lines
        axis = self.axis
        fast = self._fast_ok()
        for lineno, raw in enumerate(lines, 1):
            if fast and raw.startswith("GOTO/") and "$" not in raw:
                rest = raw[5:]
                if rest.isascii() and "_" not in rest:
                    try:
                        vals = list(map(float, rest.split(",")))
                    except ValueError:
                        vals = []
                    nv = len(vals)
                    if nv == 3:
                        if (vals[0] + vals[1] + vals[2]) * 0.0 == 0.0:  # all finite
                            vals += axis
                            rows.append(vals)
                            out_lines.append(lineno)
                            continue
                    elif nv == 6:
                        i, j, k = vals[3], vals[4], vals[5]
                        if 0.98 < i * i + j * j + k * k < 1.02 and (vals[0] + vals[1] + vals[2]) * 0.0 == 0.0:
                            axis = (i, j, k)
                            rows.append(vals)
                            out_lines.append(lineno)
                            continue
            self.axis = axis
            self._slow(raw, lineno)
            if self.done:
                break
            axis = self.axis
            fast = self._fast_ok()
        self.axis = axis
        if self.pending is not None:
            raise self.fail("continuation '$' at end of file: the record is incomplete", self.pending_line)
        if self.circle is not None:
            raise self.fail("CIRCLE is not followed by the GOTO that ends the arc", self.circle[3])
        if self.header_open:
            self._close_header()

    def _slow(self, raw: str, lineno: int) -> None:
        if self.pending is None:
            s = raw.strip()
            if not s or s.startswith("$$"):
                return
            head, sep, rest = s.partition("/")
            if sep and " ".join(head.split()).upper() in _TEXT_RECORDS:
                self._text_record(" ".join(head.split()).upper(), rest.strip(), lineno)
                return
            if _TRAILER_RE.match(s) or (not self.seen_record and _HEADER_RE.match(s)):
                return
        cut = raw.find("$$")
        body = (raw if cut < 0 else raw[:cut]).rstrip()
        if body.endswith("$"):
            if self.pending is None:
                self.pending = []
                self.pending_line = lineno
            self.pending.append(body[:-1])
            return
        line = lineno
        if self.pending is not None:
            if not body.strip():
                return  # blank or comment-only line inside a continued record
            self.pending.append(body)
            body = "".join(self.pending)
            line = self.pending_line
            self.pending = None
        self._record(body, line)

    def _record(self, body: str, line: int) -> None:
        s = body.strip()
        if not s:
            return
        head, _sep, args = s.partition("/")
        word = " ".join(head.split()).upper()
        handler = self.handlers.get(word)
        if handler is not None:
            self.seen_record = True
            handler(args, line)
        elif word in _IGNORED:
            self.seen_record = True
        elif word in _REJECTED:
            raise self.fail(_REJECTED[word], line)
        else:
            shown = head.strip()
            if len(shown) > 40:
                shown = shown[:37] + "..."
            self.warn(line, f"unknown record '{shown}' ignored")

    # ------------------------------------------------------------------ motion records

    def _goto(self, args: str, line: int) -> None:
        p, a = self._point_axis(args, "GOTO", line)
        self._motion_to(p, a, line)

    def _motion_to(self, p: list[float], a: tuple[float, float, float], line: int) -> None:
        if self.circle is not None:
            self._arc_to(p, a, line)
        elif self.cycle is not None:
            self._drill(p, a, line)
        else:
            self.axis = a
            self._add_pose(p, a, line, self._take_rapid())

    def _no_pending_circle(self, what: str, line: int) -> None:
        if self.circle is not None:
            raise self.fail(f"CIRCLE at line {self.circle[3]} must be followed by a GOTO, not {what}", line)

    def _from(self, args: str, line: int) -> None:
        self._no_pending_circle("FROM", line)
        p, a = self._point_axis(args, "FROM", line)
        self.axis = a
        self._take_rapid()
        self._add_pose(p, a, line, rapid=True)
        an = np.array(a) / np.linalg.norm(a)
        self.home = self._to_part(np.array(p, dtype=float), an, self.frame_id)

    def _gohome(self, args: str, line: int) -> None:
        self._no_pending_circle("GOHOME", line)
        if self.home is None:
            raise self.fail("GOHOME without a FROM position", line)
        p, a = self._from_part(*self.home)
        self.axis = (float(a[0]), float(a[1]), float(a[2]))
        self._take_rapid()
        self._add_pose([float(v) for v in p], self.axis, line, rapid=True)

    def _godlta(self, args: str, line: int) -> None:
        self._no_pending_circle("GODLTA", line)
        if self.cycle is not None:
            raise self.fail("GODLTA inside a drilling CYCLE is not supported", line)
        vals = self._numbers(args, "GODLTA", line)
        p, a = self._current_pose("GODLTA", line)
        if len(vals) == 1:
            q = p + vals[0] * a
        elif len(vals) == 3:
            q = p + np.array(vals)
        else:
            raise self.fail(f"GODLTA needs 1 or 3 numbers, got {len(vals)}", line)
        self._motion_to([float(v) for v in q], self.axis, line)

    def _rapid(self, args: str, line: int) -> None:
        if args.strip():
            self.warn(line, f"RAPID/{args.strip()}: arguments ignored")
        self.rapid_next = True

    def _tlaxis(self, args: str, line: int) -> None:
        vals = self._numbers(args, "TLAXIS", line)
        if len(vals) != 3:
            raise self.fail(f"TLAXIS needs 3 numbers, got {len(vals)}", line)
        self._check_axis(vals, "tool axis", line)
        self.axis = (vals[0], vals[1], vals[2])

    def _multax(self, args: str, line: int) -> None:
        word = args.strip().upper()
        if word == "ON":
            self.multax = True
        elif word == "OFF":
            self.multax = False
            self.axis = (0.0, 0.0, 1.0)
        else:
            raise self.fail(f"MULTAX needs ON or OFF, got '{args.strip()}'", line)

    # ------------------------------------------------------------------ feeds and units

    def _feed_from(self, value: float, unit: str | None, what: str, line: int) -> float:
        """Feed in mm/min from a value and its unit word (None: file units per minute)."""
        if value <= 0:
            raise self.fail(f"{what} feed must be positive, got {value:g}", line)
        if unit is None:
            return value * self.scale
        if unit == "MMPM":
            return value
        if unit == "IPM":
            return value * MM_PER_INCH
        per_rev = value * (MM_PER_INCH if unit == "IPR" else 1.0)
        if not self.spindle_on or self.rpm is None:
            raise self.fail(f"{what} per-revolution feed ({unit}) needs a spindle speed (SPINDL)", line)
        return per_rev * self.rpm

    def _fedrat(self, args: str, line: int) -> None:
        toks = self._tokens(args, "FEDRAT", line)
        nums = [t for t in toks if isinstance(t, float)]
        words = [t for t in toks if isinstance(t, str)]
        if len(nums) != 1:
            raise self.fail(f"FEDRAT needs one feed value, got {len(nums)}", line)
        if len(words) > 1:
            raise self.fail(f"FEDRAT has more than one unit word: {', '.join(words)}", line)
        unit = words[0] if words else None
        if unit is not None and unit not in _FEED_WORDS and unit != "INVERS":
            raise self.fail(f"FEDRAT: unknown feed unit '{unit}' (expected MMPM, IPM, MMPR, IPR or INVERS)", line)
        value = nums[0]
        self.fpr = None
        self.inverse = False
        if unit == "INVERS":
            if value <= 0:
                raise self.fail(f"FEDRAT inverse-time value must be positive, got {value:g}", line)
            self.feed_val = value
            self.inverse = True
        elif unit in ("MMPR", "IPR"):
            if value <= 0:
                raise self.fail(f"FEDRAT feed must be positive, got {value:g}", line)
            self.fpr = value * (MM_PER_INCH if unit == "IPR" else 1.0)
            if not self.spindle_on or self.rpm is None:
                raise self.fail(f"FEDRAT/{unit} (feed per revolution) needs a spindle speed (SPINDL) first", line)
            self.feed_val = self.fpr * self.rpm
        else:
            self.feed_val = self._feed_from(value, unit, "FEDRAT", line)
        self._push_state()

    def _refresh_per_rev_feed(self) -> None:
        if self.fpr is None:
            return
        if self.spindle_on and self.rpm is not None:
            self.feed_val = self.fpr * self.rpm
        else:
            self.feed_val = math.nan
            self.feed_problem = "feed move with a per-revolution FEDRAT while the spindle is off"
        self._push_state()

    def _units(self, args: str, line: int) -> None:
        word = args.strip().upper()
        if word not in _UNIT_WORDS:
            raise self.fail(f"unknown UNITS '{args.strip()}' (expected MM or INCHES)", line)
        u = _UNIT_WORDS[word]
        if self.units_override:
            if u != self.units:
                self.warn(line, f"UNITS/{args.strip()} ignored: units='{self.units}' was given")
            return
        if u != self.units:
            first = f" (line {self.units_seen[1]})" if self.units_seen else ""
            raise self.fail(
                f"UNITS changes from {self.units}{first} to {u}: mixed units in one file are not supported",
                line,
            )
        if self.units_seen is None:
            self.units_seen = (u, line)

    # ------------------------------------------------------------------ frames

    def _make_frame(
        self, o: list[float], x: list[float], y: list[float], z: list[float] | None, what: str, line: int
    ) -> None:
        xa, ya = np.array(x, dtype=float), np.array(y, dtype=float)
        nx, ny = float(np.linalg.norm(xa)), float(np.linalg.norm(ya))
        if nx < 1e-9 or ny < 1e-9:
            raise self.fail(f"{what} axis has zero length", line)
        if abs(nx - 1.0) > _ANG_TOL or abs(ny - 1.0) > _ANG_TOL:
            raise self.fail(f"{what} axes are not unit vectors (|X|={nx:.6g}, |Y|={ny:.6g})", line)
        xa, ya = xa / nx, ya / ny
        c = float(xa @ ya)
        if abs(c) > _ANG_TOL:
            deg = math.degrees(math.acos(max(-1.0, min(1.0, c))))
            raise self.fail(f"{what} X and Y axes are not orthogonal ({deg:.4f} deg apart)", line)
        ya = ya - c * xa
        ya /= np.linalg.norm(ya)
        za = np.cross(xa, ya)
        if z is not None:
            zg = np.array(z, dtype=float)
            nz = float(np.linalg.norm(zg))
            if abs(nz - 1.0) > _ANG_TOL or float(za @ zg) / max(nz, 1e-12) < 1.0 - _ANG_TOL:
                raise self.fail(f"{what} matrix is not a right-handed rotation", line)
        R = np.column_stack([xa, ya, za])
        self.frames.append((R, np.array(o, dtype=float)))
        self.frame_id = len(self.frames) - 1
        self._push_state()

    def _msys(self, args: str, line: int) -> None:
        v = self._numbers(args, "MSYS", line)
        if len(v) != 9:
            raise self.fail(f"MSYS needs 9 numbers (origin, X axis, Y axis), got {len(v)}", line)
        self._make_frame(v[0:3], v[3:6], v[6:9], None, "MSYS", line)

    def _csys(self, args: str, line: int) -> None:
        v = self._numbers(args, "CSYS", line)
        if len(v) != 12:
            raise self.fail(f"CSYS needs 12 numbers (3x4 matrix, row-major), got {len(v)}", line)
        m = np.array(v, dtype=float).reshape(3, 4)
        self._make_frame(list(m[:, 3]), list(m[:, 0]), list(m[:, 1]), list(m[:, 2]), "CSYS", line)

    # ------------------------------------------------------------------ arcs

    def _circle(self, args: str, line: int) -> None:
        v = self._numbers(args, "CIRCLE", line)
        if len(v) < 7 or len(v) > 11:
            raise self.fail(f"CIRCLE needs 7 to 11 numbers (centre, axis, radius[, ...]), got {len(v)}", line)
        self._no_pending_circle("another CIRCLE", line)
        if self.cycle is not None:
            raise self.fail("CIRCLE inside a drilling CYCLE", line)
        n = np.array(v[3:6], dtype=float)
        nn = float(np.linalg.norm(n))
        if nn < 1e-9:
            raise self.fail("circle axis has zero length", line)
        if v[6] <= 0:
            raise self.fail(f"circle radius must be positive, got {v[6]:g}", line)
        self._current_pose("CIRCLE", line)  # there must be a start point
        self.circle = (np.array(v[0:3], dtype=float), n / nn, float(v[6]), line)

    def _arc_to(self, p_end: list[float], a_end: tuple[float, float, float], line: int) -> None:
        assert self.circle is not None
        c, n, r, cline = self.circle
        self.circle = None
        p0, a0 = self._current_pose("CIRCLE", cline)
        p1 = np.array(p_end, dtype=float)
        d0, d1 = p0 - c, p1 - c
        h0, h1 = float(d0 @ n), float(d1 @ n)
        v0, v1 = d0 - h0 * n, d1 - h1 * n
        r0, r1 = float(np.linalg.norm(v0)), float(np.linalg.norm(v1))
        tol_r = max(0.01 / self.scale, 1e-3 * r)
        unit = " in" if self.scale != 1.0 else " mm"
        if abs(r0 - r) > tol_r:
            raise self.fail(f"arc start point is {r0:.5g}{unit} from the CIRCLE centre, radius is {r:.5g}{unit}", cline)
        if abs(r1 - r) > tol_r:
            raise self.fail(f"arc end point is {r1:.5g}{unit} from the CIRCLE centre, radius is {r:.5g}{unit}", line)
        if min(r0, r1) <= 1e-9 * max(r, 1.0):
            raise self.fail("arc start or end point lies on the CIRCLE axis", line)
        u = v0 / r0
        w = np.cross(n, u)
        if float(np.linalg.norm(v1 - v0)) <= max(1e-4 / self.scale, 1e-9 * r):
            theta = 2.0 * math.pi  # end == start: full circle
        else:
            theta = math.atan2(float(v1 @ w), float(v1 @ u))
            if theta <= 0.0:
                theta += 2.0 * math.pi
        rr = max(r0, r1)
        dmax = 2.0 * math.acos(1.0 - self.tol / rr) if self.tol < rr else math.pi / 2
        dmax = min(dmax, math.pi / 2)
        k = max(2, math.ceil(theta / dmax - 1e-9))
        a1 = np.array(a_end, dtype=float)
        a1 /= np.linalg.norm(a1)
        dot = max(-1.0, min(1.0, float(a0 @ a1)))
        omega = math.acos(dot)
        if math.pi - omega < 1e-6:
            raise self.fail("tool axis reverses across the CIRCLE arc", line)
        rapid = self._take_rapid()
        for j in range(1, k):
            t = j / k
            phi = t * theta
            q = c + (r0 + t * (r1 - r0)) * (math.cos(phi) * u + math.sin(phi) * w) + (h0 + t * (h1 - h0)) * n
            a = a1 if omega < 1e-09 else (math.sin((1 - t) * omega) * a0 + math.sin(t * omega) * a1) / math.sin(omega)
            self._add_pose(
                [float(q[0]), float(q[1]), float(q[2])], (float(a[0]), float(a[1]), float(a[2])), line, rapid
            )
        self.axis = a_end
        self._add_pose(p_end, a_end, line, rapid)

    # ------------------------------------------------------------------ drilling cycles

    def _cycle(self, args: str, line: int) -> None:
        toks = self._tokens(args, "CYCLE", line)
        if not toks or not isinstance(toks[0], str):
            raise self.fail("CYCLE needs a cycle type (e.g. CYCLE/DRILL or CYCLE/OFF)", line)
        kind = toks[0]
        if kind == "OFF":
            self.cycle = None
            return
        self._no_pending_circle("CYCLE", line)
        if kind == "ON":
            if self.last_cycle is None:
                raise self.fail("CYCLE/ON without a previous CYCLE", line)
            self.cycle = self.last_cycle
            return
        if kind in _CYCLE_REJECTED:
            raise self.fail(
                f"CYCLE/{kind}: {_CYCLE_REJECTED[kind]} is not supported (only plain CYCLE/DRILL is "
                "expanded); output this operation as explicit GOTO moves",
                line,
            )
        if kind != "DRILL":
            raise self.fail(f"CYCLE/{kind} is not supported (only plain CYCLE/DRILL is expanded)", line)
        if len(toks) > 1 and isinstance(toks[1], str) and toks[1] in _CYCLE_REJECTED:
            raise self.fail(
                f"CYCLE/DRILL,{toks[1]}: {_CYCLE_REJECTED[toks[1]]} is not supported (only plain drilling "
                "is expanded); output this operation as explicit GOTO moves",
                line,
            )
        self.cycle = self.last_cycle = self._parse_drill(toks[1:], args.strip(), line)

    def _parse_drill(self, toks: list[float | str], text: str, line: int) -> dict[str, Any]:
        def unsupported(why: str) -> InputError:
            return self.fail(f"this CYCLE/DRILL form is not supported ({why}): CYCLE/{text}", line)

        def number_at(i: int, key: str) -> float:
            if i >= len(toks) or not isinstance(toks[i], float):
                raise unsupported(f"{key} needs a number")
            return float(toks[i])  # type: ignore[arg-type]

        depth: float | None = None
        feed: tuple[float, str | None] | None = None
        clear: float | None = None
        rapto: float | None = None
        rtrcto: float | None = None
        i = 0
        while i < len(toks):
            t = toks[i]
            if isinstance(t, float):
                if i == 0:
                    depth = t  # classic APT: CYCLE/DRILL,depth,...
                    i += 1
                elif i + 1 < len(toks) and toks[i + 1] in _FEED_WORDS and feed is None:
                    feed = (t, str(toks[i + 1]))
                    i += 2
                elif feed is not None and clear is None and rapto is None:
                    clear = t
                    i += 1
                else:
                    raise unsupported(f"unexpected number {t:g}")
            elif t in ("DEPTH", "FEDTO"):
                v = number_at(i + 1, t)
                depth = abs(v) if t == "FEDTO" else v
                i += 2
            elif t in _FEED_WORDS:
                feed = (number_at(i + 1, t), t)
                i += 2
            elif t == "FEDRAT":
                if i + 1 < len(toks) and toks[i + 1] in _FEED_WORDS:
                    feed = (number_at(i + 2, "FEDRAT"), str(toks[i + 1]))
                    i += 3
                elif i + 2 < len(toks) and toks[i + 2] in _FEED_WORDS:
                    feed = (number_at(i + 1, "FEDRAT"), str(toks[i + 2]))
                    i += 3
                else:
                    feed = (number_at(i + 1, "FEDRAT"), None)
                    i += 2
            elif t == "CLEAR":
                clear = number_at(i + 1, t)
                i += 2
            elif t == "RAPTO":
                rapto = number_at(i + 1, t)
                i += 2
            elif t == "RTRCTO":
                if i + 1 < len(toks) and toks[i + 1] == "AUTO":
                    i += 2
                else:
                    rtrcto = number_at(i + 1, t)
                    i += 2
            elif t in ("AUTO", "MANUAL"):
                i += 1
            elif t in _CYCLE_REJECTED:
                raise self.fail(
                    f"CYCLE/DRILL with {_CYCLE_REJECTED[t]} is not supported (only plain drilling is "
                    "expanded); output this operation as explicit GOTO moves",
                    line,
                )
            else:
                raise unsupported(f"unknown word '{t}'")
        if depth is None:
            raise unsupported("no depth")
        if depth <= 0:
            raise self.fail(f"CYCLE/DRILL depth must be positive, got {depth:g}", line)
        if clear is None and rapto is None:
            raise unsupported("no clearance: give CLEAR,c or RAPTO,r")
        for name, val in (("CLEAR", clear), ("RAPTO", rapto), ("RTRCTO", rtrcto)):
            if val is not None and val < 0:
                raise self.fail(f"CYCLE/DRILL {name} must not be negative, got {val:g}", line)
        approach = rapto if rapto is not None else clear
        retract = max(v for v in (clear, rapto, rtrcto) if v is not None)
        if feed is not None:
            feed_mm = self._feed_from(feed[0], feed[1], "CYCLE/DRILL", line)
        elif self.feed_val == self.feed_val and not self.inverse:
            feed_mm = self.feed_val
        else:
            raise self.fail("CYCLE/DRILL has no feed and no per-minute FEDRAT is active", line)
        return {"depth": depth, "approach": approach, "retract": retract, "feed": feed_mm, "line": line}

    def _drill(self, p: list[float], a: tuple[float, float, float], line: int) -> None:
        cyc = self.cycle
        assert cyc is not None
        self.axis = a
        self._take_rapid()
        top = np.array(p, dtype=float)
        an = np.array(a, dtype=float)
        an /= np.linalg.norm(an)
        for q, rapid, feed in (
            (top + cyc["approach"] * an, True, None),
            (top - cyc["depth"] * an, False, cyc["feed"]),
            (top + cyc["retract"] * an, True, None),
        ):
            self._add_pose([float(q[0]), float(q[1]), float(q[2])], a, line, rapid, feed)

    # ------------------------------------------------------------------ tools

    def _slot(self) -> int:
        self.events.append(None)
        return len(self.events) - 1

    @staticmethod
    def _compatible(target: dict[str, Any], geom: dict[str, Any]) -> bool:
        return all(target[k] is None or geom[k] is None for k in ("length", "diameter"))

    @staticmethod
    def _merge(target: dict[str, Any], geom: dict[str, Any]) -> None:
        for k in ("length", "diameter"):
            if geom[k] is not None:
                target[k] = geom[k]

    def _attach_geom(self, length: float | None, diameter: float | None, line: int) -> None:
        self.header_open = True
        geom = {"length": length, "diameter": diameter, "line": line}
        if self.h_loads and self._compatible(self.h_loads[-1], geom):
            self._merge(self.h_loads[-1], geom)
            return
        geom["slot"] = self._slot()
        self.h_geoms.append(geom)

    def _new_load(
        self, tool: int, adjust: int | None, length: float | None, line: int, slot: int | None = None
    ) -> None:
        self.header_open = True
        load: dict[str, Any] = {
            "slot": self._slot() if slot is None else slot,
            "line": line,
            "tool": tool,
            "length": length,
            "diameter": None,
            "adjust": adjust,
        }
        for geom in list(self.h_geoms):
            if self._compatible(load, geom):
                self._merge(load, geom)
                self.h_geoms.remove(geom)
        self.h_loads.append(load)

    def _close_header(self) -> None:
        index = len(self.lines)
        if self.h_select is not None and not self.h_loads:
            sel = self.h_select
            self._new_load(sel["tool"], None, None, sel["line"], slot=sel["slot"])
        for load in self.h_loads:
            self.events[load["slot"]] = ToolChange(
                index=index,
                line=load["line"],
                tool=load["tool"],
                length=load["length"],
                diameter=load["diameter"],
                adjust=load["adjust"],
            )
            self.tool = load["tool"]
            self.active_geom = (load["length"], load["diameter"])
        if self.h_geoms:
            first = self.h_geoms[0]
            if self.h_loads:
                for geom in self.h_geoms:
                    self.warn(geom["line"], "tool data does not fit the tool load of this operation; ignored")
            else:
                merged: dict[str, Any] = {"length": None, "diameter": None}
                for geom in self.h_geoms:
                    self._merge(merged, geom)
                if self.active_geom != (merged["length"], merged["diameter"]):
                    if self.tool == 0:
                        self.warn(
                            first["line"],
                            "tool data without a tool load (LOAD/TOOL, LOADTL, SELECT/TOOL): "
                            "ToolChange with tool number 0 carries it",
                        )
                    self.events[first["slot"]] = ToolChange(
                        index=index, line=first["line"], tool=self.tool,
                        length=merged["length"], diameter=merged["diameter"],
                    )  # fmt: skip
                    self.active_geom = (merged["length"], merged["diameter"])
        self.h_loads = []
        self.h_geoms = []
        self.h_select = None
        self.header_open = False
        self._push_state()

    def _tool_number(self, v: float, line: int) -> int:
        if v != int(v) or v < 0:
            raise self.fail(f"tool number must be a non-negative integer, got {v:g}", line)
        return int(v)

    def _tldata(self, args: str, line: int) -> None:
        toks = self._tokens(args, "TLDATA", line)
        kind = toks[0] if toks and isinstance(toks[0], str) else None
        nums = [t for t in toks if isinstance(t, float)]
        if kind not in ("MILL", "DRILL"):
            self.warn(line, f"TLDATA/{kind or '?'}: tool type not supported, tool data ignored")
            return
        if len(nums) < 3:
            raise self.fail(f"TLDATA/{kind} needs at least 3 numbers (diameter, radius, length), got {len(nums)}", line)
        dia, length = nums[0], nums[2]
        if dia < 0:
            raise self.fail(f"TLDATA/{kind}: diameter must not be negative, got {dia:g}", line)
        if length <= 0:
            self.warn(line, f"TLDATA/{kind}: tool length {length:g} is not positive; length unknown")
        self._attach_geom(length * self.scale if length > 0 else None, dia * self.scale, line)

    def _cutter(self, args: str, line: int) -> None:
        nums = self._numbers(args, "CUTTER", line)
        if not nums:
            raise self.fail("CUTTER needs a diameter", line)
        if nums[0] < 0:
            raise self.fail(f"CUTTER diameter must not be negative, got {nums[0]:g}", line)
        self._attach_geom(None, nums[0] * self.scale, line)

    def _keyword_ints(self, toks: list[float | str], start: int, what: str, line: int) -> dict[str, float]:
        """Keyword/value pairs after position ``start`` (ADJUST,h / LENGTH,l); stray numbers ignored."""
        out: dict[str, float] = {}
        i = start
        while i < len(toks):
            t = toks[i]
            if isinstance(t, str):
                if i + 1 >= len(toks) or not isinstance(toks[i + 1], float):
                    raise self.fail(f"{what}: {t} needs a number", line)
                if t in ("ADJUST", "LENGTH"):
                    out[t] = float(toks[i + 1])  # type: ignore[arg-type]
                else:
                    self.warn(line, f"{what}: {t} ignored")
                i += 2
            else:
                i += 1
        return out

    def _load(self, args: str, line: int) -> None:
        toks = self._tokens(args, "LOAD", line)
        if len(toks) < 2 or toks[0] != "TOOL" or not isinstance(toks[1], float):
            raise self.fail("LOAD needs the form LOAD/TOOL,n[,ADJUST,h]", line)
        kw = self._keyword_ints(toks, 2, "LOAD/TOOL", line)
        adjust = self._tool_number(kw["ADJUST"], line) if "ADJUST" in kw else None
        length = kw["LENGTH"] * self.scale if "LENGTH" in kw else None
        self._new_load(self._tool_number(toks[1], line), adjust, length, line)

    def _loadtl(self, args: str, line: int) -> None:
        toks = self._tokens(args, "LOADTL", line)
        if not toks or not isinstance(toks[0], float):
            raise self.fail("LOADTL needs a tool number", line)
        kw = self._keyword_ints(toks, 1, "LOADTL", line)
        adjust = self._tool_number(kw["ADJUST"], line) if "ADJUST" in kw else None
        length = kw["LENGTH"] * self.scale if "LENGTH" in kw else None
        self._new_load(self._tool_number(toks[0], line), adjust, length, line)

    def _select(self, args: str, line: int) -> None:
        toks = self._tokens(args, "SELECT", line)
        if len(toks) < 2 or toks[0] != "TOOL" or not isinstance(toks[1], float):
            self.warn(line, f"SELECT/{args.strip()}: only SELECT/TOOL,n is understood; ignored")
            return
        self.header_open = True
        tool = self._tool_number(toks[1], line)
        if self.h_select is None and not self.h_loads:
            self.h_select = {"tool": tool, "line": line, "slot": self._slot()}
        # otherwise a pre-selection of the next tool: no load

    # ------------------------------------------------------------------ machine functions

    def _spindl(self, args: str, line: int) -> None:
        toks = self._tokens(args, "SPINDL", line)
        rpm: float | None = None
        direction: Literal["CW", "CCW"] | None = None
        off = on = False
        i = 0
        while i < len(toks):
            t = toks[i]
            if isinstance(t, float):
                if rpm is not None:
                    raise self.fail("SPINDL has more than one speed", line)
                rpm = t
            elif t == "RPM":
                pass
            elif t in ("CLW", "CW"):
                direction = "CW"
            elif t in ("CCLW", "CCW"):
                direction = "CCW"
            elif t == "OFF":
                off = True
            elif t == "ON":
                on = True
            elif t in ("RANGE", "MAXRPM"):
                i += 1  # its value is not a speed
            elif t in ("SFM", "SMM"):
                raise self.fail(f"SPINDL/{t} (constant surface speed) is not supported; program RPM", line)
            else:
                raise self.fail(f"SPINDL: unknown word '{t}'", line)
            i += 1
        index = len(self.lines)
        if off:
            if rpm is not None or on or direction is not None:
                raise self.fail("SPINDL/OFF takes no speed or direction", line)
            self.spindle_on = False
            self.events.append(Spindle(index=index, line=line, rpm=0.0, direction="OFF"))
        else:
            if rpm is None:
                if self.rpm is None:
                    raise self.fail("SPINDL/ON without a previous spindle speed", line)
                rpm = self.rpm
            if rpm <= 0:
                raise self.fail(f"spindle speed must be positive, got {rpm:g}", line)
            self.rpm = rpm
            if direction is not None:
                self.spindle_dir = direction
            self.spindle_on = True
            self.events.append(Spindle(index=index, line=line, rpm=rpm, direction=self.spindle_dir))
        self._refresh_per_rev_feed()

    def _coolnt(self, args: str, line: int) -> None:
        modes: dict[str, Literal["ON", "FLOOD", "MIST", "THRU", "OFF"]] = {
            "ON": "ON", "FLOOD": "FLOOD", "MIST": "MIST", "THRU": "THRU", "THROUGH": "THRU", "OFF": "OFF",
        }  # fmt: skip
        words = [t for t in self._tokens(args, "COOLNT", line) if isinstance(t, str)]
        known = [modes[w] for w in words if w in modes]
        unknown = [w for w in words if w not in modes]
        if unknown or not known:
            self.warn(line, f"COOLNT/{args.strip()}: coolant mode not supported, ignored")
            return
        mode = next((m for m in known if m not in ("ON",)), "ON")
        self.events.append(Coolant(index=len(self.lines), line=line, mode=mode))

    def _stop(self, args: str, line: int) -> None:
        self.events.append(Stop(index=len(self.lines), line=line, optional=False))

    def _opstop(self, args: str, line: int) -> None:
        self.events.append(Stop(index=len(self.lines), line=line, optional=True))

    def _cutcom(self, args: str, line: int) -> None:
        word = args.strip().upper()
        if word and word.split(",")[0].strip() == "OFF":
            return
        raise self.fail(
            f"CUTCOM/{args.strip()}: cutter radius compensation is not supported; output tool-tip CL data",
            line,
        )

    def _fini(self, args: str, line: int) -> None:
        self.done = True

    def _toolpath(self, args: str, line: int) -> None:
        fields = [f.strip() for f in args.split(",")]
        name = fields[0] if fields and fields[0] else "?"
        text = name
        if len(fields) >= 3 and fields[1].upper() == "TOOL" and fields[2]:
            text = f"{name} (tool {fields[2]})"
        self.events.append(Comment(index=len(self.lines), line=line, text=text))

    def _text_record(self, word: str, text: str, line: int) -> None:
        self.seen_record = True
        index = len(self.lines)
        if word == "PARTNO" and self.part_name is None:
            self.part_name = text
            return
        if word == "INSERT":
            self.warn(line, f"INSERT/{text}: not executed, kept as a comment")
        self.events.append(Comment(index=index, line=line, text=text))

    # ------------------------------------------------------------------ result

    def result(self) -> Toolpath:
        n = len(self.rows)
        if n == 0:
            raise InputError("no motion records in file", source=self.src)
        arr = np.array(self.rows, dtype=float)
        tip, axis = arr[:, :3].copy(), arr[:, 3:].copy()
        line = np.array(self.lines, dtype=np.int64)
        _validate(tip, axis, line, self.src, "GOTO")
        axis /= np.sqrt(np.einsum("ij,ij->i", axis, axis))[:, None]
        starts = np.array([r[0] for r in self.runs], dtype=np.int64)
        counts = np.diff(np.append(starts, n))
        feed = np.repeat(np.array([r[1] for r in self.runs], dtype=float), counts)
        inverse = np.repeat(np.array([r[2] for r in self.runs], dtype=bool), counts)
        tool = np.repeat(np.array([r[3] for r in self.runs], dtype=np.int64), counts)
        frame = np.repeat(np.array([r[4] for r in self.runs], dtype=np.int64), counts)
        for fid in sorted({r[4] for r, c in zip(self.runs, counts, strict=True) if c > 0}):
            if fid == 0:
                continue  # identity
            R, o = self.frames[fid]
            if (frame == fid).all():
                tip = o + np.einsum("ij,nj->ni", R, tip)
                axis = np.einsum("ij,nj->ni", R, axis)
            else:
                m = frame == fid
                tip[m] = o + np.einsum("ij,nj->ni", R, tip[m])
                axis[m] = np.einsum("ij,nj->ni", R, axis[m])
        tip *= self.scale
        rapid = np.zeros(n, dtype=bool)
        rapid[np.array(self.rapid_idx, dtype=np.int64)] = True
        for idx, f in self.feed_override.items():
            feed[idx] = f
            inverse[idx] = False
        feed[rapid] = np.nan
        inverse[rapid] = False
        return Toolpath(
            source=self.src,
            tip=np.ascontiguousarray(tip),
            axis=np.ascontiguousarray(axis),
            line=line,
            rapid=rapid,
            feed=feed,
            tool=tool,
            inverse_time=inverse,
            events=tuple(e for e in self.events if e is not None),
            part_name=self.part_name,
            units=self.units,
            warnings=tuple(self.warnings),
        )


def _validate(tip: np.ndarray, axis: np.ndarray, line: np.ndarray, src: str, what: str) -> None:
    """Raise for the first (by line) pose with a non-finite value or a non-unit / zero tool axis."""
    finite = np.isfinite(tip).all(axis=1) & np.isfinite(axis).all(axis=1)
    safe = np.where(np.isfinite(axis), axis, 0.0)
    norms = np.sqrt(np.einsum("ij,ij->i", safe, safe))
    huge = (np.abs(np.where(np.isfinite(tip), tip, 0.0)) > _MAX_COORD).any(axis=1)
    bad = ~finite | huge | (norms < 1e-6) | (np.abs(norms - 1.0) > _AXIS_LEN_TOL)
    if not bad.any():
        return
    k = int(np.flatnonzero(bad)[np.argmin(line[bad])])
    row = np.concatenate([tip[k], axis[k]])
    if np.isnan(row).any():
        reason = f"NaN in {what}"
    elif not np.isfinite(row).all():
        reason = f"infinite value in {what}"
    elif huge[k]:
        reason = f"coordinate out of range in {what} (|value| > {_MAX_COORD:g})"
    elif norms[k] < 1e-6:
        reason = "tool axis has zero length"
    else:
        reason = f"tool axis has length {norms[k]:.6g}, expected a unit vector"
    raise InputError(reason, source=src, line=int(line[k]))


def read_cl(
    path: str | os.PathLike[str],
    *,
    units: Literal["mm", "inch"] | None = None,
    chordal_tolerance: float = 0.001,
) -> Toolpath:
    """Read an APT/CLSF cutter-location file.

    ``units`` overrides the source units (else ``UNITS`` record, else inferred from IPM/MMPM
    feeds, else mm). ``chordal_tolerance`` (mm) bounds the chord sagitta when ``CIRCLE`` arcs
    are interpolated into poses. The result is in mm, mm/min and the part frame (MSYS/CSYS
    applied); see the module docstring for the records handled. Raises
    :class:`~verne_post.errors.InputError` naming the file and line for malformed input.
    """
    src = _source(path)
    override = _check_units_arg(units)
    if not (isinstance(chordal_tolerance, (int, float)) and 1e-6 <= chordal_tolerance < math.inf):
        raise InputError(f"chordal tolerance must be a number >= 1e-6 mm, got {chordal_tolerance!r}")
    text = _read_text(path, src)
    warnings: list[str] = []
    file_units = _decide_units(text, override, src, warnings)
    parser = _Parser(src, file_units, override is not None, float(chordal_tolerance), warnings)
    parser.parse(_split_lines(text))
    return parser.result()


_CSV_COLUMNS = ("x", "y", "z", "i", "j", "k")


def read_pose_csv(path: str | os.PathLike[str], *, units: Literal["mm", "inch"] | None = None) -> Toolpath:
    """Read a CSV pose list: header ``x,y,z,i,j,k[,feed]`` (any order, case-insensitive).

    Positions are in ``units`` (default mm) in the part frame; ``feed`` (optional column, empty
    cells allowed) is in ``units`` per minute, converted to mm/min, NaN where absent. Every pose
    is a feed move with tool 0; axes are normalised. Blank lines and lines starting with ``#``
    are skipped.
    """
    src = _source(path)
    file_units: Units = _check_units_arg(units) or "mm"
    scale = MM_PER_INCH if file_units == "inch" else 1.0
    columns, line = read_table(path, _CSV_COLUMNS, ("feed",))
    if not len(line):
        raise InputError("no poses in file", source=src)
    tip = np.column_stack([columns[c] for c in "xyz"])
    axis = np.column_stack([columns[c] for c in "ijk"])
    feed = columns.get("feed", np.full(len(line), math.nan))
    if np.any(feed <= 0):
        k = int(np.argmax(feed <= 0))
        raise InputError(f"feed must be positive, got {feed[k]:g}", source=src, line=int(line[k]))
    _validate(tip, axis, line, src, "pose")
    n = len(line)
    return Toolpath(
        source=src,
        tip=tip * scale,
        axis=axis / np.linalg.norm(axis, axis=1)[:, None],
        line=line,
        rapid=np.zeros(n, dtype=bool),
        feed=feed * scale,
        tool=np.zeros(n, dtype=np.int64),
        inverse_time=np.zeros(n, dtype=bool),
        units=file_units,
    )


def read_toolpath(path: str | os.PathLike[str], **kw: Any) -> Toolpath:
    """Read ``path`` as CSV poses if its suffix is ``.csv`` (any case), else as a CL file.

    Keyword arguments go to :func:`read_pose_csv` or :func:`read_cl`; ``chordal_tolerance`` is
    dropped for CSV files (they have no arcs).
    """
    if Path(path).suffix.lower() == ".csv":
        kw.pop("chordal_tolerance", None)
        return read_pose_csv(path, **kw)
    return read_cl(path, **kw)
