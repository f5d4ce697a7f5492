"""Curve records: CIRCLE (arcs and helices), MOVARC, and NX's NURBS / KNOT / CNTRL splines.

``CIRCLE/xc,yc,zc,i,j,k[,r[,t,f,d,e]][,TIMES,n]`` (file units, CL frame): the next GOTO ends the
arc. The direction about (i,j,k) is the dialect's (see :mod:`.dialects`); six numbers (SolidWorks
CAM) give no radius, which is then the start point's distance from the axis. ``TIMES,n`` (NX
helix): the partial arc from start to end plus n - 1 full turns. ``MOVARC/xc,yc,zc,i,j,k,r,ANGLE,a``
(Autodesk HSM APT): the same with the swept angle a (degrees) given. Arcs are expanded into poses
within the chordal tolerance, never a chord; the tool axis is slerped.

``NURBS/`` then ``KNOT/`` values (continued over several records) and ``CNTRL/x,y,z`` control
points: a spline from the current position, evaluated by :mod:`.spline` to the chordal tolerance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .arcs import arc_points, arc_sweep
from .lexer import Record
from .state import MAX_COORD, Arc, ReaderState


@dataclass
class PendingArc:
    centre: np.ndarray
    axis: np.ndarray  # unit
    radius: float | None  # None: the start point's distance
    turns: int
    sweep_deg: float | None  # MOVARC's ANGLE
    line: int
    word: str


@dataclass
class PendingSpline:
    line: int
    knots: list[float] = field(default_factory=list)
    control: list[list[float]] = field(default_factory=list)
    weights: list[float] = field(default_factory=list)


def no_pending_curve(st: ReaderState, what: str, line: int) -> None:
    if isinstance(st.curve, PendingArc):
        raise st.fail(f"{st.curve.word} at line {st.curve.line} must be followed by a GOTO, not {what}", line)


def _arc_record(st: ReaderState, rec: Record, word: str) -> tuple[list[float], list[str | float]]:
    toks = st.tokens(rec.args, word, rec.line)
    nums: list[float] = []
    rest: list[str | float] = []
    for i, t in enumerate(toks):
        if isinstance(t, str):
            rest = toks[i:]
            break
        nums.append(t)
    no_pending_curve(st, f"another {word}", rec.line)
    if st.cycle is not None:
        raise st.fail(f"{word} inside a drilling CYCLE", rec.line)
    st.coordinate(nums[:3], word, rec.line)
    return nums, rest


def _axis(st: ReaderState, nums: list[float], word: str, line: int) -> np.ndarray:
    n = np.array(nums[3:6], dtype=float)
    big = float(np.abs(n).max())
    scaled = n / big if big > 0 else n  # no overflow in the norm for components near 1e308
    nn = float(np.linalg.norm(scaled)) * big
    if not 1e-9 <= nn <= 1e9:
        raise st.fail(f"{word} axis has zero or absurd length ({nn:.3g})", line)
    return scaled / np.linalg.norm(scaled)


def _radius(st: ReaderState, value: float, word: str, line: int) -> float:
    if not 0 < value <= MAX_COORD:
        raise st.fail(f"{word} radius must be positive and at most {MAX_COORD:g}, got {value:g}", line)
    return value


def circle(st: ReaderState, rec: Record) -> None:
    nums, rest = _arc_record(st, rec, "CIRCLE")
    if not 6 <= len(nums) <= 11:
        raise st.fail(f"CIRCLE needs 6 to 11 numbers (centre, axis[, radius, ...]), got {len(nums)}", rec.line)
    turns = 1
    if rest:
        if len(rest) != 2 or rest[0] != "TIMES" or not isinstance(rest[1], float):
            raise st.fail(f"CIRCLE: expected TIMES,n after the numbers, got {','.join(map(str, rest))[:40]}",
                          rec.line)
        if rest[1] != int(rest[1]) or not 1 <= rest[1] <= 10_000:
            raise st.fail(f"CIRCLE TIMES must be a whole number of turns from 1 to 10000, got {rest[1]:g}", rec.line)
        turns = int(rest[1])
    axis = _axis(st, nums, "circle", rec.line)
    radius = _radius(st, nums[6], "circle", rec.line) if len(nums) > 6 else None
    st.current_pose("CIRCLE", rec.line)  # there must be a start point
    st.curve = PendingArc(np.array(nums[:3], dtype=float), axis, radius, turns, None, rec.line, "CIRCLE")


def movarc(st: ReaderState, rec: Record) -> None:
    nums, rest = _arc_record(st, rec, "MOVARC")
    if len(nums) != 7 or len(rest) != 2 or rest[0] != "ANGLE" or not isinstance(rest[1], float):
        raise st.fail("MOVARC needs the form MOVARC/xc,yc,zc,i,j,k,r,ANGLE,a", rec.line)
    if not 0 < abs(rest[1]) <= 360.0 * 10_000:
        raise st.fail(f"MOVARC angle must be non-zero and at most 10000 turns, got {rest[1]:g}", rec.line)
    axis = _axis(st, nums, "MOVARC", rec.line)
    st.current_pose("MOVARC", rec.line)
    radius = _radius(st, nums[6], "MOVARC", rec.line)
    st.curve = PendingArc(np.array(nums[:3], dtype=float), axis, radius, 1, abs(rest[1]), rec.line, "MOVARC")


def end_curve(st: ReaderState, p_end: list[float], a_end: tuple[float, float, float], line: int) -> None:
    """The GOTO after a CIRCLE / MOVARC: expand the arc from the current pose to ``p_end``."""
    spec = st.curve
    assert isinstance(spec, PendingArc)
    st.curve = None
    c, n = spec.centre, spec.axis
    p0, a0 = st.current_pose(spec.word, spec.line)
    p1 = np.array(p_end, dtype=float)
    r0 = float(np.linalg.norm((p0 - c) - ((p0 - c) @ n) * n))
    r1 = float(np.linalg.norm((p1 - c) - ((p1 - c) @ n) * n))
    r = spec.radius if spec.radius is not None else r0
    tol_r = max(0.01 / st.scale, 1e-3 * r)
    unit = " in" if st.scale != 1.0 else " mm"
    if abs(r0 - r) > tol_r:
        raise st.fail(f"arc start point is {r0:.5g}{unit} from the {spec.word} centre, radius is {r:.5g}{unit}",
                      spec.line)
    if abs(r1 - r) > tol_r:
        raise st.fail(f"arc end point is {r1:.5g}{unit} from the {spec.word} centre, radius is {r:.5g}{unit}", line)
    if min(r0, r1) <= 1e-9 * max(r, 1.0):
        raise st.fail("arc start or end point lies on the arc's axis", line)
    direction = st.arc_direction
    closed_tol = max(1e-4 / st.scale, 1e-9 * r)
    sweep = arc_sweep(c, n, p0, p1, direction, spec.turns, closed_tol)
    if spec.sweep_deg is not None:  # MOVARC: whole turns from the given angle
        extra = round((math.radians(spec.sweep_deg) - sweep) / (2 * math.pi))
        sweep += 2 * math.pi * max(0, extra)
    a1 = np.array(a_end, dtype=float)
    a1 /= np.linalg.norm(a1)
    omega = math.acos(max(-1.0, min(1.0, float(a0 @ a1))))
    if math.pi - omega < 1e-6:
        raise st.fail(f"tool axis reverses across the {spec.word} arc", line)
    try:
        points, t = arc_points(c, n, p0, p1, sweep, direction, st.tol)
    except ValueError as error:
        raise st.fail(str(error), spec.line) from None
    if omega < 1e-9:
        axes = np.broadcast_to(a1, points.shape)
    else:
        axes = (np.sin((1 - t) * omega)[:, None] * a0 + np.sin(t * omega)[:, None] * a1) / math.sin(omega)
    rapid = st.take_rapid()
    start = len(st.rows) - 1
    st.add_poses(points[:-1], axes[:-1], line, rapid, "arc")
    st.axis = a_end
    st.add_pose(p_end, a_end, line, rapid, motion="arc")
    st.arcs.append(Arc(start, len(st.rows) - 1, c, n, spec.line))


# ---------------------------------------------------------------------------- NX splines


def nurbs(st: ReaderState, rec: Record) -> None:
    no_pending_curve(st, "NURBS", rec.line)
    if st.cycle is not None:
        raise st.fail("NURBS inside a drilling CYCLE", rec.line)
    st.current_pose("NURBS", rec.line)
    st.curve = PendingSpline(rec.line)


def _spline(st: ReaderState, what: str, line: int) -> PendingSpline:
    if not isinstance(st.curve, PendingSpline):
        raise st.fail(f"{what} outside a NURBS spline", line)
    return st.curve


def knot(st: ReaderState, rec: Record) -> None:
    spline = _spline(st, "KNOT", rec.line)
    spline.knots.extend(st.numbers(rec.args, "KNOT", rec.line))


def cntrl(st: ReaderState, rec: Record) -> None:
    spline = _spline(st, "CNTRL", rec.line)
    vals = st.numbers(rec.args, "CNTRL", rec.line)
    if len(vals) not in (3, 4):
        raise st.fail(f"CNTRL needs 3 numbers (or 4 with a weight), got {len(vals)}", rec.line)
    st.coordinate(vals[:3], "CNTRL", rec.line)
    spline.control.append(vals[:3])
    if len(vals) == 4:
        spline.weights.append(vals[3])


def finish_spline(st: ReaderState) -> None:
    """Expand the spline read so far (called by the reader at the first record after its CNTRLs)."""
    from .spline import nurbs_points

    spline = st.curve
    assert isinstance(spline, PendingSpline)
    st.curve = None
    start, _axis = st.current_pose("NURBS", spline.line)
    if spline.weights and len(spline.weights) != len(spline.control):
        raise st.fail("NURBS: some CNTRL records have a weight and others not", spline.line)
    try:
        points = nurbs_points(start, spline.knots, np.array(spline.control, dtype=float).reshape(-1, 3),
                              np.array(spline.weights) if spline.weights else None, st.tol)
    except ValueError as error:
        raise st.fail(f"NURBS: {error}", spline.line) from None
    st.add_poses(points, np.broadcast_to(np.array(st.axis), points.shape), spline.line, st.take_rapid(), "spline")
    st.skip_goto = np.array(points[-1], dtype=float) if len(points) else None


HANDLERS = {"CIRCLE": circle, "MOVARC": movarc, "NURBS": nurbs, "KNOT": knot, "CNTRL": cntrl}
