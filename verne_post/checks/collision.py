"""The collision check of a program's blocks: every body of the machine and the setup along the
joint-space line of every block (feeds and moves between cuts), :mod:`verne_post.bodies`.

A collision (clearance 0: the bodies meet) is a violation at the CL line of the block; a near
miss (under ``bodies.margin``) a warning. Units: mm, rad.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..api import placeable
from ..bodies.clearance import ClearanceResult, MotionTooLongError
from ..bodies.layout import Stack, tool_stack
from ..bodies.world import ProgramBodies, ToolShape, World, cutting, least_contacts
from ..cl.toolpath import ToolChange
from ..machine import Machine
from ..motion.poses import MachinePoses
from .limits import Violation

#: Contacts reported per program at most (a program wrong everywhere: enough to say so).
MAX_REPORTED = 200


def tool_stacks(machine: Machine, poses: MachinePoses) -> tuple[Stack, ...]:
    """The head bodies of each tool use (``poses.tools``, in load order)."""
    return tuple(tool_stack(machine.bodies, use.length, use.diameter, use.holder, use.flute_length)
                 for use in poses.tools)


def program_bodies(poses: MachinePoses, work_offset: tuple[float, float, float]) -> ProgramBodies:
    """The setup (back in the part frame from ``work_offset``, mm) and the tools' shapes of a
    program, for its verification."""
    return ProgramBodies(poses.setup.shifted(-np.asarray(work_offset, dtype=float)),
                         {use.number: ToolShape(use.diameter, use.flute_length, use.holder)
                          for use in reversed(poses.tools)})  # a tool's first load wins


def tool_shapes(machine: Machine, diameters: dict[int, float | None]) -> dict[int, ToolShape]:
    """The tools' shapes by number: the machine's tool table, with the cutter diameters a CL
    file gives (``diameters`` by tool number, mm) in place of the table's."""
    shapes = {}
    for number in {*machine.tools, *diameters}:
        entry = machine.tools.get(number)
        holder = None if entry is None or entry.holder is None else tuple((h.diameter, h.length)
                                                                          for h in entry.holder)
        diameter = diameters.get(number) or (None if entry is None else entry.diameter)
        shapes[number] = ToolShape(diameter, None if entry is None else entry.flute_length, holder)
    return shapes


def tool_use_of_poses(poses: MachinePoses) -> np.ndarray:
    """(N,) per pose: the index in ``poses.tools`` of the tool it is cut with."""
    starts = [e.index for e in poses.events if isinstance(e, ToolChange)]
    if len(poses.tools) > len(starts):  # motion before the first tool change: the --tool-length tool
        starts = [0, *starts]
    index = np.searchsorted(np.asarray(starts, int), np.arange(len(poses)), side="right") - 1
    return np.clip(index, 0, max(len(poses.tools) - 1, 0))


def world_of(machine: Machine, poses: MachinePoses) -> World:
    """The bodies of the program (the setup as ``poses`` carries it: table frame)."""
    return World(machine.bodies, machine.geom, tool_stacks(machine, poses), poses.setup, np.zeros(3))


@dataclass(frozen=True)
class Collisions:
    """What the check found: violations (collisions), warnings (near misses), and the clearance
    of every block (mm)."""

    violations: list[Violation]
    warnings: list[str]
    clearance: ClearanceResult | None


def check_collisions(machine: Machine, poses: MachinePoses, joints: np.ndarray, pose: np.ndarray,
                     rapid: np.ndarray, tip: np.ndarray, world: World | None = None,
                     first_collision: bool = False, alpha: np.ndarray | None = None) -> Collisions:
    """The collisions along block ends ``joints`` (M, 5) readings (mm, rad) of CL poses ``pose``
    (M,) (indices of ``poses``), ``rapid`` (M,) per block (a move between cuts: the cutter is
    checked against the stock too, see :func:`verne_post.bodies.world.cutting`), ``tip`` (M, 3) the block ends' tool
    tips (mm, table frame). Block k runs from end k - 1 to end k. With ``first_collision`` the
    search stops at the first pair that meets (placement's room asks only whether it runs). ``alpha``
    (M,) rad: the platform's tilt at the block ends, as the inverse kinematics found it (the forward
    kinematics' warm start; it still solves and checks every end)."""
    if not machine.bodies.check or not len(joints):
        return Collisions([], [], None)
    world = world_of(machine, poses) if world is None else world
    stack = tool_use_of_poses(poses)[pose]
    radius = max(float(s.radius[0]) for s in world.stacks)
    try:
        result = world.clearance(placeable(machine, joints), stack, cutting(poses.setup, tip, rapid, radius),
                                 first_collision, alpha)
    except MotionTooLongError as long:
        return Collisions([Violation(int(poses.line[pose[long.block]]), "motion", str(long))], [], None)
    violations: list[Violation] = []
    warnings: list[str] = []
    for line, a, b, clearance in least_contacts(result.contacts, poses.line[pose])[:MAX_REPORTED]:
        if clearance <= 0.0:
            violations.append(Violation(line, "collision", f"the {a} meets the {b} (clearance 0.000 mm)"))
        else:
            warnings.append(f"{poses.source}:{line}: near miss: the {a} passes {clearance:.3f} mm from the "
                            f"{b} (margin {machine.bodies.margin:g} mm)")
    return Collisions(violations, warnings, result)
