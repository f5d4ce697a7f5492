"""Write the example simultaneous 5-axis job ``examples/impeller_5axis.cls`` (APT/CLSF, mm).

    python examples/generate_job.py                               # ~30,000 GOTO points -> examples/impeller_5axis.cls
    python examples/generate_job.py --points 100000 -o /tmp/big.cls   # larger variant for benchmarks

The part is a 9-blade impeller, OD 220 mm, 90 mm high, with a spherical nose dome on the hub.
Part zero is the centre of the rotary table on the table top (the impeller's back face), +Z
along the table normal, so the job runs with the VERNE's default work offset X0 Y0 Z0.

Operations (in this order):

1. ``RIM_CONTOUR_3AX`` - tool 2, D16 R0.8 end mill, gauge length 60 mm: 3-axis contour of the
   rim at 7 Z levels with ``CIRCLE`` arcs (tangential lead-in/out arcs counter-clockwise seen from
   +Z, the climb-milled rim clockwise). As NX writes them, the circle axis is the one about which
   the motion is clockwise: 0,0,-1 for the lead arcs, 0,0,1 for the rim.
2. ``BLADE_FLANK_5AX`` - tool 4, D8 ball, 100 mm: flank (swarf) milling of both sides of every
   twisted, leaning blade in zig-zag depth levels; the tool axis follows the blade rulings,
   tilt 6..58 degrees from +Z, its azimuth sweeping all around the part.
3. ``NOSE_DOME_5AX`` - tool 3, D10 ball, 80 mm: zig-zag finishing of the dome, tool axis
   = surface normal with a 10 degree lead; the centre pass goes exactly through the rotary
   table's pole (axis 0,0,1), its neighbours pass within a fraction of a degree of it.

Between passes the tool retracts along its axis until the tip is at the safe height Z130, moves
there with ``RAPID``, comes down along the new axis and plunges at a slower feed.

The output is deterministic: no randomness, and every transcendental function is evaluated
with :mod:`math` (numpy's SIMD sin/cos may differ in the last bit between CPUs), so the file
is byte-for-byte reproducible; ``tests/test_examples_generator.py`` checks that.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

DEFAULT_POINTS = 30000
DEFAULT_OUTPUT = Path(__file__).resolve().with_name("impeller_5axis.cls")
PART_NAME = "IMPELLER 5AX DEMO"
WORK_OFFSET = (0.0, 0.0, 0.0)  # where this job needs part zero in the table frame (mm)

SAFE_Z = 130.0  # clearance height for rapids between passes (part top at Z90)
APPROACH = 5.0  # rapid down to this distance above the pass start (along the tool axis), then plunge

# Part geometry (mm).
RIM_RADIUS = 110.0
RIM_LEVELS = (26.0, 22.0, 18.0, 14.0, 10.0, 6.0, 2.0)
DOME_CENTRE_Z = 20.0  # centre of the nose sphere on the table axis
DOME_RADIUS = 70.0  # sphere radius: top of the part at Z90
DOME_EXTENT = 46.0  # dome finishing covers XY radius <= this
DOME_LEAD = math.radians(10.0)
N_BLADES = 9
BLADE_R_LE, BLADE_R_TE = 52.0, 98.0  # leading / trailing edge radius at the hub
BLADE_WRAP = math.radians(40.0)
HUB_SLOPE = 0.65  # hub cone outside the dome: Z drops 0.65 mm per mm of radius

# name, number, diameter, corner radius, gauge length (spindle nose to tip), rpm
TOOLS = {
    "rim": ("EM16R08", 2, 16.0, 0.8, 60.0, 8000.0),
    "blade": ("BALL8", 4, 8.0, 4.0, 100.0, 12000.0),
    "dome": ("BALL10", 3, 10.0, 5.0, 80.0, 14000.0),
}


# ---------------------------------------------------------------- deterministic maths helpers


def _map(function: Callable[[float], float], x: np.ndarray | float) -> np.ndarray:
    """``function`` (from :mod:`math`) applied elementwise: the same bits on every CPU."""
    a = np.asarray(x, dtype=float)
    return np.fromiter(map(function, a.ravel().tolist()), float, a.size).reshape(a.shape)


def _sin(x: np.ndarray | float) -> np.ndarray:
    return _map(math.sin, x)


def _cos(x: np.ndarray | float) -> np.ndarray:
    return _map(math.cos, x)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.sqrt(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] + v[..., 2] * v[..., 2])[..., None]


def _grid(a: float, b: float, step: float, anchor: float | None = None) -> np.ndarray:
    """Values from ``a`` to ``b`` (both included), spaced at most ``step``; ``anchor`` included if given."""
    if anchor is not None and min(a, b) < anchor < max(a, b):
        return np.concatenate([_grid(a, anchor, step), _grid(anchor, b, step)[1:]])
    return np.linspace(a, b, max(2, math.ceil(abs(b - a) / step - 1e-9) + 1))


def hub_z(r: np.ndarray) -> np.ndarray:
    """Hub surface height (mm) at radius ``r``: the nose sphere, then a cone."""
    r = np.asarray(r, dtype=float)
    sphere = DOME_CENTRE_Z + np.sqrt(np.maximum(DOME_RADIUS**2 - r * r, 0.0))
    z_joint = DOME_CENTRE_Z + math.sqrt(DOME_RADIUS**2 - 50.0**2)
    return np.where(r <= 50.0, sphere, z_joint - HUB_SLOPE * (r - 50.0))


# ---------------------------------------------------------------- CL writer


class _ClWriter:
    """Collects CLSF records the way NX writes them (positions 4 decimals, axes 6)."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.feed: float | None = None

    def record(self, text: str) -> None:
        self.lines.append(text)

    def records(self, texts: Iterable[str]) -> None:
        self.lines.extend(texts)

    def fedrat(self, feed: float) -> None:
        if feed != self.feed:
            self.record(f"FEDRAT/MMPM,{feed:.4f}")
            self.feed = feed

    def goto(self, tip: np.ndarray, axis: np.ndarray | None = None) -> None:
        """GOTO records for tips (N, 3) mm, with the tool axes (N, 3) if given (6-value GOTO)."""
        tip = np.atleast_2d(np.asarray(tip, dtype=float))
        p = np.where(np.abs(tip) < 5e-5, 0.0, tip).tolist()  # no "-0.0000"
        if axis is None:
            self.records([f"GOTO/{x:.4f},{y:.4f},{z:.4f}" for x, y, z in p])
        else:
            axis = np.atleast_2d(np.asarray(axis, dtype=float))
            a = np.where(np.abs(axis) < 5e-7, 0.0, axis).tolist()
            self.records([f"GOTO/{x:.4f},{y:.4f},{z:.4f},{i:.6f},{j:.6f},{k:.6f}"
                          for (x, y, z), (i, j, k) in zip(p, a, strict=True)])

    def rapid(self, tip: np.ndarray, axis: np.ndarray | None = None) -> None:
        self.record("RAPID")
        self.goto(tip, axis)
        self.feed = None  # NX writes FEDRAT again after a rapid

    def circle(self, centre: tuple[float, float, float], normal: tuple[float, float, float], radius: float,
               end: tuple[float, float, float], tool: tuple[float, float]) -> None:
        """Arc from the current point to ``end``, counter-clockwise about ``normal``.

        Written as Siemens NX writes CIRCLE records (CLSF Manager documentation: "i,j,k is the
        circle or helix axis vector in the MCS (assuming a clockwise direction)"): the recorded
        axis is the one the motion runs clockwise about, -normal.
        """
        xc, yc, zc = centre
        i, j, k = (0.0 - v for v in normal)
        dia, corner = tool
        self.record(f"CIRCLE/{xc:.4f},{yc:.4f},{zc:.4f},{i:.7f},{j:.7f},{k:.7f},{radius:.4f},0.0100,0.5000,"
                    f"{dia:.4f},{corner:.4f}")
        self.goto(np.array(end))

    def text(self) -> str:
        return "\n".join(self.lines) + "\n"


