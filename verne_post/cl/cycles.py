"""Drilling cycles (``CYCLE/...``) as explicit moves along the tool axis.

Pure functions (numpy only, no reader state). :func:`parse_cycle` turns the tokens of one
``CYCLE/`` record into a :class:`CycleSpec`; :func:`cycle_moves` expands it at one hole into
rapid, feed and dwell moves. All lengths are in the CL file's units, measured along the tool
axis from the hole top (the ``GOTO`` point while the cycle is active); feeds keep the record's
unit word and the reader converts them.

Sources, per CAM family
-----------------------
* Siemens NX writes ``CYCLE/DRILL[,DEEP|BRKCHP],RAPTO,r,FEDTO,-d,MMPM,f[,RTRCTO,AUTO|v]
  [,STEP,s...][,DWELL,t]`` (FEDTO negative: below the point). The expansion follows NX Post
  Builder's own simulated cycles, which turn the same cycle data into linear moves for
  controllers without canned cycles: github.com/Unigraphics/PostBuilder (branch PB1980s),
  POSTBUILD/pblib/custom_command/pb_cmd_simulated_cycles.tcl. There every position is
  ``top_of_hole + value * spindle_axis`` with ``rapid_to`` above and ``feed_to`` below the top;
  ``PB_CMD_sim_cycle_drill_move``: rapid to rapid_to, feed to feed_to, rapid to retract_to;
  ``_drill_dwell_move``: the same with a dwell at the bottom; ``_drill_deep_move``: pecks of
  ``step1``, after each one rapid back to rapid_to, then rapid down to ``rapid_to`` above the
  previous peck's depth (only if that is below rapid_to) before feeding on;
  ``_drill_break_chip_move``: the same without the full retract, i.e. after each peck rapid back
  up to ``rapid_to`` above the peck's depth, then feed on; ``_bore_move`` / ``_bore_dwell_move``:
  feed in, [dwell,] feed out to rapid_to, rapid to retract_to if that is higher (``SIM_RTRCTO``);
  DRAG / NODRAG / BACK / MANUAL boring stop or orient the spindle.
* PTC Creo writes ``CYCLE / DEEP, DEPTH, a, STEP, b, IPM, c, CLEAR, d, RAPTO, e, RETURN, f``;
  BRKCHP adds ``DWELL | BACK | REV, g, TIMES, h``; a peck table repeats STEP (and may change
  the feed between steps): PTC Creo help, "CL Output for Holemaking Cycles" and "Example: Peck
  Table" (support.ptc.com/help/creo/creo_pma/usascii/manufacturing/nc/
  cl_output_for_holemaking_cycles.html, example_peck_table.html). Creo defines RAPTO as a
  further rapid advance from CLEAR towards the hole and RETURN as the pull-out distance.
* SolidWorks CAM (CAMWorks): only real output is known (/work/shared/CL-DIALECTS.md):
  ``CYCLE/DRILL,FEDTO,2.75344,MMPM,731.52,RAPTO,3.,RTRCTO,10.,DWELL,0`` and
  ``CYCLE/DEEP2,FEDTO,10.1,1STPECK,5.,SUBPECK,2.,MMPM,1097.28,RAPTO,3.,RTRCTO,10.`` (FEDTO
  positive). No documentation was found; DEEP2 is read as a full-retract peck cycle whose first
  peck is 1STPECK and every later one SUBPECK.
* Creo's ``cycle_format fixed``: ``CYCLE / type, z, f, units, [t,] r, i`` (PTC Creo help, "CL Output
  for Holemaking Cycles"; t only for TAP, i the depth increment of DEEP): read as the classic
  form with the peck increment last.
* Classic positional APT: ``CYCLE/DRILL, d, IPM, f, c [, RAPTO, r] [, DWELL, q]``,
  ``CYCLE/DEEP, d, INCR, i, IPM, f, c`` (depth first, clearance after the feed), read with the
  GOTO the hole top and c above it. Autodesk's "Common ISO 4343 APT" posts write the same shape
  with the GOTO the hole bottom and c an absolute height, below zero where the holes are
  (``cycle_point`` in :mod:`.dialects`; the reader converts, this module sees only the hole top
  and heights above it); their chip breaking's DWELL is at the final depth; their fine boring
  (G76) adds its shift after c, refused as boring that orients the spindle.

Readings chosen
---------------
* depth = DEPTH, |FEDTO| or the leading number; approach (rapid-to height above the top) = RAPTO,
  else CLEAR; retract = the largest of CLEAR, RAPTO, RTRCTO and RETURN. For Creo records with
  both CLEAR and RAPTO this feeds from a height at least as high as Creo's CLEAR - RAPTO, never
  lower, so it can only feed more air, not rapid into material.
* Peck depths: STEP/INCR values (or 1STPECK, SUBPECK) in order, the last one repeated, until
  the total depth; the final peck is whatever remains (10.1 deep, 5 then 2: 5, 7, 9, 10.1).
* Creo's ``RETURN, 0`` means "retract to the retract plane" (PTC Creo help, "CL Output for
  Holemaking Cycles"), the plane the tool came from: read as ``RTRCTO,AUTO``.
* Re-entry clearance between pecks and the chip-break back-off both equal the approach
  distance, as NX's simulated cycles do; the CAM declared that distance safe to rapid to above
  material, and the previous peck's bottom is material. A Creo ``BACK,g`` sets the back-off.
  (LinuxCNC's G83 uses a fixed 0.010 in instead: rs274ngc ``G83_RAPID_DELTA``.)
* A dwell (DWELL,t; t = 0 means none) is made once, at the final depth.
* Positioning over each hole, from wherever the tool is to the approach point, splits into a move
  across the axis and one along it, the one along it first when it goes up and last when it goes
  down, as NX's ``SIM_RAPID_APPROACH`` does (and as canned cycles position): never a diagonal
  rapid that descends while it travels (:func:`approach_moves`).
* ``RTRCTO,AUTO`` is NX's G98, ``RTRCTO,v,MANUAL`` its G99 (NX Post Builder's MOM variable list,
  POSTBUILD/app/mom_vars_csv.txt, ``mom_cycle_retract_mode``): AUTO returns to the level the tool
  was at when the cycle began, if that is higher than the retract (the reader knows that level),
  MANUAL to the retract value, which is what every other form does.
* ``CYCLE/ON[,keyword,value...]`` re-activates the last cycle with those values replaced or added
  (NX: ``CYCLE/ON,FEDTO,-74.5,...`` after ``CYCLE/DRILL,DEEP,...``): :func:`reactivated`.
* Rejected with a one-line reason: tapping (the feed must follow the spindle, which a
  joint-space program cannot express), boring that stops or orients the spindle, web drilling,
  milling cycles, Creo chip breaking by dwell/revolutions/retract count, peck tables that change
  the feed, unknown words, and contradictory or incomplete forms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

__all__ = ["MAX_PECKS", "CycleSpec", "Move", "approach_moves", "cycle_moves", "parse_cycle", "peck_depths",
           "reactivated"]

CycleKind = Literal["drill", "deep", "brkchp", "bore"]
MoveKind = Literal["rapid", "feed", "dwell"]
Move = tuple[np.ndarray, MoveKind, float]

MAX_PECKS = 10_000  # a hole needing more pecks than this is refused (bounded output)

_FEED_WORDS = {"MMPM", "IPM", "FPM", "MMPR", "IPR", "FPR", "PERMIN", "PERREV"}  # as FEDRAT reads them
_TYPES: dict[str, CycleKind] = {
    "DRILL": "drill",
    "FACE": "drill",  # Creo: drill with an optional dwell at the bottom
    "CSINK": "drill",  # Creo: countersink, fed to depth like a drill
    "DEEP": "deep",
    "DEEP2": "deep",
    "BRKCHP": "brkchp",
    "BORE": "bore",
    "REAM": "bore",  # feed in, feed out
}
# CYCLE/DRILL,DEEP,...; NX's countersink (MOM_drill_counter_sink) feeds to FEDTO like a drill
_SUBTYPES: dict[str, CycleKind] = {"DEEP": "deep", "BRKCHP": "brkchp", "CSINK": "drill"}
_TAPPING = "tapping needs the feed synchronised with the spindle, which a joint-space program cannot express"
_REJECTED = {
    "TAP": _TAPPING,
    "RIGID": _TAPPING,
    "THRU": "web drilling through several plates (THRU) is not supported",
    "MILL": "milling cycles (MILL) are not supported",
    "ON": "CYCLE/ON and CYCLE/OFF are not cycle definitions",
    "OFF": "CYCLE/ON and CYCLE/OFF are not cycle definitions",
}
_BORE_REJECTED = {
    "DRAG": "boring with the spindle stopped before the retract (DRAG) cannot be expressed as moves",
    "NODRAG": "boring with spindle orientation and shift before the retract (NODRAG) cannot be expressed as moves",
    "BACK": "back boring needs spindle orientation and a shift (BACK)",
    "MANUAL": "boring with a manual retract (MANUAL) cannot be expressed as moves",
}
_WORD_REJECTED = {
    "TAP": _TAPPING,
    "REV": "chip breaking by spindle revolutions (REV) is not supported",
    "TIMES": "chip breaking with a full retract every few pecks (TIMES) is not supported",
}
_SINGLE = ("DEPTH", "FEDTO", "CLEAR", "RAPTO", "RTRCTO", "RETURN", "DWELL", "BACK", "1STPECK", "SUBPECK", "ORIENT")


@dataclass(frozen=True)
class CycleSpec:
    """One drilling cycle, lengths in CL file units along the tool axis from the hole top.

    kind: 'drill' (feed in, rapid out), 'deep' (pecks with full retract), 'brkchp' (pecks with
    a back-off), 'bore' (feed in, feed out). depth >= 0 below the top; approach: rapid-to height
    above the top; retract: height above the top after the hole (>= approach); feed and
    feed_unit: the record's feed and its unit word (None: not given; unit None with a feed:
    ``FEDRAT,f``, file units per minute); pecks: peck increments, the last one repeated;
    chip_break: back-off after each peck of a 'brkchp' cycle (None: the approach); dwell: seconds
    at the bottom (0: none); retract_auto: ``RTRCTO,AUTO`` asked for a return to the level
    before the cycle, which the reader knows and this module does not.
    """

    kind: CycleKind
    depth: float
    approach: float
    retract: float
    feed: float | None = None
    feed_unit: str | None = None
    pecks: tuple[float, ...] = ()
    chip_break: float | None = None
    dwell: float = 0.0
    retract_auto: bool = False
    positional: bool = False  # classic APT order, the depth first (see cycle_records for its two readings)
    clear: float | None = None  # the record's CLEAR value (or the classic form's clearance)
    rapto: float | None = None  # the record's RAPTO value


# One scan, kept whole (about 100 lines): the position in the tokens, what was seen, the feed and
# whether the form is positional are shared by every branch, and a number's meaning depends on what
# came before it (the classic APT order); split into handlers, each would take all of that state.
def parse_cycle(toks: list[float | str], autodesk: bool = False) -> CycleSpec:
    """Read the tokens of one ``CYCLE/`` record (numbers as float, words upper-case str).

    Keywords may come in any order; see the module docstring for the forms and their sources.
    ``autodesk``: the classic positional form is written by Autodesk's posts (``cycle_point``
    "bottom" in :mod:`.dialects`): its clearance is a height along the tool axis, not a distance
    above the hole, so it may be negative (holes below the work zero), and a chip-breaking
    cycle's DWELL is Fusion's "dwelling period", at the final depth before the retract (Autodesk
    Inventor HSM / Fusion help, drilling Parameter Reference).
    Raises ValueError with a one-line reason for unsupported, contradictory or incomplete forms.
    """
    if not toks or not isinstance(toks[0], str):
        raise ValueError("CYCLE needs a cycle type (e.g. CYCLE/DRILL)")
    word = toks[0]
    if word in _REJECTED:
        raise ValueError(f"CYCLE/{word}: {_REJECTED[word]}")
    if word not in _TYPES:
        raise ValueError(f"CYCLE/{word} is not a known cycle")
    kind = _TYPES[word]
    name = word
    i = 1
    if i < len(toks) and isinstance(toks[i], str):
        sub = toks[i]
        if word == "DRILL" and sub in _SUBTYPES:
            kind, name, i = _SUBTYPES[sub], f"DRILL,{sub}", i + 1
        elif word == "DRILL" and sub in _REJECTED:
            raise ValueError(f"CYCLE/DRILL,{sub}: {_REJECTED[sub]}")
        elif word == "BORE" and sub in _BORE_REJECTED:
            raise ValueError(f"CYCLE/BORE,{sub}: {_BORE_REJECTED[sub]}")
    first_arg = i

    seen: dict[str, float] = {}
    steps: list[float] = []
    feed: tuple[float, str | None] | None = None
    retract_auto = False
    positional = False

    def _number(j: int, key: str) -> float:
        if j >= len(toks) or isinstance(toks[j], str):
            raise ValueError(f"CYCLE/{name}: {key} needs a number")
        value = float(toks[j])
        if not math.isfinite(value):
            raise ValueError(f"CYCLE/{name}: {key} must be a finite number")
        return value

    def set_feed(value: float, unit: str | None) -> None:
        nonlocal feed
        if feed is not None and feed != (value, unit):
            raise ValueError(f"CYCLE/{name} gives a second feed (a peck table with changing feeds is not supported)")
        feed = (value, unit)

    while i < len(toks):
        t = toks[i]
        if not isinstance(t, str):
            if i == first_arg:
                seen["DEPTH"] = _number(i, "depth")  # classic APT: the depth comes first
                positional = True
                i += 1
            elif i + 1 < len(toks) and toks[i + 1] in _FEED_WORDS:
                set_feed(_number(i, "feed"), str(toks[i + 1]))  # value before its unit word
                i += 2
            elif feed is not None and "CLEAR" not in seen and "RAPTO" not in seen:
                seen["CLEAR"] = _number(i, "clearance")  # classic APT: the clearance follows the feed
                i += 1
            elif positional and kind in ("deep", "brkchp") and not steps and "CLEAR" in seen:
                steps.append(_number(i, "depth increment"))  # Creo's fixed form: type, z, f, units, r, i
                i += 1
            elif positional and kind == "bore" and "CLEAR" in seen:
                # Autodesk's posts write fine boring (G76) as CYCLE/BORE, d, unit, f, c, shift
                raise ValueError(f"CYCLE/{name}: fine boring with a shift ({float(t):g} after the clearance) "
                                 "needs the spindle oriented and the tool shifted off the wall")
            else:
                raise ValueError(f"CYCLE/{name}: unexpected number {float(t):g}")
        elif t in _FEED_WORDS:
            set_feed(_number(i + 1, t), t)
            i += 2
        elif t == "FEDRAT":
            if i + 1 < len(toks) and toks[i + 1] in _FEED_WORDS:
                set_feed(_number(i + 2, "FEDRAT"), str(toks[i + 1]))
                i += 3
            elif i + 2 < len(toks) and toks[i + 2] in _FEED_WORDS:
                set_feed(_number(i + 1, "FEDRAT"), str(toks[i + 2]))
                i += 3
            else:
                set_feed(_number(i + 1, "FEDRAT"), None)
                i += 2
        elif t in ("STEP", "INCR"):
            steps.append(_number(i + 1, t))
            i += 2
        elif t == "RTRCTO" and i + 1 < len(toks) and toks[i + 1] == "AUTO":
            if retract_auto or "RTRCTO" in seen:
                raise ValueError(f"CYCLE/{name}: RTRCTO given twice")
            retract_auto = True
            i += 2
        elif t in _SINGLE:
            if t in seen or (t == "RTRCTO" and retract_auto):
                raise ValueError(f"CYCLE/{name}: {t} given twice")
            seen[t] = _number(i + 1, t)
            i += 2
        elif t == "MANUAL":  # G99: back to the retract value, as every other form
            i += 1
        elif t in _WORD_REJECTED:
            raise ValueError(f"CYCLE/{name}: {_WORD_REJECTED[t]}")
        else:
            raise ValueError(f"CYCLE/{name}: unknown word '{t}'")
    return replace(_spec(kind, name, seen, steps, feed, retract_auto, positional and autodesk),
                   positional=positional, clear=seen.get("CLEAR"), rapto=seen.get("RAPTO"))


def _spec(
    kind: CycleKind,
    name: str,
    seen: dict[str, float],
    steps: list[float],
    feed: tuple[float, str | None] | None,
    retract_auto: bool,
    autodesk: bool,
) -> CycleSpec:
    if "DEPTH" in seen and "FEDTO" in seen:
        raise ValueError(f"CYCLE/{name} gives both DEPTH and FEDTO")
    if "DEPTH" in seen:
        depth = seen["DEPTH"]
        if depth < 0:
            raise ValueError(f"CYCLE/{name} depth must not be negative, got {depth:g}")
    elif "FEDTO" in seen:
        depth = abs(seen["FEDTO"])  # NX writes it negative (below the point), SolidWorks CAM positive
    else:
        raise ValueError(f"CYCLE/{name} has no depth (give DEPTH,d or FEDTO,d)")
    for key in ("RAPTO", "RTRCTO", "RETURN", "DWELL") + (() if autodesk else ("CLEAR",)):
        if seen.get(key, 0.0) < 0:
            raise ValueError(f"CYCLE/{name} {key} must not be negative, got {seen[key]:g}")
    if "RAPTO" not in seen and "CLEAR" not in seen:
        raise ValueError(f"CYCLE/{name} has no clearance: give CLEAR,c or RAPTO,r")
    approach = seen.get("RAPTO", seen.get("CLEAR", 0.0))
    retract = max(seen.get(key, 0.0) for key in ("CLEAR", "RAPTO", "RTRCTO", "RETURN"))
    if seen.get("RETURN") == 0.0:  # Creo's PULLOUT_DIST: "If programmed at 0, retract to the retract plane"
        retract_auto = True
    if feed is not None and feed[0] <= 0:
        raise ValueError(f"CYCLE/{name} feed must be positive, got {feed[0]:g}")

    if steps and ("1STPECK" in seen or "SUBPECK" in seen):
        raise ValueError(f"CYCLE/{name} gives both STEP/INCR and 1STPECK/SUBPECK")
    pecks = tuple(steps) or tuple(seen[k] for k in ("1STPECK", "SUBPECK") if k in seen)
    if any(p <= 0 for p in pecks):
        raise ValueError(f"CYCLE/{name} peck depths must be positive, got {min(pecks):g}")
    if kind in ("deep", "brkchp") and not pecks:
        # NX's DEEP / BRKCHP without STEP: NX Post Builder's simulated cycles
        # (PB_CMD_sim_cycle_drill_deep_move, _break_chip_move) start at deep_depth = -step1 = 0 and
        # peck while feed_to < deep_depth, stepping by step1: a feed to the point itself (FEDTO,0,
        # NX's countersink) is one feed; any depth below it is never reached without a step.
        if depth > 1e-9 * max(1.0, *(abs(v) for v in seen.values())):
            raise ValueError(f"CYCLE/{name} pecks to {depth:g} below the point but gives no peck depth (STEP, "
                             "INCR or 1STPECK): NX's own cycle pecks by the step and never gets below the point "
                             "without one")
        kind = "drill"  # one feed to the point, as NX's simulated cycle makes it
    if kind not in ("deep", "brkchp") and pecks:
        raise ValueError(f"CYCLE/{name} does not peck but gives peck depths")
    if "BACK" in seen and kind != "brkchp":
        raise ValueError(f"CYCLE/{name}: BACK (chip-break back-off) belongs to BRKCHP only")
    if "BACK" in seen and seen["BACK"] <= 0:
        raise ValueError(f"CYCLE/{name} BACK must be positive, got {seen['BACK']:g}")
    dwell = seen.get("DWELL", 0.0)
    if kind == "brkchp" and dwell > 0 and not autodesk:
        # Creo's BRKCHP DWELL is a dwell at every peck instead of a back-off, NX's a dwell at the bottom.
        raise ValueError(f"CYCLE/{name} with DWELL is ambiguous (a dwell at every peck or at the bottom)")
    if "ORIENT" in seen and kind != "bore":
        raise ValueError(f"CYCLE/{name}: ORIENT (spindle orientation) belongs to boring only")
    # ORIENT on a feed-out bore only says where the spindle would stop; without a shift the path is the same.
    return CycleSpec(
        kind=kind,
        depth=depth,
        approach=approach,
        retract=retract,
        feed=None if feed is None else feed[0],
        feed_unit=None if feed is None else feed[1],
        pecks=pecks,
        chip_break=seen.get("BACK") if kind == "brkchp" else None,  # None: as far as the approach
        dwell=dwell,
        retract_auto=retract_auto,
    )


def reactivated(defined: list[float | str], changes: list[float | str]) -> list[float | str]:
    """The tokens of ``CYCLE/ON,changes`` after the cycle ``defined`` (both without ON): each
    ``keyword,value`` of ``changes`` replaces that keyword's value in ``defined`` or is added."""
    out = list(defined)
    k = 0
    while k < len(changes):
        key = changes[k]
        if key == "MANUAL":  # a flag without a value
            out += [] if key in out else [key]
            k += 1
            continue
        if not isinstance(key, str) or k + 1 >= len(changes):
            raise ValueError(f"CYCLE/ON: expected keyword,value pairs, got {','.join(map(str, changes))[:40]}")
        value = changes[k + 1]
        same = _FEED_WORDS if key in _FEED_WORDS else {key}  # a new feed replaces the old in any unit
        at = [j for j in range(1, len(out) - 1) if out[j] in same]
        if at:
            out[at[0]:at[0] + 2] = [key, value]
        else:
            out += [key, value]
        k += 2
    return out


