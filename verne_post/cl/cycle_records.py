"""CYCLE records: drilling cycles read by :mod:`.cycles` and expanded at every GOTO until ``CYCLE/OFF``.

``CYCLE/OFF`` ends the cycle, ``CYCLE/ON[,keyword,value...]`` re-activates the last one (with those
values changed), ``CYCLE/INIT`` (SolidWorks CAM's marker before the cycle record) is accepted; a
tool change also ends a cycle. Each GOTO while a cycle is active is the hole's top point: the tool
is positioned over it (:func:`.cycles.approach_moves`), then the cycle's moves run along the tool
axis and its dwells become :class:`~verne_post.cl.toolpath.Dwell` events. ``RTRCTO,AUTO`` returns to
the level of the tool's position when the cycle was defined or re-activated (G98).
"""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np

from . import cycles
from .curves import no_pending_curve
from .dialects import DIALECTS
from .lexer import Record
from .machine_functions import dwell_event, feed_from
from .state import ReaderState


def cycle(st: ReaderState, rec: Record) -> None:
    if st.dialect.name == DIALECTS["catia"].name and re.search(r",\s*,", rec.args):
        # CATIA writes a cycle with the syntax of the PP word table its machine uses (Dassault, NC
        # Manufacturing, "PP Tables and PP Word Syntaxes": the table's syntaxes, e.g.
        # CYCLE/TAP,%MFG_TOTAL_DEPTH,%MFG_CLEAR_TIP, are resolved into the APT output), with an empty
        # field for a parameter without a value. The APT file does not carry that table, so which
        # number is the depth, the clearance or the feed cannot be known from it.
        raise st.fail(f"CYCLE/{rec.args.split(',')[0].strip()[:20]}: CATIA's positional cycle (fields and empty fields "
                      "as the PP word table of its machine defines them, which the APT file does not carry): the "
                      "depth, clearance and feed cannot be told apart; output the cycle with a PP table whose syntax "
                      "names them (CYCLE/DRILL,DEPTH,d,CLEAR,c,MMPM,f) or as GOTO moves", rec.line)
    toks = st.tokens(rec.args, "CYCLE", rec.line)
    if not toks or not isinstance(toks[0], str):
        raise st.fail("CYCLE needs a cycle type (e.g. CYCLE/DRILL or CYCLE/OFF)", rec.line)
    kind = toks[0]
    if kind == "OFF":
        st.cycle = None
        return
    if kind == "INIT":
        return
    no_pending_curve(st, "CYCLE", rec.line)
    if st.cycle is None:  # G98's initial level is where the tool is as a cycle begins, kept while it runs
        st.cycle_start = _position(st, rec.line)
    if kind == "ON":
        if st.last_cycle is None:
            raise st.fail("CYCLE/ON without a previous CYCLE", rec.line)
        if len(toks) == 1:
            st.cycle = st.last_cycle
            return
        try:
            toks = cycles.reactivated(st.last_cycle_tokens, toks[1:])
        except ValueError as error:
            raise st.fail(str(error), rec.line) from None
        kind = str(toks[0])
    try:
        spec = cycles.parse_cycle(toks, autodesk=st.dialect.cycle_point == "bottom")
        cycles.peck_depths(spec.depth, spec.pecks)  # a hole of too many pecks refused here, at its record
    except ValueError as error:
        reason = str(error)
        raise st.fail(reason if reason.startswith("CYCLE") else f"CYCLE/{kind[:20]}: {reason}", rec.line) from None
    if spec.feed is not None:
        feed = feed_from(st, spec.feed, spec.feed_unit, "CYCLE", rec.line)
    elif st.feed_val == st.feed_val and not st.inverse:
        feed = st.feed_val
    else:
        raise st.fail(f"CYCLE/{kind[:20]} has no feed and no per-minute FEDRAT is active", rec.line)
    st.cycle = st.last_cycle = (spec, feed)
    st.last_cycle_tokens = toks


def _position(st: ReaderState, line: int) -> np.ndarray | None:
    """The tool tip now (CL frame, file units): the last pose, else a FROM given before any tool load."""
    if len(st.rows):
        return st.current_pose("CYCLE", line)[0]
    if st.home is not None:
        frame, tip, axis = st.home
        return st.to_current(tip, axis, frame)[0]
    return None


def drill(st: ReaderState, p: list[float], a: tuple[float, float, float], line: int) -> None:
    """One hole: the active cycle's moves from the top point ``p`` (file units) along the axis ``a``."""
    spec, feed = st.cycle
    st.take_rapid()
    axis = np.array(a, dtype=float) / np.linalg.norm(a)
    top = np.array(p, dtype=float)
    if spec.retract_auto:
        if st.cycle_start is None:
            raise st.fail("CYCLE with RTRCTO,AUTO (back to the level where the cycle began) but no position "
                          "before it", line)
        level = float((st.cycle_start - top) @ axis)
        if level > spec.retract:
            spec = replace(spec, retract=level)
    if spec.positional and st.dialect.cycle_point == "bottom":
        spec, top = _from_bottom(st, spec, top, axis, line)
    try:
        moves = cycles.cycle_moves(spec, top, axis)
    except ValueError as error:  # the depth as the hole's bottom point makes it
        raise st.fail(f"the hole of CYCLE/{spec.kind.upper()}: {error}", line) from None
    if len(st.rows):
        for point in cycles.approach_moves(st.current_pose("CYCLE", line)[0], moves[0][0], axis)[:-1]:
            st.add_pose(point, a, line, rapid=True, motion="cycle")
    st.axis = a
    for point, kind, seconds in moves:
        if kind == "dwell":
            dwell_event(st, seconds, line)
        else:
            st.add_pose(point, a, line, rapid=kind == "rapid", feed=feed, motion="cycle")


def _from_bottom(st: ReaderState, spec: cycles.CycleSpec, bottom: np.ndarray, axis: np.ndarray, line: int
                 ) -> tuple[cycles.CycleSpec, np.ndarray]:
    """Autodesk's positional cycle (module :mod:`.dialects`, ``cycle_point``): the GOTO is the
    hole bottom, the clearance an absolute height along the axis and RAPTO its distance down to
    the retract plane; as the hole top and heights above it (file units)."""
    top = bottom + spec.depth * axis
    clearance = (spec.clear or 0.0) - float(top @ axis)
    approach = clearance - (spec.rapto or 0.0)
    if approach < 0:
        raise st.fail(f"CYCLE: the retract plane ({approach:g} from the hole top, as {st.dialect.name} writes the "
                      "clearance height and RAPTO) is below the hole top", line)
    return replace(spec, approach=approach, retract=max(clearance, approach)), top


HANDLERS = {"CYCLE": cycle}
