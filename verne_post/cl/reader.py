"""Read APT / CLSF cutter-location files and CSV pose lists into a :class:`~verne_post.cl.toolpath.Toolpath`.

The reader runs in stages, each a module of its own:

1. :mod:`.lexer`: logical records (continuations, comments, line numbers);
2. :mod:`.dialects`: which CAM system wrote the file, and so what its records mean (arc
   direction, frames, centre-line data), from the header and records; ``arc_direction`` and
   ``frame`` override it;
3. record handlers grouped by family, each a table ``WORD -> handler``: :mod:`.motion`,
   :mod:`.curves` (arcs, helices, splines), :mod:`.tools`, :mod:`.machine_functions` (feeds,
   spindle, coolant, stops, units, text), :mod:`.frames`, :mod:`.cycle_records`; below, the records
   read and knowingly ignored, and those refused with the reason;
4. pure geometry expanders that take numbers and return points: :mod:`.arcs`, :mod:`.spline`,
   :mod:`.cycles`;
5. :meth:`.state.ReaderState.result`: whole arrays in mm, mm/min and the part frame.

Units and frames: every output position is in **mm** and every feed in **mm/min** (inverse-time
feeds in 1/min) whatever the source units; inch files are scaled by 25.4. Source units come from
the ``units`` argument, else the ``UNITS`` record, else the first per-minute / per-rev feed word
(``IPM``/``IPR`` inch, ``MMPM``/``MMPR`` mm), else mm (the last two with a warning). Tool axes are
unit vectors from the tip towards the spindle; each pose keeps the 1-based line of its record.

After reading, every arc whose neighbouring moves carry direction information is checked for
tangency under both readings (:func:`.arcs.tangent_votes`). Where the dialect fixes the
direction and the file's tangent arcs mostly say the other one, the file is refused, naming the
first contradicting arc and ``--arc-direction``; where the dialect leaves it open, the file's
own arcs decide (counter-clockwise, with a warning, when no arc says).

Errors are :class:`~verne_post.errors.InputError` with the file name as given and the 1-based
line where the offending record starts.
"""

from __future__ import annotations

import itertools
import math
import os
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from verne_post.cl.toolpath import MIN_FEED, Toolpath
from verne_post.errors import InputError
from verne_post.output.tables import read_table

from . import curves, cycle_records, frames, machine_functions, motion, tools
from .arcs import tangent_votes
from .dialects import DIALECTS, ArcDirection, FrameMode, detect_dialect
from .lexer import GotoRun, Record, iter_lines, record_runs
from .machine_functions import MAX_FEED
from .result import toolpath_of
from .state import MM_PER_INCH, UNIT_WORDS, ReaderState, Units, Warnings, validate_poses

__all__ = ["read_cl", "read_pose_csv", "read_toolpath"]

MAX_CL_BYTES = 2 << 30  # 2 GiB of CL text: far beyond any program, short of exhausting memory
_CTRL_RE = re.compile(r"[\x00-\x08\x0b\x0e-\x1f\x7f]")
_UNITS_RE = re.compile(r"^[ \t]*UNITS?[ \t]*/[ \t]*([A-Za-z]+)", re.IGNORECASE | re.MULTILINE)
_FEED_UNIT_RE = re.compile(
    r"^[ \t]*(?:FEDRAT|CYCLE)[ \t]*/[^\n$]*?\b(IPM|IPR|MMPM|MMPR)\b", re.IGNORECASE | re.MULTILINE
)

Handler = Callable[[ReaderState, Record], None]
_PP_WORD_RE = re.compile(r"[A-Z][A-Z0-9_]*\Z")  # one word, as a PP word's major word is
HANDLERS: dict[str, Handler] = {
    **motion.HANDLERS, **curves.HANDLERS, **tools.HANDLERS, **machine_functions.HANDLERS, **frames.HANDLERS,
    **cycle_records.HANDLERS,
}  # fmt: skip