def approach_moves(start: np.ndarray, target: np.ndarray, axis: np.ndarray) -> list[np.ndarray]:
    """Rapid points from ``start`` to ``target`` (CL file units and frame; ``axis`` the unit tool
    axis): along the axis first if that part goes up, across it first if it goes down (NX's
    SIM_RAPID_APPROACH), each part left out when it is zero."""
    move = target - start
    along = float(move @ axis) * axis
    across = move - along
    tiny = 1e-12 * max(1.0, float(np.abs(start).max()), float(np.abs(target).max()))
    first = across if float(move @ axis) < 0 else along
    points = [start + first] if float(np.abs(first).max()) > tiny and float(np.abs(move - first).max()) > tiny else []
    return [*points, target] if float(np.abs(move).max()) > tiny else points


def peck_depths(depth: float, pecks: tuple[float, ...]) -> list[float]:
    """Depths (>= 0, below the top) the tool feeds to: running sums of ``pecks`` (the last one
    repeated) below ``depth``, then ``depth`` itself. Raises ValueError past MAX_PECKS."""
    if not pecks:
        return [depth]
    if min(pecks) <= 0:
        raise ValueError(f"peck depths must be positive, got {min(pecks):g}")
    head = sum(pecks[:-1])
    if head < depth and (depth - head) / pecks[-1] + len(pecks) > MAX_PECKS:
        raise ValueError(f"a hole {depth:g} deep in pecks of {pecks[-1]:g} needs more than {MAX_PECKS} pecks: "
                         "check the depth and the peck depth")
    eps = 1e-9 * max(1.0, depth)  # a last peck shorter than this merges with the one before
    out: list[float] = []
    reached = 0.0
    for k in range(MAX_PECKS):
        reached += pecks[min(k, len(pecks) - 1)]
        if reached >= depth - eps:
            break
        out.append(reached)
    out.append(depth)
    return out


