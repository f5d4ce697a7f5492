"""Where every body of the machine is, for N joint sets: pure functions of the kinematics' results.

Frames (VERNE-KINEMATICS.md): the base frame R_b (z down) carries the guideways; the platform
pose is Trans(P) Rot(x, alpha); the table frame R_t is bT_t = Tz(da) Rx(theta1) Tz(dt) Rx(pi)
Rz(theta2), and the cradle frame is that at theta2 = 0 (the cradle tilts, the table turns in it).
The head bodies are cylinders on the spindle axis, measured from the tool tip U = P + Rot(x,
alpha) (0, 0, Delta). Units: mm, radians.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..kinematics.geometry import Geometry
from ..kinematics.jacobian import closure_inverse
from .config import BodiesConfig
from .convex import Capsules


@dataclass(frozen=True)
class Stack:
    """One tool's bodies on the spindle axis: names, and their spans (mm from the tool tip toward
    the spindle) and radii (mm). The first is the cutter."""

    names: tuple[str, ...]
    start: np.ndarray  # (H,) mm from the tip
    end: np.ndarray  # (H,)
    radius: np.ndarray  # (H,)


def tool_stack(bodies: BodiesConfig, length: float, diameter: float | None,
               holder: tuple[tuple[float, float], ...] | None = None, flute_length: float | None = None) -> Stack:
    """The head bodies of a tool of gauge ``length`` (mm, nose to tip) and cutter ``diameter``
    (mm; the machine file's default where None): cutter from the tip, shank up to the holder,
    the holder's cylinders ``(diameter, length)`` from the nose toward the tip (the machine's
    default holder where None), the spindle housing above the nose. A holder longer than the
    tool is cut at the tip's end of its flutes."""
    d = bodies.cutter_diameter if diameter is None or diameter <= 0 else diameter
    pieces = [(h.diameter, h.length) for h in bodies.holder] if holder is None else list(holder)
    flutes = min(flute_length or bodies.flute_length or 3.0 * d, length)
    names, start, end, radius = ["cutter"], [0.0], [flutes], [0.5 * d]
    top = length  # the nose, where the holder's stack starts downward
    lower = length - sum(h for _, h in pieces)
    if lower > flutes:
        names.append("shank")
        start.append(flutes)
        end.append(lower)
        radius.append(0.5 * d)
    for k, (diameter_k, height) in enumerate(pieces):
        bottom = max(top - height, flutes)
        if top > bottom:
            names.append("holder" if len(pieces) == 1 else f"holder {k + 1}")
            start.append(bottom)
            end.append(top)
            radius.append(0.5 * diameter_k)
        top = bottom
    names.append("spindle")
    start.append(length)
    end.append(length + bodies.spindle.length)
    radius.append(0.5 * bodies.spindle.diameter)
    return Stack(tuple(names), np.array(start), np.array(end), np.array(radius))


def table_rotation(theta1: np.ndarray, theta2: np.ndarray) -> np.ndarray:
    """(N, 3, 3): the rotation of bT_t (table frame to base frame), true angles in rad."""
    c1, s1, c2, s2 = np.cos(theta1), np.sin(theta1), np.cos(theta2), np.sin(theta2)
    zero = np.zeros_like(c1)
    # Rx(theta1) Rx(pi) = Rx(theta1 + pi); times Rz(theta2)
    ca, sa = -c1, -s1
    return np.stack([np.stack([c2, -s2, zero], -1),
                     np.stack([ca * s2, ca * c2, -sa], -1),
                     np.stack([sa * s2, sa * c2, ca], -1)], -2)


def table_origin(da: float, dt: float, theta1: np.ndarray) -> np.ndarray:
    """(N, 3) mm, base frame: the table frame's origin, Tz(da) Rx(theta1) (0, 0, dt)."""
    return np.column_stack([np.zeros_like(theta1), -dt * np.sin(theta1), da + dt * np.cos(theta1)])