# Read and knowingly ignored: display, CAM-setup and bookkeeping records that change nothing the
# machine does. NX: PAINT, DISPLY...; Creo: MACHIN, MFGNO; SolidWorks CAM: CSI_SET_* (tool
# flute/extension lengths for its own simulation), SETUP/START|END; Makino: SET/MODE,ABSOL
# (absolute data, the only kind there is here); HSM: AUXFUN (machine-specific codes);
# Creo: MOVNRB, a NURBS written beside its own point-to-point GOTOs, which carry the motion (PTC
# Creo help, "CL Output for NURBS Interpolation": MOVNRB/NEXT "indicates the start of the actual
# point-to-point output").
_IGNORED = frozenset({
    "PAINT", "DISPLY", "PEN", "AUTOPS", "OPERATION", "TPRINT", "PPLOT", "TOLER", "INTOL", "OUTTOL",
    "MACHIN", "SEQNO", "END-OF-PATH", "END", "PLABEL", "SETUP", "SET", "MFGNO", "FEATNO",
    "AUXFUN", "OPSKIP", "MOVNRB",
})  # fmt: skip
_IGNORED_PREFIXES = ("CSI_SET_",)
# Refused: records whose geometry cannot be honoured in one joint-space program.
_REJECTED = {
    "TRANS": "TRANS (coordinate transformation) is not supported; output the CL data in one MSYS",
    "REFSYS": "REFSYS (reference system) is not supported; use MSYS",
    # Autodesk's CAMplete and Mori APT posts: each section's work-plane frame, the GOTOs in it
    **{w: f"{w} (a work-plane frame for the data after it) is not supported: output the CL data in one frame"
       for w in ("MCS", "MCSYS")},
    "INDEX": "INDEX/COPY (repeated motion) is not supported; output the motion explicitly",
    "COPY": "INDEX/COPY (repeated motion) is not supported; output the motion explicitly",
    # ROTATE's index form is read (frames.rotate); these move a rotary axis in forms not documented
    **{w: f"{w} (a rotary axis moved by the CL data) is not supported: give 5-axis tool axes in GOTO records"
       for w in ("ROTABL", "ROTHED")},
    "INDIRP": "INDIRP is not supported: the CL file must contain explicit GOTO points",
    **{w: f"motion record {w} is not supported: the CL file must contain explicit GOTO points"
       for w in ("GOFWD", "GOLFT", "GORGT", "GOBACK", "GOUP", "GODOWN", "GO")},
    # ICAM's table of CL commands gives CONT and MOVE the class of GOTO (5000): motion that must
    # not be dropped, in forms whose details it does not document
    **{w: f"motion record {w} is not supported: write the motion as GOTO records" for w in ("CONT", "MOVE")},
    # Vericut's "Supported APT-CLS NC Program Records": ARC is CIRCLE with the end point added,
    # its field order not documented there
    "ARC": "ARC (an arc with its end point) is not supported: write the arc as CIRCLE then GOTO",
    "THREAD": "THREAD (threading motion that follows the spindle) cannot be expressed in a joint-space program",
}  # fmt: skip
# Read as information, with a warning: ICAM's documentation of TRACUT says most CAM systems pass it,
# if at all, as the transformation already applied to the data that follow.
_INFORMATIONAL = {
    "TRACUT": "TRACUT read as information: the CL data after it are taken as already transformed, as "
              "ICAM documents most CAM systems writing it; check the part's position",
}  # fmt: skip


def _read_text(path: str | os.PathLike[str], src: str) -> str:
    """Read a text file; reject binary data (NUL bytes, undecodable or control characters)."""
    try:
        with open(path, "rb") as handle:  # bounded: a device or pipe may never end
            data = handle.read(MAX_CL_BYTES + 1)
    except FileNotFoundError:
        raise InputError("file not found", source=src) from None
    except IsADirectoryError:
        raise InputError("is a directory, not a file", source=src) from None
    except OSError as exc:
        raise InputError(f"cannot read file: {exc.strerror or exc}", source=src) from None
    if len(data) > MAX_CL_BYTES:
        raise InputError(f"larger than {MAX_CL_BYTES >> 20} MiB: split the program", source=src)
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


def _check_units_arg(units: str | None) -> Units | None:
    if units is None or units in ("mm", "inch"):
        return units  # type: ignore[return-value]
    raise InputError(f"units must be 'mm' or 'inch', got {units!r}")


