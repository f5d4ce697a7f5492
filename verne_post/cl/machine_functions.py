"""Feeds, spindle, coolant, stops, dwells, cutter compensation, units and text records.

``FEDRAT/f[,unit]`` or ``FEDRAT/unit,f``: ``MMPM``, ``IPM``, ``PERMIN`` (file units per minute,
Makino FF CAM), ``MMPR``, ``IPR``, ``PERREV`` (per revolution: needs a spindle speed), ``INVERS``
(inverse time, 1/min); bare: file units per minute. Feeds are modal and kept in mm/min.
``FEDRAT/INVERS,AUTO`` and ``FEDRAT/INVERS,OFF`` carry no feed: Creo writes them around a sequence
whose inverse-time feeds the post-processor is to compute from the programmed feed (PTC Creo
help, "Supported CL Data Commands"), as this one always does; the feed stays as programmed.
``SPINDL/[RPM,]s[,CLW|CCLW]``, ``SPINDL/ON|OFF``; ``COOLNT/ON|FLOOD|MIST|THRU|OFF``;
``STOP``/``OPSTOP``; ``DELAY/s`` (a dwell in seconds). ``CUTCOM/LEFT|RIGHT|ON[,...]`` on
centre-line data is accepted with one warning (a joint-space program cannot carry controller
compensation; the path is the tool centre as programmed); on contact-point data it is an error.
"""

from __future__ import annotations

import math
from typing import Literal

from verne_post.toolpath import MIN_FEED, Comment, Coolant, Dwell, Spindle, Stop

from .lexer import Record
from .state import MM_PER_INCH, UNIT_WORDS, ReaderState

MAX_FEED = 1e7
MAX_RPM = 1e6
MAX_DWELL = 1e5  # s
# mm per unit of each feed word; None: the file's units. FPM / FPR (feet): Creo's FEDRAT units
# (PTC Creo help, "Supported CL Data Commands": FPM, IPM, FPR, IPR, MMPM, MMPR).
_PER_MINUTE: dict[str, float | None] = {"MMPM": 1.0, "IPM": MM_PER_INCH, "FPM": 12 * MM_PER_INCH, "PERMIN": None}
_PER_REV: dict[str, float | None] = {"MMPR": 1.0, "IPR": MM_PER_INCH, "FPR": 12 * MM_PER_INCH, "PERREV": None}
FEED_WORDS = frozenset({*_PER_MINUTE, *_PER_REV})


def _checked_feed(st: ReaderState, mm_per_min: float, what: str, line: int) -> float:
    if not MIN_FEED <= mm_per_min <= MAX_FEED:
        raise st.fail(f"{what} feed {mm_per_min:.6g} mm/min is outside {MIN_FEED:g} to {MAX_FEED:g}", line)
    return mm_per_min


def feed_from(st: ReaderState, value: float, unit: str | None, what: str, line: int) -> float:
    """Feed in mm/min from a value and its unit word (None: file units per minute)."""
    if value <= 0:
        raise st.fail(f"{what} feed must be positive, got {value:g}", line)
    if unit is None or unit in _PER_MINUTE:
        factor = _PER_MINUTE.get(unit or "PERMIN") or st.scale
        return _checked_feed(st, value * factor, what, line)
    per_rev = value * (_PER_REV[unit] or st.scale)
    if not st.spindle_on or st.rpm is None:
        raise st.fail(f"{what} per-revolution feed ({unit}) needs a spindle speed (SPINDL)", line)
    return _checked_feed(st, per_rev * st.rpm, what, line)


def fedrat(st: ReaderState, rec: Record) -> None:
    toks = st.tokens(rec.args, "FEDRAT", rec.line)
    nums = [t for t in toks if isinstance(t, float)]
    words = [t for t in toks if isinstance(t, str)]
    if not nums and words in (["INVERS", "AUTO"], ["INVERS", "OFF"]):
        return
    if len(nums) != 1:
        raise st.fail(f"FEDRAT needs one feed value, got {len(nums)}", rec.line)
    if len(words) > 1:
        raise st.fail(f"FEDRAT has more than one unit word: {', '.join(words)[:60]}", rec.line)
    unit = words[0] if words else None
    if unit is not None and unit not in FEED_WORDS and unit != "INVERS":
        raise st.fail(f"FEDRAT: unknown feed unit '{unit[:40]}' (expected MMPM, IPM, FPM, PERMIN, MMPR, IPR, FPR, "
                      "PERREV or INVERS)", rec.line)
    value = nums[0]
    if st.first_fedrat is None:
        st.first_fedrat = len(st.lines)
    st.fpr = None
    st.inverse = False
    if unit == "INVERS":
        if value <= 0:
            raise st.fail(f"FEDRAT inverse-time value must be positive, got {value:g}", rec.line)
        st.feed_val = _checked_feed(st, value, "FEDRAT inverse-time", rec.line)
        st.inverse = True
    elif unit in _PER_REV:
        if value <= 0:
            raise st.fail(f"FEDRAT feed must be positive, got {value:g}", rec.line)
        st.fpr = value * (_PER_REV[unit] or st.scale)
        if not st.spindle_on or st.rpm is None:
            raise st.fail(f"FEDRAT/{unit} (feed per revolution) needs a spindle speed (SPINDL) first", rec.line)
        st.feed_val = _checked_feed(st, st.fpr * st.rpm, "FEDRAT", rec.line)
    else:
        st.feed_val = feed_from(st, value, unit, "FEDRAT", rec.line)
    st.push_state()


