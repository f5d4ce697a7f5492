"""The bodies along a program as read back: every block's joint-space line, as the controller runs
it, placed by the forward kinematics of the joints and tool lengths the text gives (not the post's
inverse kinematics), and checked with the certified distances and sampling bound of
:mod:`verne_post.bodies`. Units: mm, rad; the setup in the table frame.
"""

from __future__ import annotations

import numpy as np

from ..api import placeable
from ..bodies.clearance import MotionTooLongError
from ..bodies.world import ProgramBodies, cutting, least_contacts
from ..machine import Machine
from .gcode_reader import GcodeProgram
from .reference import Finding


def collision_findings(program: GcodeProgram, machine: Machine, bodies: ProgramBodies, lengths: np.ndarray,
                       tip: np.ndarray, work_offset: np.ndarray, alpha: np.ndarray | None = None) -> list[Finding]:
    """A finding at each G-code line where two bodies meet; ``lengths`` (M,) mm the tool length per
    block as read, ``tip`` (M, 3) mm the block ends' tool tips by the forward kinematics (table
    frame; NaN where unknown), the setup placed at ``work_offset`` (mm, table frame). The first
    block is the positioning from where the machine stood, checked at its end. ``alpha`` (M,) rad: the
    platform's tilt at the block ends by the verifier's own forward kinematics (a warm start)."""
    if not machine.bodies.check or not len(program):
        return []
    world, stack = bodies.world(machine.bodies, machine.geom, program.tool, lengths, work_offset)
    radius = max(float(s.radius[0]) for s in world.stacks)
    cut = cutting(world.setup, tip, program.rapid, radius)
    try:
        result = world.clearance(placeable(machine, program.joints), stack, cut, alpha_guess=alpha)
    except MotionTooLongError as long:
        return [Finding(int(program.line[long.block]), "motion", str(long))]
    return [Finding(line, "collision", f"the {a} meets the {b} (clearance 0.000 mm)", value=0.0)
            for line, a, b, clearance in least_contacts(result.contacts, program.line) if clearance <= 0.0]