def _decide_units(text: str, override: Units | None, src: str, warnings: Warnings) -> Units:
    """Source units of a CL file (see the module docstring for the order of precedence)."""
    if override is not None:
        return override
    m = _UNITS_RE.search(text)
    if m is not None:
        word = m.group(1).upper()
        if word not in UNIT_WORDS:
            line = text.count("\n", 0, m.start()) + 1
            raise InputError(f"unknown UNITS '{m.group(1)[:40]}' (expected MM or INCHES)", source=src, line=line)
        return UNIT_WORDS[word]
    m = _FEED_UNIT_RE.search(text)
    if m is not None:
        word = m.group(1).upper()
        units: Units = "inch" if word in ("IPM", "IPR") else "mm"
        warnings.add(text.count("\n", 0, m.start()) + 1, f"no UNITS record: {units} inferred from {word} feed")
        return units
    warnings.add(None, "no UNITS record and no IPM/MMPM feed: assuming mm")
    return "mm"


#: Machine-function records whose malformed form a valid one may replace before any motion: CATIA
#: passes PP words as its user typed them (``SPINDL/900CCLW`` and, on the next line,
#: ``SPINDL/10000,CLW``); the last valid one is what the machine would run.
_REPLACEABLE = frozenset({"SPINDL", "FEDRAT", "COOLNT"})


def _machine_function(st: ReaderState, rec: Record, handler: Handler) -> None:
    """Run ``handler``; a malformed record waits (see :data:`_REPLACEABLE`) for a valid one of its
    word before any motion, which gets a warning naming both lines; motion first is its error."""
    try:
        handler(st, rec)
    except InputError as error:
        if error.line != rec.line:
            raise
        if rec.word not in st.malformed:  # the first malformed one is the one a motion would report
            st.malformed[rec.word] = (rec.line, f"{rec.word}/{rec.args.strip()}"[:60], error)
        return
    bad = st.malformed.pop(rec.word, None)
    if bad is not None:
        st.warn(bad[0], f"{bad[1]} is malformed ({bad[2].reason}); {rec.word}/{rec.args.strip()[:40]} at line "
                f"{rec.line} replaces it before any motion: read as that")


def pp_word(st: ReaderState, rec: Record) -> None:
    """A CATIA PP word (``LOOP/START,15``, ``AICC/ON,10``, a bare word, ``TOOLNO/13,1``): kept for
    one grouped warning. CATIA writes its PP table's syntaxes and its user's PP instructions into
    the APT as they are (Dassault, NC Manufacturing, "PP Tables and PP Word Syntaxes" and the "PP
    Instruction" operation), for a post-processor that knows them; they move nothing here."""
    text = f"{rec.word}/{rec.args.strip()}" if rec.args.strip() else rec.word
    st.pp_words.setdefault(text[:40], rec.line)


def _pp_words_warning(st: ReaderState) -> None:
    if not st.pp_words:
        return
    shown = sorted(st.pp_words.items(), key=lambda item: item[1])
    listed = ", ".join(f"{text} (line {line})" for text, line in shown[:8])
    more = f" and {len(shown) - 8} more" if len(shown) > 8 else ""
    st.warn(shown[0][1], f"{len(shown)} post-processor words in CATIA's output (its PP table's or typed by its user), "
            f"not CL records, ignored: {listed}{more}", kind="CATIA PP words")