def _refresh_per_rev_feed(st: ReaderState, line: int) -> None:
    if st.fpr is None:
        return
    if st.spindle_on and st.rpm is not None:
        st.feed_val = _checked_feed(st, st.fpr * st.rpm, "per-revolution", line)
    else:
        st.feed_val = math.nan
        st.feed_problem = "feed move with a per-revolution FEDRAT while the spindle is off"
    st.push_state()


def spindl(st: ReaderState, rec: Record) -> None:
    toks = st.tokens(rec.args, "SPINDL", rec.line)
    rpm: float | None = None
    direction: Literal["CW", "CCW"] | None = None
    off = on = False
    i = 0
    while i < len(toks):
        t = toks[i]
        if isinstance(t, float):
            if rpm is not None:
                raise st.fail("SPINDL has more than one speed", rec.line)
            rpm = t
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
            raise st.fail(f"SPINDL/{t} (constant surface speed, a lathe's spindle mode) is not supported; program "
                          "RPM", rec.line)
        elif t != "RPM":
            raise st.fail(f"SPINDL: unknown word '{t[:40]}'", rec.line)
        i += 1
    index = len(st.lines)
    if off:
        if rpm is not None or on or direction is not None:
            raise st.fail("SPINDL/OFF takes no speed or direction", rec.line)
        st.spindle_on = False
        st.events.append(Spindle(index=index, line=rec.line, rpm=0.0, direction="OFF"))
    else:
        if rpm is None:
            if st.rpm is None:
                raise st.fail("SPINDL/ON without a previous spindle speed", rec.line)
            rpm = st.rpm
        if not 0 < rpm <= MAX_RPM:
            raise st.fail(f"spindle speed must be positive and at most {MAX_RPM:g} rpm, got {rpm:g}", rec.line)
        st.rpm = rpm
        if direction is not None:
            st.spindle_dir = direction
        st.spindle_on = True
        st.events.append(Spindle(index=index, line=rec.line, rpm=rpm, direction=st.spindle_dir))
    _refresh_per_rev_feed(st, rec.line)


_PRESSURES = frozenset({"LOW", "MEDIUM", "HIGH"})
_COOLANT: dict[str, Literal["ON", "FLOOD", "MIST", "THRU", "OFF"]] = {
    "ON": "ON", "FLOOD": "FLOOD", "MIST": "MIST", "THRU": "THRU", "THROUGH": "THRU", "OFF": "OFF",
    "TAP": "FLOOD",  # tapping fluid: NX Post Builder gives it M8 (mom_sys_coolant_code(TAP)), as flood
}  # fmt: skip


def coolnt(st: ReaderState, rec: Record) -> None:
    """COOLNT/type[,pressure]: Creo writes ``COOLNT / type, pressure`` with pressure LOW, MEDIUM or HIGH
    (PTC Creo help, "Supported CL Data Commands"), which one M code cannot carry: dropped."""
    words = [t for t in st.tokens(rec.args, "COOLNT", rec.line) if isinstance(t, str) and t not in _PRESSURES]
    known = [_COOLANT[w] for w in words if w in _COOLANT]
    if len(known) != len(words) or not known:
        st.warn(rec.line, f"COOLNT/{rec.args.strip()[:40]}: coolant mode not supported, ignored", kind="COOLNT")
        return
    mode = next((m for m in known if m != "ON"), "ON")
    st.events.append(Coolant(index=len(st.lines), line=rec.line, mode=mode))


def stop(st: ReaderState, rec: Record) -> None:
    st.events.append(Stop(index=len(st.lines), line=rec.line, optional=False))


def opstop(st: ReaderState, rec: Record) -> None:
    st.events.append(Stop(index=len(st.lines), line=rec.line, optional=True))


def dwell_event(st: ReaderState, seconds: float, line: int) -> None:
    if not 0 <= seconds <= MAX_DWELL:
        raise st.fail(f"dwell must be from 0 to {MAX_DWELL:g} s, got {seconds:g}", line)
    if seconds > 0:
        st.events.append(Dwell(index=len(st.lines), line=line, seconds=seconds))