def cycle_moves(spec: CycleSpec, top: np.ndarray, axis: np.ndarray) -> list[Move]:
    """Moves of one hole: (point (3,), 'rapid' | 'feed' | 'dwell', dwell seconds).

    ``top`` is the hole top (the ``GOTO`` point) and ``axis`` the tool axis (from tip towards
    the spindle, any length), both in CL file units and frame. Points are ``top + h * unit axis``
    with h from ``spec.approach`` down to ``-spec.depth`` and up to ``spec.retract``; moves that
    would not change the position are left out, the first rapid (to the approach height) never.
    """
    a = np.asarray(axis, dtype=float).reshape(-1)
    p0 = np.asarray(top, dtype=float).reshape(-1)
    norm = float(np.linalg.norm(a))
    if a.shape != (3,) or p0.shape != (3,) or not (np.isfinite(norm) and norm > 0 and np.all(np.isfinite(p0))):
        raise ValueError("cycle needs a finite hole top and a non-zero tool axis")
    a = a / norm
    moves: list[Move] = [(p0 + spec.approach * a, "rapid", 0.0)]
    level = spec.approach  # current height above the top

    def go(h: float, kind: MoveKind) -> None:
        nonlocal level
        if h != level:
            moves.append((p0 + h * a, kind, 0.0))
            level = h

    if spec.kind in ("deep", "brkchp"):
        depths = peck_depths(spec.depth, spec.pecks)
        for k, d in enumerate(depths):
            if k:
                prev = depths[k - 1]
                if spec.kind == "deep":
                    if -prev + spec.approach < level:  # rapid back down, only below the approach height
                        go(-prev + spec.approach, "rapid")
                else:
                    back = spec.chip_break if spec.chip_break is not None else spec.approach
                    go(min(-prev + back, spec.approach), "rapid")
            go(-d, "feed")
            if spec.kind == "deep" and k < len(depths) - 1:
                go(spec.approach, "rapid")
    else:
        go(-spec.depth, "feed")
    if spec.dwell > 0:
        moves.append((p0 - spec.depth * a, "dwell", spec.dwell))
    if spec.kind == "bore":
        go(spec.approach, "feed")
    go(spec.retract, "rapid")
    return moves
