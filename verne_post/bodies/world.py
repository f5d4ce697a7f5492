"""The machine and its setup as one world of bodies, and the clearance of a program's motion in it.

Which pairs are checked (the others are joined by a joint, or cannot meet):
- every head body (cutter, shank, holder, spindle) and the platform against the table, the
  cradle, the stock and the fixtures; the cutter against the stock only in moves between cuts
  (in a cut it is the cut itself);
- the rods and the platform against the guideways of the other legs, and the rods of
  different legs against each other (leg I's two rods: the rod-clearance margin).
Units: mm, rad.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..kinematics import Geometry
from ..kinematics.module import module_fk_working
from .clearance import K_J, ClearanceResult, Contact, Pair, Samples, clear_at, clear_motion
from .config import BodiesConfig
from .convex import Boxes, Capsules, Cylinders
from .layout import (
    GUIDEWAY_NAMES,
    LINK_NAMES,
    Stack,
    guideways,
    link_radii,
    place,
    place_links,
    platform_speeds,
    tool_stack,
)
from .setup import Setup

#: Links that meet each guideway at a joint (their own slider): never checked against it.
_OWN_GUIDEWAY = {0: (0, 1, 4), 1: (2, 4), 2: (3, 4)}
#: Link pairs of different legs.
_LINK_PAIRS = ((0, 2), (0, 3), (1, 2), (1, 3), (2, 3))


@dataclass(frozen=True)
class World:
    """The bodies of one program: the machine's, the tools' stacks (one per tool use) and the setup
    at the work offset ``offset`` (mm, table frame)."""

    bodies: BodiesConfig
    geometry: Geometry
    stacks: tuple[Stack, ...]
    setup: Setup
    offset: np.ndarray

    @property
    def slots(self) -> tuple[str, ...]:
        """The head bodies' names over every stack, in order from the tip."""
        names: list[str] = []
        for stack in self.stacks:
            names += [n for n in stack.names if n not in names]
        return tuple(sorted(names, key=lambda n: (n != "cutter", n == "spindle", n)))

    def _spans(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per stack and slot: start, end, radius (mm) and presence."""
        slots = self.slots
        shape = (len(self.stacks), len(slots))
        start, end, radius, present = np.zeros(shape), np.zeros(shape), np.zeros(shape), np.zeros(shape, bool)
        for i, stack in enumerate(self.stacks):
            for j, name in enumerate(stack.names):
                k = slots.index(name)
                start[i, k], end[i, k], radius[i, k], present[i, k] = stack.start[j], stack.end[j], \
                    stack.radius[j], True
        return start, end, radius, present

    def obstacles(self) -> list[tuple[str, str, Boxes | Cylinders]]:
        """The fixed bodies on the table side: (name, frame, one-row shape); the setup in the table
        frame, the cradle's boxes in the cradle frame, and the table too: it turns about its own
        axis, so it is the same cylinder there, and a program without a setup needs the moving
        bodies in one frame only."""
        t = self.bodies.table
        out: list[tuple[str, str, Boxes | Cylinders]] = [
            ("table", "cradle", Cylinders(np.array([[0.0, 0.0, t.top - t.thickness]]), np.array([[0.0, 0.0, t.top]]),
                                         np.array([0.5 * t.diameter])))]
        out += [(b.name, "cradle", Boxes(np.array([b.lo]), np.array([b.hi]))) for b in self.bodies.cradle]
        out += [(b.name, "table", b.shape(self.offset)) for b in self.setup.bodies]
        return out

    def sampler(self):
        """``place(joints, stack, guess, names=None) -> Samples`` for :func:`clear_motion`: the
        moving bodies ``names`` (None: all) in the frames their pairs are checked in."""
        start, end, radius, _ = self._spans()
        lengths = np.array([s.start[-1] for s in self.stacks])  # the spindle starts at the nose
        g, slots = self.geometry, self.slots
        radii = link_radii(self.bodies)
        # the rods' platform ends' and the platform's ends' distances from its tilt axis (mm)
        rod_levers = (g.R1, g.R1, g.R2, g.R2)
        platform_half = max(g.R1, g.R2)
        table_side = frozenset(f"{name}@{frame}" for name in (*slots, "platform") for frame in ("table", "cradle"))

        def sample(joints: np.ndarray, stack: np.ndarray, guess: np.ndarray | None,
                   names: frozenset[str] | None = None) -> Samples:
            def wanted(key: str) -> bool:
                return names is None or key in names

            true = g.true_joints(joints)
            module = module_fk_working(g, joints[:, :3], guess)
            speed_p, speed_alpha = platform_speeds(g, joints[:, :3], module.platform, module.alpha)
            speed_p, speed_alpha = K_J * speed_p, K_J * speed_alpha
            bodies: dict[str, np.ndarray] = {}
            rad: dict[str, np.ndarray] = {}
            levers: dict[str, np.ndarray] = {}
            zero = np.zeros(len(true))
            links = place_links(self.bodies, g, true[:, :3], module.platform, module.alpha)
            for k, name in enumerate(LINK_NAMES[:4]):
                key = f"{name}@base"
                if not wanted(key):
                    continue
                # a rod: its slider end moves at most the sliders' step, its platform end with the
                # platform (both joints' centres: its body ends within them); its radius turns with
                # its axis, at most the two ends' speeds over the joints' distance
                rod = links[:, k]
                platform_end = speed_p + speed_alpha * rod_levers[k]
                length = np.linalg.norm(rod[:, 1] - rod[:, 0], axis=1) + 2.0 * radii[k]
                bodies[key], rad[key] = rod, np.full(len(true), radii[k])
                levers[key] = np.column_stack([np.maximum(1.0, platform_end) + radii[k] * (1.0 + platform_end) / length,
                                               zero, zero])
            if names is not None and not names & table_side:  # the rods alone: no table side to place
                return Samples(bodies, rad, module.alpha, levers)
            delta = g.spindle_nose + lengths[stack]
            placed = place(self.bodies, g, true, module.platform, module.alpha, delta, start[stack], end[stack], links)
            in_table = [wanted(f"{name}@table") for name in slots]
            in_cradle = [wanted(f"{name}@cradle") for name in slots]
            used = [k for k in range(len(slots)) if in_table[k] or in_cradle[k]]
            # the wanted slots' rows (K, N) side by side: the same operations on the same numbers
            # as one slot at a time, in a few whole-array calls
            r = np.ascontiguousarray(radius[stack][:, used].T)
            span_start, span_end = delta - start[stack][:, used].T, delta - end[stack][:, used].T
            # the slots' axis ends from P along ez = Rot(x, alpha) e_z (y and z: the cradle's axis is x)
            ez_y, ez_z = -np.sin(module.alpha), np.cos(module.alpha)
            p_y, p_z = module.platform[:, 1], module.platform[:, 2]
            from_cradle = np.maximum(np.hypot(p_y + span_start * ez_y, p_z + span_start * ez_z - g.da),
                                     np.hypot(p_y + span_end * ez_y, p_z + span_end * ez_z - g.da)) + r
            every = used == list(range(len(slots)))  # (as a rule) then views, not copies
            x, y, z = placed.parts if every else placed.parts[:, used]  # (K, 2, N) each, table frame
            from_table = np.maximum(np.hypot(x[:, 0], y[:, 0]), np.hypot(x[:, 1], y[:, 1])) + r
            lever = np.empty((len(used), len(true), 3))  # per slot a contiguous (N, 3)
            lever[..., 0] = speed_p + speed_alpha * (np.maximum(np.abs(span_start), np.abs(span_end)) + r)
            lever[..., 1], lever[..., 2] = from_cradle, from_table
            lever_cradle = np.empty_like(lever)  # lever * (1, 1, 0), a column at a time
            lever_cradle[..., 0], lever_cradle[..., 1] = lever[..., 0] * 1.0, from_cradle * 1.0
            lever_cradle[..., 2] = from_table * 0.0
            # the cradle frame (the table's turn undone): the slots wanted there and the platform,
            # cos and sin of theta2 once for all
            cos2, sin2 = np.cos(placed.theta2), np.sin(placed.theta2)
            cradle_slots = [j for j, k in enumerate(used) if in_cradle[k]]
            cradle = np.empty((len(cradle_slots) + 1, len(true), 2, 3))  # per body a contiguous (N, 2, 3)
            # to_cradle's arithmetic, a body's end at a time: every operation over a row of N
            ends = [(x[j, e], y[j, e], z[j, e]) for j in cradle_slots for e in range(2)]
            ends += [(placed.platform_table[:, e, 0], placed.platform_table[:, e, 1], placed.platform_table[:, e, 2])
                     for e in range(2)]
            for i, (end_x, end_y, end_z) in enumerate(ends):
                out = cradle[i // 2, :, i % 2]
                out[:, 0] = cos2 * end_x - sin2 * end_y
                out[:, 1] = sin2 * end_x + cos2 * end_y
                out[:, 2] = end_z
            for j, k in enumerate(used):
                if in_table[k]:
                    key = f"{slots[k]}@table"
                    bodies[key], rad[key], levers[key] = placed.head[:, k], r[j], lever[j]
            for i, j in enumerate(cradle_slots):
                key = f"{slots[used[j]]}@cradle"
                bodies[key], rad[key], levers[key] = cradle[i], r[j], lever_cradle[j]
            r = radii[4]
            platform_lever = np.column_stack([speed_p + speed_alpha * (platform_half + r),
                                              _from_cradle_axis(links[:, 4], g.da) + r,
                                              _from_table_axis(placed.platform_table) + r])
            bodies["platform@table"], bodies["platform@cradle"] = placed.platform_table, cradle[-1]
            rad["platform@table"] = rad["platform@cradle"] = np.full(len(true), r)
            levers["platform@table"], levers["platform@cradle"] = platform_lever, platform_lever * [1.0, 1.0, 0.0]
            return Samples(bodies, rad, module.alpha, levers)

        return sample

    def pairs(self, stack: np.ndarray, cut: np.ndarray) -> list[Pair]:
        """The checked pairs for blocks with tool stacks ``stack`` (M,) and ``cut`` (M,) bool."""
        _, _, _, present = self._spans()
        pairs: list[Pair] = []
        for name, frame, shape in self.obstacles():
            is_stock = any(b.name == name and b.role == "stock" for b in self.setup.bodies)
            for k, slot in enumerate(self.slots):
                active = present[stack, k]
                if slot == "cutter" and is_stock:
                    active = active & ~cut
                pairs.append(Pair(f"{slot}@{frame}", name, Cylinders, shape, active))
            pairs.append(Pair(f"platform@{frame}", name, Capsules, shape))
        ways = guideways(self.bodies, self.geometry)
        for w, way in enumerate(GUIDEWAY_NAMES):
            shape = Capsules(ways.p0[w:w + 1], ways.p1[w:w + 1], ways.radius[w:w + 1])
            for k, link in enumerate(LINK_NAMES):
                if k not in _OWN_GUIDEWAY[w]:
                    pairs.append(Pair(f"{link}@base", way, Capsules, shape))
        for a, b in _LINK_PAIRS:
            pairs.append(Pair(f"{LINK_NAMES[a]}@base", f"{LINK_NAMES[b]}@base", Capsules, None))
        return pairs

    def clearance(self, joints: np.ndarray, stack: np.ndarray, cut: np.ndarray,
                  first_collision: bool = False, alpha_guess: np.ndarray | None = None) -> ClearanceResult:
        """The clearance along block ends ``joints`` (M, 5) readings (mm, rad) with tool stacks
        ``stack`` (M,) and ``cut`` (M,) (a feed block: the cutter may touch the stock); see
        :func:`clear_motion` for ``first_collision`` and ``alpha_guess``."""
        return clear_motion(joints, self.sampler(), stack, self.pairs(stack, cut), self.bodies.margin,
                            first_collision=first_collision, alpha_guess=alpha_guess)

    def clearance_at(self, joints: np.ndarray, stack: np.ndarray, cut: np.ndarray,
                     alpha_guess: np.ndarray | None = None) -> np.ndarray:
        """(N,) mm: the least clearance of the bodies standing still at joint sets ``joints`` (N, 5)
        (mm, rad) with tool stacks ``stack`` (N,) and ``cut`` (N,) (the cutter may touch the stock);
        see :func:`clear_at`."""
        return clear_at(joints, self.sampler(), stack, self.pairs(stack, cut), self.bodies.margin, alpha_guess)


def _from_cradle_axis(ends: np.ndarray, da: float) -> np.ndarray:
    """(N,) mm: the larger distance of two base-frame axis end points (N, 2, 3) from the cradle's
    axis (x through (0, 0, da))."""
    return np.maximum(np.hypot(ends[:, 0, 1], ends[:, 0, 2] - da), np.hypot(ends[:, 1, 1], ends[:, 1, 2] - da))


def _from_table_axis(ends: np.ndarray) -> np.ndarray:
    """(N,) mm: the larger distance of two table-frame axis end points (N, 2, 3) from the table's axis."""
    return np.maximum(np.hypot(ends[:, 0, 0], ends[:, 0, 1]), np.hypot(ends[:, 1, 0], ends[:, 1, 1]))


def plain(name: str) -> str:
    """A body's name without the frame it is checked in."""
    return name.partition("@")[0]


def least_contacts(contacts: tuple[Contact, ...], lines: np.ndarray) -> list[tuple[int, str, str, float]]:
    """Per line and pair of bodies the least clearance (mm), sorted by line: (line, moving body,
    other body, clearance). ``lines`` (M,): the line of each block. A near miss and a collision
    of one pair at one line is a collision, whichever block comes first."""
    least: dict[tuple[int, str, str], float] = {}
    for contact in contacts:
        key = (int(lines[contact.block]), plain(contact.moving), plain(contact.other))
        least[key] = min(least.get(key, np.inf), contact.clearance)
    return [(*key, clearance) for key, clearance in sorted(least.items())]


def cutting(setup: Setup, tip: np.ndarray, rapid: np.ndarray, radius: float) -> np.ndarray:
    """(M,) per block: where the cutter may touch the stock. In a feed it is the cut. A move
    between cuts that starts or ends with the tip (``tip`` (M, 3) mm at the block ends, the
    setup's frame) within the stock's box grown by the cutter's ``radius`` is the CAM's own way
    into or out of its cut: the material there is the CAM's in-process stock, which a box does
    not know. Every other move between cuts (the post's retracts, travels and descents outside
    the envelope, CL rapids between points outside the stock) is checked with the cutter too."""
    stock = setup.stock
    if not stock:
        return ~rapid
    lo = np.min([b.lo for b in stock], axis=0) - radius
    hi = np.max([b.hi for b in stock], axis=0) + radius
    inside = np.all((tip >= lo) & (tip <= hi), axis=1)
    return ~rapid | inside | np.r_[False, inside[:-1]]


@dataclass(frozen=True)
class ToolShape:
    """A tool's shape beyond its length (mm; None: the machine file's default)."""

    diameter: float | None = None
    flute_length: float | None = None
    holder: tuple[tuple[float, float], ...] | None = None  # (diameter, length) from the nose


@dataclass(frozen=True)
class ProgramBodies:
    """What a program's bodies are beyond the machine: the setup (mm, part frame) and the tools'
    shapes by tool number. Plain data: what the post hands its verification, and what
    ``verify`` builds from its options; the verification places the setup at its work offset."""

    setup: Setup
    tools: Mapping[int, ToolShape]

    def world(self, bodies: BodiesConfig, geometry: Geometry, tool: np.ndarray, length: np.ndarray,
              offset: np.ndarray) -> tuple[World, np.ndarray]:
        """The world of a program at work offset ``offset`` (mm, table frame) whose blocks run
        tool numbers ``tool`` (M,) of gauge lengths ``length`` (M,) mm (NaN: unknown, taken as
        the first known), and per block the index of its stack in the world (the world's setup
        in the table frame)."""
        known = np.isfinite(length)
        fill = float(length[known][0]) if known.any() else 0.0
        # (tool, length) pairs as complex numbers: numpy sorts those by real part, then imaginary,
        # as it sorts rows, at a fifteenth of the time of np.unique(rows, axis=0)
        keys = tool.astype(float) + 1j * np.where(known, length, fill)
        unique, index = np.unique(keys, return_inverse=True)
        stacks = []
        for number, gauge in zip(unique.real, unique.imag, strict=True):
            shape = self.tools.get(int(number), ToolShape())
            stacks.append(tool_stack(bodies, float(gauge), shape.diameter, shape.holder, shape.flute_length))
        placed = self.setup.shifted(np.asarray(offset, dtype=float))
        return World(bodies, geometry, tuple(stacks), placed, np.zeros(3)), index.reshape(-1)
