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
from .clearance import ClearanceResult, Contact, Pair, Samples, clear_motion
from .config import BodiesConfig
from .convex import Boxes, Capsules, Cylinders
from .layout import GUIDEWAY_NAMES, LINK_NAMES, Stack, guideways, link_radii, place, to_cradle, tool_stack
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
        """The fixed bodies on the table side: (name, frame, one-row shape); table-frame ones and
        the cradle's boxes in the cradle frame."""
        t = self.bodies.table
        out: list[tuple[str, str, Boxes | Cylinders]] = [
            ("table", "table", Cylinders(np.array([[0.0, 0.0, t.top - t.thickness]]), np.array([[0.0, 0.0, t.top]]),
                                         np.array([0.5 * t.diameter])))]
        out += [(b.name, "cradle", Boxes(np.array([b.lo]), np.array([b.hi]))) for b in self.bodies.cradle]
        out += [(b.name, "table", b.shape(self.offset)) for b in self.setup.bodies]
        return out

    def sampler(self):
        """``place(joints, stack, guess) -> Samples`` for :func:`clear_motion`: every moving body in
        the frames its pairs are checked in."""
        start, end, radius, _ = self._spans()
        lengths = np.array([s.start[-1] for s in self.stacks])  # the spindle starts at the nose
        g, slots = self.geometry, self.slots
        radii = link_radii(self.bodies)

        def sample(joints: np.ndarray, stack: np.ndarray, guess: np.ndarray | None) -> Samples:
            true = g.true_joints(joints)
            module = module_fk_working(g, joints[:, :3], guess)
            placed = place(self.bodies, g, true, module.platform, module.alpha,
                           g.spindle_nose + lengths[stack], start[stack], end[stack])
            bodies: dict[str, np.ndarray] = {}
            rad: dict[str, np.ndarray] = {}
            cradle_head = to_cradle(placed.head.reshape(len(true), -1, 3), placed.theta2).reshape(placed.head.shape)
            for k, name in enumerate(slots):
                bodies[f"{name}@table"], bodies[f"{name}@cradle"] = placed.head[:, k], cradle_head[:, k]
                rad[f"{name}@table"] = rad[f"{name}@cradle"] = radius[stack, k]
            platform_cradle = to_cradle(placed.links_table[:, 4], placed.theta2)
            bodies["platform@table"], bodies["platform@cradle"] = placed.links_table[:, 4], platform_cradle
            rad["platform@table"] = rad["platform@cradle"] = np.full(len(true), radii[4])
            for k, name in enumerate(LINK_NAMES):
                bodies[f"{name}@base"] = placed.links[:, k]
                rad[f"{name}@base"] = np.full(len(true), radii[k])
            return Samples(bodies, rad)

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
                  first_collision: bool = False) -> ClearanceResult:
        """The clearance along block ends ``joints`` (M, 5) readings (mm, rad) with tool stacks
        ``stack`` (M,) and ``cut`` (M,) (a feed block: the cutter may touch the stock); see
        :func:`clear_motion` for ``first_collision``."""
        return clear_motion(joints, self.sampler(), stack, self.pairs(stack, cut), self.bodies.margin,
                            first_collision=first_collision)


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
        keys = np.column_stack([tool.astype(float), np.where(known, length, fill)])
        unique, index = np.unique(keys, axis=0, return_inverse=True)
        stacks = []
        for number, gauge in unique:
            shape = self.tools.get(int(number), ToolShape())
            stacks.append(tool_stack(bodies, float(gauge), shape.diameter, shape.holder, shape.flute_length))
        placed = self.setup.shifted(np.asarray(offset, dtype=float))
        return World(bodies, geometry, tuple(stacks), placed, np.zeros(3)), index.reshape(-1)
