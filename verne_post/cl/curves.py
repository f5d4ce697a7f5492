"""Curve records: CIRCLE (arcs and helices), MOVARC, and NX's NURBS / KNOT / CNTRL splines.

``CIRCLE/xc,yc,zc,i,j,k[,r[,t,f,d,e]][,TIMES,n]`` (file units, CL frame): the next GOTO ends the
arc. The direction about (i,j,k) is the dialect's (see :mod:`.dialects`); six numbers (SolidWorks
CAM) give no radius, which is then the start point's distance from the axis. ``TIMES,n`` (NX
helix): the partial arc from start to end plus n - 1 full turns. ``MOVARC/xc,yc,zc,i,j,k,r,ANGLE,a``
(Autodesk HSM APT): the same with the swept angle a (degrees) given. Arcs are expanded into poses
within the chordal tolerance, never a chord; the tool axis is slerped.

``NURBS/`` then ``KNOT/`` values (continued over several records) and ``CNTRL/x,y,z`` control
points: a spline from the current position, evaluated by :mod:`.spline` to the chordal tolerance.

APT's own arc statement, which Creo writes with ``CIRC_INTERPOLATION APT_FORMAT`` and CATIA by
default (PTC Creo help "CL Output for Circular Interpolation"; CATIA / DELMIA "APT Format: Syntax
of APT Instructions"): ``INDIRV/i,j,k`` then ``TLON,GOFWD/(CIRCLE/xc,yc,zc,r),ON,[n,INTOF,]
(LINE/x1,y1,z1,x2,y2,z2)``. The tool centre runs on the circle (an APT circle is the cylinder of
radius r about the line through the centre parallel to Z; ``CIRCLE/xc,yc,zc,i,j,k,r`` gives its
axis), from the current position, in the direction INDIRV gives, until it is on the line (the
plane through it parallel to the axis), at its n-th crossing (default the first). The direction is
read from INDIRV, so these arcs do not depend on the dialect.
"""

from __future__ import annotations

import math
import re
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
    if spec.sweep_deg is not None:
        direction, sweep = _movarc_sweep(st, spec, p0, p1, r, closed_tol, tol_r)
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
    if spec.sweep_deg is None:  # a MOVARC's direction is its own, not the file's
        st.arcs.append(Arc(start, len(st.rows) - 1, c, n, spec.line))
    st.last_arc = (spec, len(st.rows))


def _movarc_sweep(st: ReaderState, spec: PendingArc, p0: np.ndarray, p1: np.ndarray, r: float, closed_tol: float,
                  tol_r: float) -> tuple[str, float]:
    """(direction, sweep in rad) of a MOVARC: the way round whose sweep from start to end, plus
    whole turns, is its ANGLE. Autodesk's 2011 HSMWorks APT posts wrote the plane normal without
    turning it for clockwise arcs, so the normal alone does not give the direction; the ANGLE (the
    swept angle, positive) does. The file's direction is preferred where both fit (half turns)."""
    target = math.radians(spec.sweep_deg or 0.0)
    tol = max(math.radians(0.05), 2.0 * tol_r / r)
    other = "cw" if st.arc_direction == "ccw" else "ccw"
    for direction in (st.arc_direction, other):
        sweep = arc_sweep(spec.centre, spec.axis, p0, p1, direction, 1, closed_tol)
        sweep += 2 * math.pi * max(0, round((target - sweep) / (2 * math.pi)))
        if abs(sweep - target) <= tol:
            return direction, sweep
    raise st.fail(f"MOVARC ANGLE {spec.sweep_deg:g} does not fit the arc from its start to its end either way round",
                  spec.line)


def continue_arc(st: ReaderState) -> None:
    """Make the coming GOTO point the end of one more piece of the arc that the last GOTO ended,
    when nothing has moved since: Creo lists an arc's points on plain lines after its GOTO."""
    if st.last_arc is not None and st.last_arc[1] == len(st.rows) and st.last_arc[0].word == "CIRCLE":
        spec = st.last_arc[0]
        st.curve = PendingArc(spec.centre, spec.axis, spec.radius, 1, None, spec.line, spec.word)


# ---------------------------------------------------------------------------- APT GOFWD arcs

_GOFWD_RE = re.compile(
    r"\A\s*\(\s*CIRCLE\s*/([^()]*)\)\s*,\s*(ON|TO|PAST|TANTO)\s*,\s*(?:([^,()]*),\s*INTOF\s*,\s*)?"
    r"\(\s*LINE\s*/([^()]*)\)\s*\Z", re.I)


def indirv(st: ReaderState, rec: Record) -> None:
    """INDIRV/i,j,k: the direction the next GOFWD starts in, from the current position."""
    vals = st.numbers(rec.args, "INDIRV", rec.line)
    if len(vals) != 3:
        raise st.fail(f"INDIRV needs 3 numbers, got {len(vals)}", rec.line)
    d = np.array(vals, dtype=float)
    if not 1e-9 < float(np.linalg.norm(d)) < 1e9:
        raise st.fail("INDIRV direction has zero or absurd length", rec.line)
    st.indirv = (d / np.linalg.norm(d), len(st.rows), rec.line)