def to_table(points: np.ndarray, rotation: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Base-frame points (N, K, 3) or (N, 3) (mm) in the table frame of each of the N joint sets."""
    rel = points - (origin[:, None] if points.ndim == 3 else origin)
    return np.einsum("nji,n...j->n...i", rotation, rel)


def to_cradle(points: np.ndarray, theta2: np.ndarray) -> np.ndarray:
    """Table-frame points (N, K, 3) or (N, 3) in the cradle frame (the table frame at theta2 = 0)."""
    c, s = np.cos(theta2), np.sin(theta2)
    if points.ndim == 3:
        c, s = c[:, None], s[:, None]
    x, y = points[..., 0], points[..., 1]
    return np.stack([c * x - s * y, s * x + c * y, points[..., 2]], -1)


@dataclass(frozen=True)
class Placed:
    """The moving bodies of N joint sets. ``parts``: the stack's cylinders' axis end points in the
    table frame, x, y and z apart (3, H, 2, N) (:attr:`head` has them (N, H, 2, 3)); ``links``:
    the rods and the platform as capsules in the base frame (N, 5, 2, 3) (leg I's two rods, legs II
    and III, the platform); the platform also in the table frame, for the table-side checks;
    ``theta2`` the table's true turn."""

    parts: np.ndarray  # (3, H, 2, N) table frame
    links: np.ndarray  # (N, 5, 2, 3) base frame
    platform_table: np.ndarray  # (N, 2, 3) the platform (the last link) in the table frame
    theta2: np.ndarray  # (N,) rad, true

    @cached_property
    def head(self) -> np.ndarray:
        """(N, H, 2, 3) mm, table frame: the stack's cylinders' axis end points (built on demand:
        the collision check takes :attr:`parts`, in the cradle frame and for the levers)."""
        return np.ascontiguousarray(self.parts.transpose(3, 1, 2, 0))


LINK_NAMES = ("leg I rod 1", "leg I rod 2", "leg II", "leg III", "platform")
GUIDEWAY_NAMES = ("guideway I", "guideway II", "guideway III")


def link_radii(bodies: BodiesConfig) -> np.ndarray:
    """(5,) mm: the radii of :data:`LINK_NAMES`."""
    r = bodies.rods
    return np.array([0.5 * r.leg1_diameter, 0.5 * r.leg1_diameter, 0.5 * r.parallelogram_width,
                     0.5 * r.parallelogram_width, 0.5 * bodies.platform.diameter])


def guideways(bodies: BodiesConfig, geometry: Geometry) -> Capsules:
    """The three guideways (base frame, mm) ``outboard`` of their sliders' joints (leg I's: of
    the middle of its two rods), away from the machine's vertical axis."""
    g, p = bodies.guideways, bodies.platform
    d1, d2 = p.D1 - geometry.D1_minus_d1, p.D2 - geometry.D2_minus_d2
    joint = np.array([[d1, 0.0], [d2, -geometry.r4], [d2, geometry.r4]])
    xy = joint + g.outboard * joint / np.linalg.norm(joint, axis=1, keepdims=True)
    return Capsules(np.column_stack([xy, np.full(3, g.top)]), np.column_stack([xy, np.full(3, g.bottom)]),
                    np.full(3, 0.5 * g.diameter))


def place_links(bodies: BodiesConfig, geometry: Geometry, rho: np.ndarray, platform: np.ndarray,
                alpha: np.ndarray) -> np.ndarray:
    """(N, 5, 2, 3) mm, base frame: :data:`LINK_NAMES` as capsules' axis end points at N joint sets:
    ``rho`` (N, 3) true slider positions (mm), ``platform`` (N, 3) P (mm), ``alpha`` (N,) rad.
    A rod's capsule ends at its two joints' centres: its axis stops its radius short of each, so
    its round ends reach the centres and no further (beyond them is the joint's housing, on the
    slider or the platform; a full-length capsule would bulge into the neighbouring leg's joint,
    5.35 mm from leg I's at the default geometry, and meet it within the margin)."""
    g, p = geometry, bodies.platform
    ca, sa = np.cos(alpha), np.sin(alpha)
    px, py, pz = platform[:, 0], platform[:, 1], platform[:, 2]

    def on_platform(x: np.ndarray | float, y: np.ndarray | float) -> tuple[np.ndarray, ...]:
        # P + x e_x + y Rot(x, alpha) e_y, component by component in that order (the same sums
        # as of whole vectors, zero terms included: they keep the signs of zeros)
        return (px + x * 1.0) + y * 0.0, (py + x * 0.0) + y * ca, (pz + x * 0.0) + y * sa

    d1, d2 = p.D1 - g.D1_minus_d1, p.D2 - g.D2_minus_d2
    # the rods' joint centres (rows: the rods), x, y, z apart (4, N) or (4, 1)
    slider_x, slider_y = np.array([[d1], [d1], [d2], [d2]]), np.array([[g.r1], [-g.r1], [-g.r4], [g.r4]])
    slider = (slider_x, slider_y, rho[:, [0, 0, 1, 2]].T)
    top = on_platform(np.array([[p.D1], [p.D1], [p.D2], [p.D2]]), np.array([[g.R1], [-g.R1], [-g.R2], [g.R2]]))
    span = [top[c] - slider[c] for c in range(3)]
    # the norm as np.linalg.norm sums the squares over an axis: left to right
    length = np.sqrt((span[0] * span[0] + span[1] * span[1]) + span[2] * span[2])
    ratio = link_radii(bodies)[:4, None] / length
    out = np.empty((len(rho), 5, 2, 3))
    for c in range(3):
        inset = ratio * span[c]
        out[:, :4, 0, c] = (slider[c] + inset).T
        out[:, :4, 1, c] = (top[c] - inset).T
    half = max(g.R1, g.R2)
    for c, ends in enumerate(on_platform(np.array([[0.5 * (p.D1 + p.D2)]] * 2), np.array([[-half], [half]]))):
        out[:, 4, :, c] = ends.T
    return out


def platform_speeds(geometry: Geometry, rho: np.ndarray, platform: np.ndarray, alpha: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(N,), (N,): the Frobenius norm of dP/drho (mm/mm) and the norm of d alpha/drho (rad/mm), the
    module's Jacobian from its closure equations (:func:`verne_post.kinematics.jacobian.closure_inverse`),
    at slider readings ``rho`` (N, 3) mm with their platform P (N, 3) mm (base frame) and tilt
    ``alpha`` (N,) rad; NaN where unknown. For every slider step d (mm), |dP| <= the first times |d|
    and |d alpha| <= the second times |d|."""
    with np.errstate(invalid="ignore", divide="ignore"):
        jacobian = closure_inverse(geometry, platform, alpha, rho)[1]  # (4, 3, N); NaN rows stay NaN
    speed_p = np.sqrt(np.einsum("ijn,ijn->n", jacobian[:3], jacobian[:3]))
    return speed_p, np.sqrt(np.einsum("jn,jn->n", jacobian[3], jacobian[3]))


def place(bodies: BodiesConfig, geometry: Geometry, joints: np.ndarray, platform: np.ndarray,
          alpha: np.ndarray, delta: np.ndarray, stack_start: np.ndarray, stack_end: np.ndarray,
          links: np.ndarray | None = None) -> Placed:
    """The moving bodies at N joint sets: ``joints`` (N, 5) true joints (mm, rad), ``platform``
    (N, 3) P in the base frame (mm), ``alpha`` (N,) rad, ``delta`` (N,) P to tool tip (mm),
    ``stack_start``/``stack_end`` (N, H) the head bodies' spans from the tip (mm, :class:`Stack`;
    rows of one H); ``links``: :func:`place_links` if already known. ``geometry``: the kinematics'
    record."""
    g = geometry
    links = place_links(bodies, g, joints[:, :3], platform, alpha) if links is None else links
    ez = np.column_stack([np.zeros_like(alpha), -np.sin(alpha), np.cos(alpha)])  # Rot(x, alpha) e_z
    rotation = table_rotation(joints[:, 3], joints[:, 4])
    origin = table_origin(g.da, g.dt, joints[:, 3])
    tip_base = platform + delta[:, None] * ez
    tip = to_table(tip_base, rotation, origin)
    axis = -np.einsum("nji,nj->ni", rotation, ez)  # from the tip toward the spindle
    # tip + span * axis, x, y and z apart: a component at a time, so that every operation runs
    # over rows of N (numpy broadcasts over small leading axes slowly)
    spans = np.stack([stack_start.T, stack_end.T], 1)  # (H, 2, N)
    parts = np.empty((3, *spans.shape))
    for c in range(3):
        np.multiply(spans, axis[:, c], out=parts[c])
        np.add(tip[:, c], parts[c], out=parts[c])
    return Placed(parts, links, to_table(links[:, 4], rotation, origin), joints[:, 4])
