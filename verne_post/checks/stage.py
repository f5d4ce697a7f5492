"""The checking stage (stages 3 to 5): IK and branch, linearisation, the moves between cuts and every
check of table-frame poses, without timing.

The pipeline runs it part by part; placement runs it whole for each candidate work offset. Both
call down into this stage, so neither calls the other.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..machine import Machine
from ..motion.branch import BranchState, Pairs, PathIK, solve_path
from ..motion.linearise import Blocks, linearise
from ..motion.poses import MachinePoses
from ..motion.safe_motion import SafeSettings, between_cuts
from ..options import PostOptions
from .collision import check_collisions, tool_stacks
from .limits import Violation, check_program


@dataclass(frozen=True)
class Checked:
    """The program in joint space with everything the machine cannot do (stages 3 to 5)."""

    path: PathIK
    blocks: Blocks
    rapid: np.ndarray  # (M,) per block
    violations: tuple[Violation, ...]
    #: (M,) mm: each block's least clearance between bodies (capped, far is far); None unchecked
    clearance: np.ndarray | None = None


def check_poses(machine: Machine, poses: MachinePoses, options: PostOptions,
                lap: Callable[[str], None] = lambda stage: None, first_failure: bool = False,
                collisions: bool = True) -> Checked:
    """IK and branch, linearisation and every check of table-frame poses (no timing); violations
    sorted by line. Placement calls this for each candidate work offset. With ``first_failure``
    the linearisation stops once a block end fails: the violations then show that the program
    fails, not every way it does (placement's room only asks whether it runs). ``collisions``:
    with the bodies' check (placement's room is the room to the machine's limits)."""
    solved = solve_poses(machine, poses, options)
    lap("ik")
    blocks = linearise_poses(machine, poses, options, solved, until_failure=first_failure)
    lap("linearise")
    between = between_cuts(machine, poses, blocks, safe_settings(machine, poses, options), before=None)
    blocks = between.blocks
    rapid = rapid_blocks(poses, blocks)
    rapid[0] = True  # where the machine stands before the program is unknown: position with G0
    checks, others = program_violations(machine, poses, options, solved.pair_switch, blocks, rapid)
    others += between_violations(poses, between.problems)
    clearance = None
    if collisions and not (first_failure and (checks or others)):
        found = check_collisions(machine, poses, blocks.joints, blocks.pose, rapid, blocks.tip,
                                 first_collision=first_failure, alpha=blocks.result.alpha)
        others += found.violations
        clearance = None if found.clearance is None else found.clearance.smallest
    return Checked(solved, blocks, rapid, tuple(sorted(checks + others, key=lambda v: (v.line, v.kind))), clearance)


def safe_settings(machine: Machine, poses: MachinePoses, options: PostOptions) -> SafeSettings:
    """The moves between cuts' settings: the envelope around the feed points and the setup (the
    stock and fixtures, grown by the widest cutter's radius too, so that the cutter's side clears
    them by ``safe.clearance``; without a setup the feed points are tip positions the cutter
    already clears)."""
    box = poses.setup.bounds()
    radius = 0.0 if box is None else max(float(s.radius[0]) for s in tool_stacks(machine, poses))
    return SafeSettings.of(machine, poses.tip, poses.rapid, rapid_tol=options.rapid_tol,
                           rapid_axis_tol=np.radians(options.rapid_axis_tol), tol=options.tol,
                           axis_tol=np.radians(options.axis_tol), setup_box=box, tool_radius=radius)


def rapid_blocks(poses: MachinePoses, blocks: Blocks) -> np.ndarray:
    """Per block: a move between cuts (a CL rapid's, or one the safe-motion stage made)."""
    return poses.rapid[blocks.pose] | blocks.between


def between_violations(poses: MachinePoses, problems: tuple[tuple[int, str], ...]) -> list[Violation]:
    return [Violation(int(poses.line[pose]), "rapid", reason) for pose, reason in problems]


def solve_poses(machine: Machine, poses: MachinePoses, options: PostOptions, state: BranchState | None = None,
           pairs: Pairs | None = None) -> PathIK:
    return solve_path(machine, poses.tip, poses.axis, poses.sequence, tool_length=poses.tool_length,
                      cone=np.radians(machine.pole.cone), state=state, pairs=pairs)


def linearise_poses(machine: Machine, poses: MachinePoses, options: PostOptions, solved: PathIK,
               until_failure: bool = False) -> Blocks:
    return linearise(machine, poses, solved, tol=options.tol, axis_tol=np.radians(options.axis_tol),
                     cone=np.radians(machine.pole.cone), until_failure=until_failure)


def program_violations(machine: Machine, poses: MachinePoses, options: PostOptions, switch: np.ndarray, blocks: Blocks,
            rapid: np.ndarray, first: int = 0) -> tuple[list[Violation], list[Violation]]:
    """The violations of blocks (poses indexing ``poses``) and of the angle pair switches of poses
    ``first``...: those of the checks (one per line and kind) and the others."""
    checks = check_program(machine, blocks.result, rapid, poses.tool_length[blocks.pose], poses.line[blocks.pose])
    others = [Violation(int(poses.line[k]), "path", f"the move cannot be kept within {options.tol} mm / "
                                                    f"{options.axis_tol} deg of the CL path")
              for k in blocks.unresolved]
    others += [Violation(int(poses.line[first + k]), "branch", "no single tool-axis angle pair reaches this whole "
                                                               "cut: the table would turn half a turn mid-cut")
               for k in np.flatnonzero(switch)]
    return checks, others