def gofwd(st: ReaderState, rec: Record) -> None:
    """TLON,GOFWD/(CIRCLE/...),ON,[n,INTOF,](LINE/...): an arc to the check line (module docstring)."""
    no_pending_curve(st, "GOFWD", rec.line)
    if st.cycle is not None:
        raise st.fail("GOFWD inside a drilling CYCLE", rec.line)
    m = _GOFWD_RE.match(rec.args)
    if m is None:
        raise st.fail("GOFWD: only the form (CIRCLE/x,y,z,r),ON,[n,INTOF,](LINE/x1,y1,z1,x2,y2,z2) is supported",
                      rec.line)
    if m.group(2).upper() != "ON":
        raise st.fail(f"GOFWD ... {m.group(2).upper()}: only ON (the tool centre on the check line) is supported; "
                      "TO, PAST and TANTO need the cutter's radius", rec.line)
    circle_nums = st.numbers(m.group(1), "GOFWD CIRCLE", rec.line)
    line_nums = st.numbers(m.group(4), "GOFWD LINE", rec.line)
    if len(circle_nums) not in (4, 7) or len(line_nums) != 6:
        raise st.fail(f"GOFWD needs CIRCLE/x,y,z,r (or x,y,z,i,j,k,r) and LINE/x1,y1,z1,x2,y2,z2, got "
                      f"{len(circle_nums)} and {len(line_nums)} numbers", rec.line)
    crossing = 1
    if m.group(3) is not None:
        count = st.number(m.group(3), "GOFWD INTOF", rec.line)
        if count != int(count) or not 1 <= count <= 10_000:
            raise st.fail(f"GOFWD: the n of n,INTOF must be a whole number from 1 to 10000, got {count:g}", rec.line)
        crossing = int(count)
    st.coordinate(circle_nums[:3] + line_nums, "GOFWD", rec.line)
    c = np.array(circle_nums[:3], dtype=float)
    n = _axis(st, circle_nums, "GOFWD circle", rec.line) if len(circle_nums) == 7 else np.array([0.0, 0.0, 1.0])
    r = _radius(st, circle_nums[-1], "GOFWD circle", rec.line)
    st.carried_axis("GOFWD", rec.line)
    p0, a0 = st.current_pose("GOFWD", rec.line)
    if abs(float(a0 @ n)) < 1.0 - 1e-6:
        raise st.fail("GOFWD along a circle whose axis is not the tool axis is not supported", rec.line)
    if st.indirv is not None and st.indirv[1] == len(st.rows):
        direction = st.indirv[0]
    elif len(st.rows) >= 2:  # APT: without INDIRV the motion goes on the way it was going
        direction = p0 - np.array(st.rows[-2][:3], dtype=float)
    else:
        raise st.fail("GOFWD without INDIRV and without a move before it to give its direction", rec.line)
    st.indirv = None
    if float(np.linalg.norm(direction)) < 1e-12 * max(1.0, float(np.abs(p0).max())):
        raise st.fail("GOFWD without INDIRV, and the move before it has no length to give its direction", rec.line)
    offset = (p0 - c) - float((p0 - c) @ n) * n
    r0 = float(np.linalg.norm(offset))
    if abs(r0 - r) > max(0.01 / st.scale, 1e-3 * r) or r0 <= 1e-9 * max(r, 1.0):
        raise st.fail(f"GOFWD starts {r0:.5g} from the circle's axis, its radius is {r:.5g}", rec.line)
    u = offset / r0
    turn = float(np.cross(u, direction) @ n) / float(np.linalg.norm(direction))
    if abs(turn) < 0.1:
        raise st.fail("INDIRV does not point along the circle at the GOFWD's start (more than 84 degrees off "
                      "its tangent)", rec.line)
    axis = n if turn > 0 else -n  # the arc runs counter-clockwise about this axis
    w = np.cross(axis, u)
    # The check line, in the plane of the arc: the angles phi from u (towards w) where the tool
    # centre r (cos phi, sin phi) is on it.
    a2 = np.array([(np.array(line_nums[k:k + 3]) - c) @ e for k in (0, 3) for e in (u, w)]).reshape(2, 2)
    along = a2[1] - a2[0]
    length = float(np.linalg.norm(along))
    if length < 1e-9 * max(r, 1.0):
        raise st.fail("GOFWD check LINE has two coincident points in the plane of the circle", rec.line)
    normal = np.array([-along[1], along[0]]) / length
    h = float(normal @ a2[0]) / r
    touch = max(1e-3 / st.scale, 1e-5 * r) / r  # a line within 1 um of tangent is the tangent, as printed
    if abs(h) > 1.0 + touch:
        raise st.fail("GOFWD check LINE does not cross the circle", rec.line)
    phi0, half = math.atan2(normal[1], normal[0]), math.acos(max(-1.0, min(1.0, h)))
    if abs(h) > 1.0 - touch:  # its two crossings are one, the tangent point, which rounding alone would split
        half = 0.0 if h > 0 else math.pi
    small = max(1e-4 / st.scale, 1e-9 * r) / r  # the start itself on the line is not its end
    found = sorted(x if x > small else x + 2 * math.pi for x in {(phi0 + s * half) % (2 * math.pi) for s in (1, -1)})
    sweep = found[(crossing - 1) % len(found)] + 2 * math.pi * ((crossing - 1) // len(found))
    height = float((p0 - c) @ n) * n
    p1 = c + height + r * (math.cos(sweep) * u + math.sin(sweep) * w)
    try:
        points, _t = arc_points(c, axis, p0, p1, sweep, "ccw", st.tol)
    except ValueError as error:
        raise st.fail(str(error), rec.line) from None
    rapid = st.take_rapid()
    st.add_poses(points, np.broadcast_to(np.array(st.axis), points.shape), rec.line, rapid, "arc")


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
    st.carried_axis("NURBS", spline.line)
    st.add_poses(points, np.broadcast_to(np.array(st.axis), points.shape), spline.line, st.take_rapid(), "spline")
    st.skip_goto = np.array(points[-1], dtype=float) if len(points) else None


HANDLERS = {
    "CIRCLE": circle, "MOVARC": movarc, "NURBS": nurbs, "KNOT": knot, "CNTRL": cntrl, "INDIRV": indirv,
    "TLON,GOFWD": gofwd,  # any other modified GO statement is refused by the reader
}  # fmt: skip