def _dispatch(st: ReaderState, rec: Record) -> None:
    if isinstance(st.curve, curves.PendingSpline) and rec.word not in ("KNOT", "CNTRL"):
        curves.finish_spline(st)
    if "," in rec.word:  # a motion statement's modifier: TLON, GOFWD -> TLON,GOFWD
        rec = rec._replace(word=re.sub(r"\s*,\s*", ",", rec.word))
    handler = HANDLERS.get(rec.word)
    if rec.word == "TOOLNO" and "TURN" in (w.strip().upper() for w in rec.args.split(",")):
        # CATIA's lathe output names its tool TOOLNO/n,TURN (Dassault, Lathe Machining user's guide,
        # its APT sample: TOOLNO/1,TURN, FEDRAT/...,MMPR, GOTO/x,0,z)
        raise st.other_machine(f"TOOLNO/{rec.args.strip()[:40]}: a turning tool; this is a turning program (for a "
                               "lathe), and the VERNE is a milling machine and cannot turn", rec.line)
    if rec.word.partition(",")[0] == "CHANNEL":
        # CATIA's output for a multi-turret machine opens with CHANNEL,n (the same sample)
        raise st.other_machine(f"{rec.word[:40]}: a program for one channel of a machine with several (turrets or "
                               "heads); the VERNE has one spindle and one channel", rec.line)
    if handler is not None and rec.word in _REPLACEABLE:
        _machine_function(st, rec, handler)
    elif handler is not None:
        handler(st, rec)
    elif rec.word == "$":
        raise st.fail("continuation '$' at end of file: the record is incomplete", rec.line)
    elif rec.word in _REJECTED:
        raise st.fail(_REJECTED[rec.word], rec.line)
    elif rec.word.rpartition(",")[2].startswith("GO"):  # a motion statement with modifiers: never dropped
        raise st.fail(f"motion statement {rec.word[:40]} is not supported (of them only TLON,GOFWD along a CIRCLE "
                      "is: offset motion needs the part surfaces): output GOTO points", rec.line)
    elif rec.word in _INFORMATIONAL:
        st.warn(rec.line, _INFORMATIONAL[rec.word], kind=rec.word)
    elif rec.word in _IGNORED or rec.word.startswith(_IGNORED_PREFIXES):
        pass
    elif st.dialect.name == DIALECTS["catia"].name and _PP_WORD_RE.match(rec.word):
        pp_word(st, rec)
    else:
        shown = rec.word if len(rec.word) <= 40 else rec.word[:37] + "..."
        st.warn(rec.line, f"unknown record '{shown}' ignored", kind=f"unknown {shown}")


MAX_CALL_DEPTH = 16  # subroutines calling subroutines


@dataclass
class _Subroutines:
    """``DEFSUB/n`` ... ``ENDSUB`` store their records unexecuted; ``CALSUB/n`` runs them (Pro/ENGINEER)."""

    defined: dict[str, list[Record]] = field(default_factory=dict)
    capturing: tuple[str, int, list[Record]] | None = None  # name, DEFSUB line, records so far

    def name(self, st: ReaderState, rec: Record) -> str:
        words = [w.strip().upper() for w in rec.args.split(",")]
        if len(words) != 1 or not words[0]:
            raise st.fail(f"{rec.word} needs one subroutine name or number, got '{rec.args.strip()[:40]}'", rec.line)
        return words[0].removesuffix(".0") if words[0].replace(".", "").isdigit() else words[0]


def _bulk_gotos(st: ReaderState, run: GotoRun) -> int:
    """How many leading GOTOs of ``run`` the fast route of :func:`_run` takes, appended at once.

    The same checks as that route, on every row in numpy, and the same numbers (Python's float
    parses every one): 3 or 6 finite coordinates under 1e7 in sum, a unit axis within 2 %, a
    3-number GOTO keeping the axis before it. Returns at the first row the route would not take.
    """
    joined = ",".join(run.args)
    if "_" in joined:  # float() would read 1_0 as 10: the one-at-a-time route says what it is
        return 0
    try:
        values = np.array(list(map(float, joined.split(","))))
    except ValueError:
        return 0
    counts = np.fromiter(map(str.count, run.args, itertools.repeat(",")), int, len(run.args)) + 1
    if np.all(counts == 6):  # the usual runs: one shape throughout
        rows = values.reshape(-1, 6)
        xyz, ijk, six = rows[:, :3], rows[:, 3:], np.ones(len(counts), bool)
    elif np.all(counts == 3):
        xyz, ijk, six = values.reshape(-1, 3), np.full((len(counts), 3), np.nan), np.zeros(len(counts), bool)
    else:
        shaped = (counts == 3) | (counts == 6)
        counts = counts[:len(counts) if shaped.all() else int(np.argmin(shaped))]
        start = np.cumsum(counts) - counts
        xyz = values[start[:, None] + np.arange(3)]
        six = counts == 6
        ijk = np.where(six[:, None], values[np.minimum(start[:, None] + np.arange(3, 6), len(values) - 1)], np.nan)
    x, y, z = xyz.T
    i, j, k = ijk.T
    good = np.abs(x) + np.abs(y) + np.abs(z) < 1e7  # also false for NaN
    norm = i * i + j * j + k * k
    good &= ~six | ((norm > 0.98) & (norm < 1.02))
    n = len(good) if good.all() else int(np.argmin(good))
    if n == 0:
        return 0
    last = np.maximum.accumulate(np.where(six[:n], np.arange(n), -1))  # the GOTO that set each row's axis
    axes = ijk[np.maximum(last, 0)]
    axes[last < 0] = st.axis
    st.rows.extend(np.column_stack([xyz[:n], axes]))
    st.lines.extend(run.lines[:n])
    if last[-1] >= 0:
        st.axis = tuple(float(a) for a in axes[-1])
    return n


