"""Stage 3: everything the machine cannot do, named by CL line (before anything is written).

Checked at every block end (CL points and inserted points) and along the motion between them:
feed blocks at their midpoint (joint limits are boxes, so block ends suffice for them; reach,
rod clearance and singularity margins are not), rapids at several points of their
joint-space line. Messages read like ``slider rho2 = 1312.4 mm exceeds max 1300.0 mm``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..api import IKResult, Status, classify, forward_kinematics, joint_bounds, pose_margins
from ..kinematics import Margins
from ..kinematics.rows import norms
from ..machine import Machine

_JOINT_WORDS = ("slider rho1", "slider rho2", "slider rho3", "tilt theta1", "rotary theta2")
RAPID_SAMPLES = np.arange(1, 8) / 8.0


@dataclass(frozen=True)
class Violation:
    """One thing the machine cannot do, at a CL line."""

    line: int
    kind: str  # limit, rod_clearance, unreachable, singular, path, branch
    message: str


def _value(joint: int, value: float) -> str:
    return f"{value:.3f} mm" if joint < 3 else f"{np.degrees(value):.3f} deg"


def pose_violations(machine: Machine, joints: np.ndarray, status: np.ndarray, found: Margins, lines: np.ndarray,
                    where: str = "", limit: int = 10_000) -> list[Violation]:
    """Violations of N poses whose status is not ok, ``limit`` at most (the worst kinds first)."""
    out: list[Violation] = []
    lower, upper = joint_bounds(machine)
    t = machine.singularity
    for k in np.flatnonzero(status != Status.OK)[:limit]:
        line = int(lines[k])
        if status[k] == Status.UNREACHABLE:
            out.append(Violation(line, "unreachable", f"{where}pose is out of the machine's reach"))
            continue
        q = joints[k]
        for j in range(5):
            if q[j] > upper[j]:
                out.append(Violation(line, "limit", f"{where}{_JOINT_WORDS[j]} = {_value(j, q[j])} exceeds max "
                                                      f"{_value(j, upper[j])}"))
            elif q[j] < lower[j]:
                out.append(Violation(line, "limit", f"{where}{_JOINT_WORDS[j]} = {_value(j, q[j])} is below min "
                                                      f"{_value(j, lower[j])}"))
        if found.rod_clearance[k] < t.rod_clearance_min:
            out.append(Violation(line, "rod_clearance", f"{where}leg I rods {found.rod_clearance[k]:.2f} mm apart "
                                                          f"(min {t.rod_clearance_min:.2f} mm: rods would cross)"))
        for name, threshold in (("serial", t.serial_min), ("parallel", t.parallel_min), ("machine", t.machine_min)):
            value = getattr(found, name)[k]
            if value < threshold:
                out.append(Violation(line, "singular", f"{where}too close to a {name} singularity (margin "
                                                         f"{value:.4f}, min {threshold:.4f})"))
    return out


@dataclass(frozen=True)
class MotionSamples:
    """Poses on the joint-space lines between block ends, for the along-motion checks."""

    joints: np.ndarray
    lines: np.ndarray
    status: np.ndarray
    margins: Margins
    block: np.ndarray  # the block each sample lies in


#: Feed blocks are short: their margins at the midpoint never fall measurably below the
#: smaller end value (tests/test_pipeline.py checks this on the examples). Their midpoints are
#: sampled only where an end is within this factor of a threshold; rapids always are.
NEAR_THRESHOLD = 1.5


def _near_threshold(machine: Machine, found: Margins) -> np.ndarray:
    t = machine.singularity
    with np.errstate(invalid="ignore"):
        return ((found.serial < NEAR_THRESHOLD * t.serial_min) | (found.parallel < NEAR_THRESHOLD * t.parallel_min)
                | (found.machine < NEAR_THRESHOLD * t.machine_min)
                | (found.rod_clearance < NEAR_THRESHOLD * t.rod_clearance_min) | np.isnan(found.serial))


def motion_samples(machine: Machine, blocks: IKResult, rapid: np.ndarray, tool_length: np.ndarray,
                   lines: np.ndarray, every_feed_block: bool = False, first: int = 1) -> MotionSamples:
    """Poses on the joint-space line into each block from ``first`` on: rapids at k/8, feed blocks
    at 1/2 (all of them with ``every_feed_block``, else those with an end near a threshold)."""
    joints = blocks.joints
    into = np.arange(max(first, 1), len(joints))
    near = _near_threshold(machine, blocks.margins)
    feed = ~rapid[into] & (tool_length[into] == tool_length[into - 1])
    if not every_feed_block:
        feed &= near[into] | near[into - 1]
    rows, fractions = [], []
    for chosen, grid in ((into[feed], np.array([0.5])), (into[rapid[into]], RAPID_SAMPLES)):
        rows.append(np.repeat(chosen, len(grid)))
        fractions.append(np.tile(grid, len(chosen)))
    row, f = np.concatenate(rows), np.concatenate(fractions)
    q = joints[row - 1] + f[:, None] * (joints[row] - joints[row - 1])
    guess = blocks.alpha[row - 1] + f * (blocks.alpha[row] - blocks.alpha[row - 1])
    fk = forward_kinematics(machine, q, tool_length=tool_length[row], alpha_guess=guess)
    found = pose_margins(machine, q, fk.platform, fk.alpha, fk.reachable, tool_length[row])
    return MotionSamples(q, lines[row], classify(machine, q, fk.reachable, found), found, row)


def check_program(machine: Machine, blocks: IKResult, rapid: np.ndarray, tool_length: np.ndarray, lines: np.ndarray,
                  limit: int = 10_000, context: int = 0) -> list[Violation]:
    """All violations at block ends and along the motion, sorted by line, ``limit`` at most each.

    The first ``context`` blocks were checked before (with the blocks before them): only the
    motion from the last of them is.
    """
    ends = slice(context, None)
    at_ends = pose_violations(machine, blocks.joints[ends], blocks.status[ends], blocks.rows(ends).margins,
                              lines[ends], limit=limit)
    samples = motion_samples(machine, blocks, rapid, tool_length, lines, first=context)
    along = pose_violations(machine, samples.joints, samples.status, samples.margins, samples.lines,
                            where="on the way to this point: ", limit=limit)
    unique: dict[tuple[int, str], Violation] = {}
    for violation in at_ends + along:  # one message per CL line and kind: inserted points repeat it
        unique.setdefault((violation.line, violation.kind), violation)
    return sorted(unique.values(), key=lambda v: (v.line, v.kind))


def theta2_rate_warnings(machine: Machine, joints: np.ndarray, tip: np.ndarray, rapid: np.ndarray,
                         lines: np.ndarray, source: str) -> list[str]:
    """CL moves where the rotary table turns faster per mm of tip travel than the machine file allows
    (the tool axis passing close to the table normal, outside the pole cone); one per line."""
    max_rate = np.radians(machine.pole.max_theta2_rate)
    turn = np.abs(np.diff(joints[:, 4]))
    travel = norms(np.diff(tip, axis=0))
    # A rotation with the tip standing still is a programmed reorientation, not a whip.
    fast = ~rapid[1:] & (travel > 1e-6) & (turn > max_rate * travel) & (turn > 1e-6)
    rate = np.degrees(turn) / np.maximum(travel, 1e-9)
    worst: dict[int, float] = {}
    for k in np.flatnonzero(fast):
        line = int(lines[k + 1])
        worst[line] = max(worst.get(line, 0.0), float(rate[k]))
    return [f"{source}:{line}: rotary theta2 turns at up to {value:.0f} deg per mm of tool travel (max "
            f"{machine.pole.max_theta2_rate:g}): the tool axis passes close to the table normal"
            for line, value in worst.items()]


__all__ = ["MotionSamples", "Violation", "check_program", "motion_samples", "pose_violations",
           "theta2_rate_warnings"]
