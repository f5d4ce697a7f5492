"""CYCLE records: drilling cycles read by :mod:`.cycles` and expanded at every GOTO until ``CYCLE/OFF``.

``CYCLE/OFF`` ends the cycle, ``CYCLE/ON`` re-activates the last one, ``CYCLE/INIT`` (SolidWorks
CAM's marker before the cycle record) is accepted; a tool change also ends a cycle. Each GOTO
while a cycle is active is the hole's top point; the cycle's moves run along the tool axis and
its dwells become :class:`~verne_post.toolpath.Dwell` events.
"""

from __future__ import annotations

import numpy as np

from . import cycles
from .curves import no_pending_curve
from .lexer import Record
from .machine_functions import dwell_event, feed_from
from .state import ReaderState


def cycle(st: ReaderState, rec: Record) -> None:
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
    if kind == "ON":
        if st.last_cycle is None:
            raise st.fail("CYCLE/ON without a previous CYCLE", rec.line)
        st.cycle = st.last_cycle
        return
    try:
        spec = cycles.parse_cycle(toks)
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


def drill(st: ReaderState, p: list[float], a: tuple[float, float, float], line: int) -> None:
    """One hole: the active cycle's moves from the top point ``p`` (file units) along the axis ``a``."""
    spec, feed = st.cycle
    st.axis = a
    st.take_rapid()
    axis = np.array(a, dtype=float) / np.linalg.norm(a)
    for point, kind, seconds in cycles.cycle_moves(spec, np.array(p, dtype=float), axis):
        if kind == "dwell":
            dwell_event(st, seconds, line)
        else:
            st.add_pose(point, a, line, rapid=kind == "rapid", feed=feed, motion="cycle")


HANDLERS = {"CYCLE": cycle}
