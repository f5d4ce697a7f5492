"""TEMPORARY stub (plain DRILL only) until the cycles expander lands."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class CycleSpec:
    kind: str
    depth: float
    approach: float
    retract: float
    feed: float | None
    feed_unit: str | None


def parse_cycle(toks):
    kind = toks[0]
    if kind != "DRILL":
        raise ValueError("not supported")
    depth = approach = retract = feed = unit = None
    i = 1
    while i < len(toks):
        t = toks[i]
        if t in ("DEPTH", "FEDTO"):
            depth = abs(toks[i + 1])
            i += 2
        elif t in ("MMPM", "IPM"):
            unit, feed = t, toks[i + 1]
            i += 2
        elif t in ("CLEAR", "RAPTO"):
            approach = toks[i + 1]
            i += 2
        elif t == "RTRCTO":
            retract = toks[i + 1]
            i += 2
        elif isinstance(t, float) and depth is None:
            depth = t
            i += 1
        else:
            i += 1
    return CycleSpec("DRILL", depth, approach, max(approach, retract or 0), feed, unit)


def cycle_moves(spec, top, axis):
    return [(top + spec.approach * axis, "rapid", 0.0), (top - spec.depth * axis, "feed", 0.0),
            (top + spec.retract * axis, "rapid", 0.0)]