def _run(st: ReaderState, recs: Iterable[Record | GotoRun], subs: _Subroutines, depth: int) -> None:
    add_row, add_line = st.rows.data.extend, st.lines.append  # the fast route's appends, bound once
    fast = st.fast_goto_ok()
    for item in recs:
        if isinstance(item, GotoRun):
            taken = _bulk_gotos(st, item) if fast and subs.capturing is None else 0
            if taken == len(item.args):
                continue
            batch: Iterable[Record] = item.records(taken)
        else:
            batch = (item,)
        for rec in batch:
            if subs.capturing is not None:
                if rec.word == "ENDSUB":
                    name, _line, body = subs.capturing
                    subs.defined[name] = body
                    subs.capturing = None
                elif rec.word == "DEFSUB":
                    raise st.fail(f"DEFSUB inside the definition of subroutine {subs.capturing[0]} "
                                  f"(line {subs.capturing[1]})", rec.line)
                else:
                    subs.capturing[2].append(rec)
                continue
            if fast and rec.word == "GOTO" and not rec.follows_goto and "_" not in rec.args:  # float(1_0) = 10
                try:
                    vals = [float(v) for v in rec.args.split(",")]
                except ValueError:
                    vals = []
                if len(vals) == 3 and abs(vals[0]) + abs(vals[1]) + abs(vals[2]) < 1e7:  # also false for NaN
                    vals += st.axis
                    add_row(vals)
                    add_line(rec.line)
                    continue
                if len(vals) == 6 and abs(vals[0]) + abs(vals[1]) + abs(vals[2]) < 1e7:
                    i, j, k = vals[3], vals[4], vals[5]
                    if 0.98 < i * i + j * j + k * k < 1.02:
                        st.axis = (i, j, k)
                        add_row(vals)
                        add_line(rec.line)
                        continue
            if rec.word == "DEFSUB":
                subs.capturing = (subs.name(st, rec), rec.line, [])
            elif rec.word == "ENDSUB":
                raise st.fail("ENDSUB without DEFSUB", rec.line)
            elif rec.word == "CALSUB":
                name = subs.name(st, rec)
                if name not in subs.defined:
                    raise st.fail(f"CALSUB/{name[:40]}: no such subroutine defined before it", rec.line)
                if depth >= MAX_CALL_DEPTH:
                    raise st.fail(f"CALSUB/{name[:40]}: subroutines nested more than {MAX_CALL_DEPTH} deep",
                                  rec.line)
                _run(st, subs.defined[name], subs, depth + 1)
            else:
                _dispatch(st, rec)
            if st.done:
                return
            fast = st.fast_goto_ok()


def _parse(lines: Iterable[str], st: ReaderState) -> None:
    subs = _Subroutines()
    _run(st, record_runs(lines), subs, 0)
    if st.malformed:  # nothing replaced it: the error, as for any record
        st.motion_after_malformed()
    _pp_words_warning(st)
    if subs.capturing is not None:
        raise st.fail(f"DEFSUB/{subs.capturing[0][:40]} has no ENDSUB", subs.capturing[1])
    if isinstance(st.curve, curves.PendingSpline):
        curves.finish_spline(st)
    if isinstance(st.curve, curves.PendingArc):
        raise st.fail(f"{st.curve.word} is not followed by the GOTO that ends the arc", st.curve.line)
    if st.tools is not None and st.tools.open:
        st.tools.close(st)