def _operation_start(cl: _ClWriter, op: str, key: str, coolant: str) -> None:
    name, number, dia, corner, length, rpm = TOOLS[key]
    cl.records([
        f"TOOL PATH/{op},TOOL,{name}",
        f"TLDATA/MILL,{dia:.4f},{corner:.4f},{length:.4f},0.0000,0.0000",
        "MSYS/0.0000,0.0000,0.0000,1.0000000,0.0000000,0.0000000,0.0000000,1.0000000,0.0000000",
        "$$ centerline data",
        "PAINT/PATH",
        f"LOAD/TOOL,{number},ADJUST,{number}",
        f"SPINDL/RPM,{rpm:.4f},CLW",
        f"COOLNT/{coolant}",
    ])
    cl.feed = None


def _operation_end(cl: _ClWriter) -> None:
    cl.records(["COOLNT/OFF", "SPINDL/OFF", "END-OF-PATH"])


def _clearance(tip: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The point on the tool axis line through ``tip`` at the safe height (at least 10 mm out)."""
    return tip + max(10.0, (SAFE_Z - float(tip[2])) / float(axis[2])) * axis


def _approach(cl: _ClWriter, tip: np.ndarray, axis: np.ndarray, plunge: float) -> None:
    """Rapid to the safe height on the tool axis line, rapid down along it, plunge to ``tip``."""
    cl.rapid(_clearance(tip, axis), axis)
    cl.rapid(tip + APPROACH * axis, axis)
    cl.fedrat(plunge)
    cl.goto(tip, axis)


def _retract(cl: _ClWriter, tip: np.ndarray, axis: np.ndarray, feed: float) -> None:
    """Feed 3 mm off the part along the tool axis, then rapid up the axis to the safe height."""
    cl.fedrat(feed)
    cl.goto(tip + 3.0 * axis, axis)
    cl.rapid(_clearance(tip, axis), axis)


# ---------------------------------------------------------------- operations


def _rim_contour(cl: _ClWriter) -> None:
    """3-axis rim contour at several Z levels: lead-in line + arc, 4 quadrant arcs clockwise, lead-out."""
    _operation_start(cl, "RIM_CONTOUR_3AX", "rim", "FLOOD")
    _, _, dia, corner, _, _ = TOOLS["rim"]
    rp = RIM_RADIUS + dia / 2.0  # path radius of the tool centre line
    lead = 10.0  # lead-in / lead-out arc radius
    up = np.array([0.0, 0.0, 1.0])
    first = True
    for z in RIM_LEVELS:
        start = np.array([rp + 2 * lead, lead, z])
        if first:
            cl.rapid(np.array([start[0], start[1], SAFE_Z]), up)
            first = False
        cl.rapid(np.array([start[0], start[1], RIM_LEVELS[0] + APPROACH]))
        cl.fedrat(400.0)
        cl.goto(start)
        cl.fedrat(1500.0)
        cl.goto(np.array([rp + lead, lead, z]))
        cl.circle((rp + lead, 0.0, z), (0.0, 0.0, 1.0), lead, (rp, 0.0, z), (dia, corner))  # lead-in, CCW
        for end in ((0.0, -rp), (-rp, 0.0), (0.0, rp), (rp, 0.0)):  # climb milling: clockwise
            cl.circle((0.0, 0.0, z), (0.0, 0.0, -1.0), rp, (end[0], end[1], z), (dia, corner))
        cl.circle((rp + lead, 0.0, z), (0.0, 0.0, 1.0), lead, (rp + lead, -lead, z), (dia, corner))  # lead-out
        cl.goto(np.array([rp + 2 * lead, -lead, z]))
        cl.rapid(np.array([rp + 2 * lead, -lead, RIM_LEVELS[0] + APPROACH]))
    cl.rapid(np.array([rp + 2 * lead, -lead, SAFE_Z]))
    _operation_end(cl)


def blade_surface(k: int, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Blade ``k`` at camber parameter t (0 = leading edge, 1 = trailing edge).

    Returns the hub point H (n, 3), the unit ruling direction D (n, 3) from hub to shroud, the
    unit blade normal N (n, 3) and the span h (n,) mm. The ruling leans from 6 to 58 degrees
    off +Z along the blade, towards the direction of rotation and increasingly outwards.
    """
    r = BLADE_R_LE + (BLADE_R_TE - BLADE_R_LE) * t
    theta = 2.0 * math.pi * k / N_BLADES + BLADE_WRAP * (1.6 * t - 0.6 * t * t)
    c, s = _cos(theta), _sin(theta)
    hub = np.stack([r * c, r * s, hub_z(r)], axis=-1)
    dr = BLADE_R_TE - BLADE_R_LE
    dtheta = BLADE_WRAP * (1.6 - 1.2 * t)
    tangent = np.stack([dr * c - r * s * dtheta, dr * s + r * c * dtheta, np.full_like(t, -HUB_SLOPE * dr)], axis=-1)
    smooth = t * t * (3.0 - 2.0 * t)
    lean = np.radians(6.0 + 52.0 * smooth)
    gamma = np.radians(-15.0 + 45.0 * t)  # lean direction: from tangential towards radial
    sl, cl_, sg, cg = _sin(lean), _cos(lean), _sin(gamma), _cos(gamma)
    e_theta = np.stack([-s, c, np.zeros_like(t)], axis=-1)
    e_r = np.stack([c, s, np.zeros_like(t)], axis=-1)
    ruling = _unit(cl_[:, None] * np.array([0.0, 0.0, 1.0]) + (sl * cg)[:, None] * e_theta
                   + (sl * sg)[:, None] * e_r)
    normal = _unit(np.cross(tangent, ruling))
    span = 32.0 - 12.0 * t
    return hub, ruling, normal, span


def _blade_flank(cl: _ClWriter, scale: float, budget: int) -> None:
    """Flank milling of both sides of every blade in zig-zag depth levels."""
    _operation_start(cl, "BLADE_FLANK_5AX", "blade", "MIST")
    _, _, dia, _, _, _ = TOOLS["blade"]
    levels = max(2, 2 * round(2.0 * math.sqrt(scale)))
    per_pass = max(8, round(budget / (N_BLADES * 2 * levels)))
    t = np.linspace(0.0, 1.0, per_pass)
    for k in range(N_BLADES):
        hub, ruling, normal, span = blade_surface(k, t)
        thickness = 1.0 + 4.8 * t * (1.0 - t)  # half thickness 1.0 .. 2.2 mm
        for side in (1.0, -1.0):  # pressure side, then suction side
            offset = (side * (thickness + dia / 2.0))[:, None] * normal
            passes = []
            for level in range(levels):
                u = 0.5 + (span - 0.5) * (levels - 1 - level) / levels
                tip = hub + u[:, None] * ruling + offset
                passes.append((tip, ruling) if level % 2 == 0 else (tip[::-1], ruling[::-1]))
            _approach(cl, passes[0][0][0], passes[0][1][0], 300.0)
            for level, (tip, axis) in enumerate(passes):
                if level:
                    cl.fedrat(300.0)  # step down along the tool axis
                    cl.goto(tip[0], axis[0])
                cl.fedrat(800.0 if level == levels - 1 else 1000.0)  # slower at the hub fillet
                cl.goto(tip[1:], axis[1:])
            _retract(cl, passes[-1][0][-1], passes[-1][1][-1], 3000.0)
    _operation_end(cl)


def _dome_stepover(nominal: float) -> float:
    """Stepover (mm) near ``nominal`` whose rows keep out of Y 0.58..0.72 mm.

    A row at Y = y passes the table normal (the VERNE's rotary pole) at about y / 70 rad; just
    outside the machine's pole cone (0.5 deg, Y ~ 0.62 mm) that needs more than the allowed
    theta2 rate (90 deg per mm), so the first rows go either well inside the cone or clearly
    outside it (at most 80 deg/mm). Possible up to 5 rows inside the band (stepover >= 0.12 mm).
    """
    first = math.ceil(0.58 / nominal - 1e-9)
    if first * nominal < 0.72 and first <= 5:
        return 0.72 / first
    return nominal


def _dome_finish(cl: _ClWriter, scale: float) -> None:
    """Zig-zag finishing of the nose dome; axis = normal + lead, through the pole on the centre pass."""
    _operation_start(cl, "NOSE_DOME_5AX", "dome", "ON")
    _, _, _, ball, _, _ = TOOLS["dome"]
    stepover = _dome_stepover(0.5 / math.sqrt(scale))
    spacing = 1.0 / math.sqrt(scale)
    rows = math.floor(math.sqrt(DOME_EXTENT**2 - 2.0**2) / stepover)
    cl_, sl = math.cos(DOME_LEAD), math.sin(DOME_LEAD)
    centre = np.array([0.0, 0.0, DOME_CENTRE_Z])
    previous: tuple[np.ndarray, np.ndarray] | None = None
    for n, j in enumerate(range(-rows, rows + 1)):
        y = j * stepover
        rho = math.sqrt(DOME_RADIUS**2 - y * y)  # section of the sphere in the plane Y = y
        psi_max = math.asin(math.sqrt(DOME_EXTENT**2 - y * y) / rho)
        direction = 1.0 if n % 2 == 0 else -1.0
        pole = -direction * DOME_LEAD if j == 0 else None  # axis exactly 0,0,1 here
        psi = _grid(-direction * psi_max, direction * psi_max, spacing / rho, pole)
        sp, cp = _sin(psi), _cos(psi)
        contact = np.stack([rho * sp, np.full_like(psi, y), DOME_CENTRE_Z + rho * cp], axis=-1)
        normal = (contact - centre) / DOME_RADIUS
        feed_dir = direction * np.stack([cp, np.zeros_like(psi), -sp], axis=-1)
        axis = _unit(cl_ * normal + sl * feed_dir)
        if j == 0:
            axis[np.flatnonzero(psi == pole)] = [0.0, 0.0, 1.0]
        tip = contact + ball * normal - ball * axis
        if previous is None:
            _approach(cl, tip[0], axis[0], 600.0)
        else:  # lift off, step over, plunge: the lead flips with the feed direction
            cl.fedrat(3000.0)
            cl.goto(previous[0] + 2.0 * previous[1], previous[1])
            cl.goto(tip[0] + 2.0 * axis[0], axis[0])
            cl.fedrat(600.0)
            cl.goto(tip[0], axis[0])
        cl.fedrat(2500.0)
        cl.goto(tip[1:], axis[1:])
        previous = (tip[-1], axis[-1])
    assert previous is not None
    _retract(cl, previous[0], previous[1], 3000.0)
    _operation_end(cl)


def generate(points: int = DEFAULT_POINTS) -> str:
    """The CL text of the impeller job with about ``points`` GOTO records (never fewer than ~450)."""
    if points < 1:
        raise ValueError(f"points must be positive, got {points}")
    scale = points / DEFAULT_POINTS
    cl = _ClWriter()
    cl.records([
        "$$ generated by examples/generate_job.py" + ("" if points == DEFAULT_POINTS else f" --points {points}"),
        "$$ IMPELLER 5AX DEMO: 9 blades, OD 220 mm, height 90 mm, nose dome R70; units mm",
        "$$ part zero: rotary table centre on the table top (back face of the part), +Z = table normal",
        "$$ VERNE work offset X{:g} Y{:g} Z{:g} mm (the default machine.work_offset)".format(*WORK_OFFSET),
        "$$ ops: RIM_CONTOUR_3AX T2 L60, BLADE_FLANK_5AX T4 L100, NOSE_DOME_5AX T3 L80",
        f"PARTNO/{PART_NAME}",
        "UNITS/MM",
        "MULTAX/ON",
    ])
    _rim_contour(cl)
    _blade_flank(cl, scale, round(0.5 * points))
    _dome_finish(cl, scale)
    cl.record("FINI")
    return cl.text()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=DEFAULT_POINTS,
                        help=f"approximate number of GOTO points (default {DEFAULT_POINTS})")
    parser.add_argument("-o", "--output", type=Path, default=None,
                        help="output CL file (default: examples/impeller_5axis.cls)")
    args = parser.parse_args(argv)
    if args.points < 1:
        parser.error("--points must be positive")
    start = time.perf_counter()
    text = generate(args.points)
    output = args.output if args.output is not None else DEFAULT_OUTPUT
    output.write_text(text, encoding="ascii", newline="\n")
    gotos = text.count("\nGOTO/")
    print(f"{output}: {gotos} GOTO points, {len(text) / 1e6:.2f} MB in {time.perf_counter() - start:.2f} s",
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