def delay(st: ReaderState, rec: Record) -> None:
    """DELAY/s (seconds), or DELAY/REV,n: n spindle revolutions (NX's dwell UDE in revolutions, NX
    Post Builder's ``mom_delay_revs``), at the programmed spindle speed."""
    toks = st.tokens(rec.args, "DELAY", rec.line)
    nums = [t for t in toks if isinstance(t, float)]
    words = [t for t in toks if isinstance(t, str)]
    if len(nums) != 1 or words not in ([], ["REV"]):
        raise st.fail("DELAY needs one time in seconds (or REV,n revolutions)", rec.line)
    if words:
        if not st.spindle_on or st.rpm is None:
            raise st.fail("DELAY/REV (a dwell in spindle revolutions) needs a spindle speed (SPINDL)", rec.line)
        dwell_event(st, nums[0] * 60.0 / st.rpm, rec.line)
    else:
        dwell_event(st, nums[0], rec.line)


def cutcom(st: ReaderState, rec: Record) -> None:
    words = [t for t in st.tokens(rec.args, "CUTCOM", rec.line) if isinstance(t, str)]
    if not words or words[0] == "OFF" or "LENGTH" in words:
        return  # CUTCOM/ON,LENGTH,h: tool length compensation, which the tool data already give here
    if st.dialect.centre_line is False:
        raise st.fail(f"CUTCOM/{rec.args.strip()[:40]}: cutter compensation on tool contact-point data cannot be "
                      "postprocessed into a joint-space program; output tool centre-line CL data", rec.line)
    st.warn(rec.line, "CUTCOM (cutter compensation) ignored: a joint-space program cannot carry it; the tool "
            "centre follows the CL path as programmed", kind="CUTCOM")


def units(st: ReaderState, rec: Record) -> None:
    word = rec.args.strip().upper()
    if word not in UNIT_WORDS:
        raise st.fail(f"unknown UNITS '{rec.args.strip()[:40]}' (expected MM or INCHES)", rec.line)
    u = UNIT_WORDS[word]
    if st.units_given:
        if u != st.units:
            st.warn(rec.line, f"UNITS/{rec.args.strip()} ignored: units='{st.units}' was given")
        return
    if u != st.units:
        first = f" (line {st.units_seen[1]})" if st.units_seen else ""
        raise st.fail(f"UNITS changes from {st.units}{first} to {u}: mixed units in one file are not supported",
                      rec.line)
    if st.units_seen is None:
        st.units_seen = (u, rec.line)


def fini(st: ReaderState, rec: Record) -> None:
    st.done = True


def text_record(st: ReaderState, rec: Record) -> None:
    """PPRINT, PARTNO, INSERT: the first PARTNO names the part, the rest become comments."""
    if rec.word == "PARTNO" and st.part_name is None:
        st.part_name = rec.args
        return
    if rec.word == "INSERT":
        st.warn(rec.line, f"INSERT/{rec.args[:40]}: not executed, kept as a comment", kind="INSERT")
    st.events.append(Comment(index=len(st.lines), line=rec.line, text=rec.args))


def head(st: ReaderState, rec: Record) -> None:
    """HEAD/1, HEAD/OFF and the like change nothing on a one-spindle machine; Creo's HEAD/2 and
    HEAD/BOTH (multiple turrets, synchronised sequences: PTC Creo help, "Supported CL Data
    Commands") would merge another head's motion into this one's."""
    toks = st.tokens(rec.args, "HEAD", rec.line)
    if toks and (toks[0] == "BOTH" or (isinstance(toks[0], float) and toks[0] != 1.0)):
        raise st.other_machine(f"HEAD/{rec.args.strip()[:40]}: a program for a machine with several heads (motion for "
                               "another head or several at once); the VERNE has one spindle: output head 1's CL data "
                               "alone", rec.line)


_TURNING = "a turning program (for a lathe); the VERNE is a milling machine and cannot turn"


def turret(st: ReaderState, rec: Record) -> None:
    """TURRET: a lathe's tool turret, written instead of LOADTL by lathe and mill-turn output (CATIA's
    Lathe Machining, Creo's lathe and mill-turn workcells)."""
    raise st.other_machine(f"TURRET/{rec.args.strip()[:40]}: {_TURNING}", rec.line)


def mode(st: ReaderState, rec: Record) -> None:
    """MODE/MILL or MODE/TURN: Autodesk's ISO 4343 APT posts open with the machining mode;
    ``MODE/TURN`` is a turning program. Other MODE records change nothing here."""
    words = [w.strip().upper() for w in rec.args.split(",")]
    if words and words[0] in ("TURN", "LATHE"):
        raise st.other_machine(f"MODE/{rec.args.strip()[:40]}: {_TURNING}", rec.line)


HANDLERS = {
    "FEDRAT": fedrat, "SPINDL": spindl, "COOLNT": coolnt, "STOP": stop, "OPSTOP": opstop, "DELAY": delay,
    "CUTCOM": cutcom, "UNITS": units, "UNIT": units, "FINI": fini, "PPRINT": text_record, "PARTNO": text_record,
    "INSERT": text_record, "HEAD": head, "TURRET": turret, "MODE": mode,
}  # fmt: skip