def _arc_evidence(st: ReaderState) -> tuple[int, int, int | None, int | None]:
    """Tangent-move votes of every arc: (ccw votes, cw votes, first ccw-voting arc line, first cw one)."""
    if not st.arcs:
        return 0, 0, None, None
    rows = st.rows.array()[:, :3]
    nan = np.full(3, np.nan)
    before = np.array([rows[a.start - 1] if a.start > 0 else nan for a in st.arcs])
    after = np.array([rows[a.end + 1] if a.end + 1 < len(rows) else nan for a in st.arcs])
    starts = rows[[a.start for a in st.arcs]]
    ends = rows[[a.end for a in st.arcs]]
    ccw, cw = tangent_votes(before, starts, ends, after, np.array([a.centre for a in st.arcs]),
                            np.array([a.axis for a in st.arcs]))
    net = ccw - cw  # an arc's own verdict; a cusp (one side each way) says nothing
    first_ccw = next((a.line for a, v in zip(st.arcs, net, strict=True) if v > 0), None)
    first_cw = next((a.line for a, v in zip(st.arcs, net, strict=True) if v < 0), None)
    return int(ccw.sum()), int(cw.sum()), first_ccw, first_cw


def read_cl(
    path: str | os.PathLike[str],
    *,
    units: Literal["mm", "inch"] | None = None,
    chordal_tolerance: float = 0.001,
    arc_direction: ArcDirection | None = None,
    frame: FrameMode | None = None,
    feed: float | None = None,
) -> Toolpath:
    """Read an APT/CLSF cutter-location file (mm, mm/min, part frame; see the module docstring).

    ``units`` overrides the source units; ``chordal_tolerance`` (mm) bounds the deviation of
    arcs, helices and splines expanded into poses; ``arc_direction`` (``"cw"``/``"ccw"`` about
    the CIRCLE axis) and ``frame`` (``"local"``/``"world"``/``"apply"``) override the dialect's
    conventions; ``feed`` (mm/min, whatever the file's units) is the feed of the feed moves
    before the first FEDRAT, for CAM output that gives none (recorded in ``notes``). Raises
    :class:`~verne_post.errors.InputError` naming the file and line.
    """
    src = os.fspath(path)
    override = _check_units_arg(units)
    if arc_direction not in (None, "cw", "ccw"):
        raise InputError(f"arc direction must be 'cw' or 'ccw', got {arc_direction!r}")
    if frame not in (None, "local", "world", "apply"):
        raise InputError(f"frame must be 'local', 'world' or 'apply', got {frame!r}")
    if feed is not None and not (isinstance(feed, (int, float)) and MIN_FEED <= feed <= MAX_FEED):
        raise InputError(f"--feed must be from {MIN_FEED:g} to {MAX_FEED:g} mm/min, got {feed!r}")
    if not (isinstance(chordal_tolerance, (int, float)) and 1e-6 <= chordal_tolerance <= 10.0):
        raise InputError(f"chordal tolerance must be from 1e-6 to 10 mm, got {chordal_tolerance!r}")
    text = _read_text(path, src)
    found = detect_dialect(text)

    def reading(frames: FrameMode | None) -> ReaderState:
        dialect = found.with_overrides(arc_direction, frames)

        def attempt(direction: ArcDirection) -> ReaderState:
            warnings = Warnings(src)
            file_units = _decide_units(text, override, src, warnings)
            st = ReaderState(src, file_units, override is not None, float(chordal_tolerance), dialect, warnings,
                             None if feed is None else float(feed))
            st.arc_direction = direction
            _parse(iter_lines(text), st)
            return st

        st = attempt(dialect.arc_direction or "ccw")
        ccw, cw, first_ccw, first_cw = _arc_evidence(st)
        if dialect.arc_direction is not None:
            against, first = (cw, first_cw) if dialect.arc_direction == "ccw" else (ccw, first_ccw)
            agree = ccw + cw - against
            if against > agree:
                given = "as given by --arc-direction" if arc_direction else f"as {dialect.name} documents"
                raise InputError(
                    f"arcs run {'counter-clockwise' if dialect.arc_direction == 'ccw' else 'clockwise'} about the "
                    f"CIRCLE axis {given}, but {against} of {ccw + cw} tangent moves into and out of the file's "
                    f"arcs say the other way (this arc among them): check the CAM system, or give --arc-direction",
                    source=src, line=first)
        elif cw > ccw:
            st = attempt("cw")
        elif ccw == cw and st.arcs:
            st.warn(st.arcs[0].line, "no tangent move tells the arc direction: counter-clockwise about the CIRCLE "
                    "axis assumed (give --arc-direction to choose)")
        return st

    st = reading(frame)
    if not (_FRAME_RE.search(text) and (frame or found.frames) in ("local", "apply")):
        text = ""  # the toolpath's arrays need the room
        return toolpath_of(st)
    return _frame_by_tool_direction(toolpath_of(st), frame, found.frames, lambda other: toolpath_of(reading(other)))


# Frame records whose reading (the data in the frame, or mapped by it) can turn the tool over.
_FRAME_RE = re.compile(r"^[ \t]*(?:MSYS|CSYS|ORIGIN)[ \t]*/", re.IGNORECASE | re.MULTILINE)


def _up_share(tp: Toolpath) -> float:
    """The share of the poses whose tool axis points away from the table (k > 0 in the part frame,
    whose Z is the table's: the work offset only translates)."""
    return float(np.mean(tp.axis[:, 2] > 1e-9))


def _frame_by_tool_direction(tp: Toolpath, given: FrameMode | None, default: FrameMode,
                             reading: Callable[[FrameMode], Toolpath]) -> Toolpath:
    """Of the two readings of a file's frame records, the one under which the tool points away
    from the table for most poses.

    NX's MSYS says where the MCS sits in NX's absolute frame, and its CLSF documentation puts the
    GOTO data in the MCS (the ``local`` reading); yet real NX files exist both ways (CL-DIALECTS:
    drilling files with MSYS Z down and tool axes +Z in the MCS, a variable-contour file with MSYS
    Z down and every axis down in the MCS). A tool pointing into the table is never the meaning:
    of the readings ``local`` and ``apply``, the one with the tool above the part for most poses
    is taken, with a warning and a note for the program header. ``--frame`` (``given``) is obeyed;
    when it turns the tool down and the other reading would not, a warning says so.
    """
    share = _up_share(tp)
    if share > 0.5:
        return tp
    other: FrameMode = "apply" if (given or default) == "local" else "local"
    try:
        alternative = reading(other)
    except InputError:
        return tp  # the other reading is not even readable: the first one's outcome stands
    other_share = _up_share(alternative)
    if other_share <= 0.5:
        return tp
    first = int(tp.line[0])
    if given is not None:
        hint = (f"--frame {given}: the tool axis points into the table at {1 - share:.0%} of the poses; with "
                f"--frame {other} it points away from it at {other_share:.0%}")
        return replace(tp, warnings=(*tp.warnings, f"{tp.source}:{first}: {hint}"), frame_hint=f"--frame {other}")
    how = {"apply": "mapped by the frame records into the part frame", "local": "in the frame the records describe"}
    text = (f"frames read as {other} (the data {how[other]}), not {given or default}: so the tool axis points away "
            f"from the table at {other_share:.0%} of the poses, against {share:.0%}; --frame {default} overrides")
    return replace(alternative, warnings=(*alternative.warnings, f"{tp.source}:{first}: {text}"),
                   notes=(*alternative.notes, f"FRAMES READ AS {other.upper()}: THE TOOL AXES POINT AWAY FROM THE "
                                              f"TABLE (--frame {default} OVERRIDES)"))


_CSV_COLUMNS = ("x", "y", "z", "i", "j", "k")


def read_pose_csv(path: str | os.PathLike[str], *, units: Literal["mm", "inch"] | None = None) -> Toolpath:
    """Read a CSV pose list: header ``x,y,z,i,j,k[,feed]`` (any order, case-insensitive).

    Positions are in ``units`` (default mm) in the part frame; ``feed`` (optional column, empty
    cells allowed) is in ``units`` per minute, converted to mm/min, NaN where absent. Every pose
    is a feed move with tool 0; axes are normalised. Blank lines and lines starting with ``#``
    are skipped.
    """
    src = os.fspath(path)
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
    validate_poses(tip, axis, line, src, "pose")
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

    Keyword arguments go to :func:`read_pose_csv` or :func:`read_cl`; ``chordal_tolerance``,
    ``arc_direction``, ``frame`` and ``feed`` are dropped for CSV files (they have no arcs or
    frames, and their feed column is per row).
    """
    if Path(path).suffix.lower() == ".csv":
        for key in ("chordal_tolerance", "arc_direction", "frame", "feed"):
            kw.pop(key, None)
        return read_pose_csv(path, **kw)
    return read_cl(path, **kw)
