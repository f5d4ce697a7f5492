"""Stage 4: keep the tool on the programmed path between blocks.

The controller interpolates linearly in joint space, which bends the tool tip away from the
straight CL segment and turns the axis off its interpolated direction. Blocks are split at
their Cartesian midpoint (tip linear, axis by spherical interpolation, joints by IK) until
the forward kinematics of the joint interpolation stays within the tolerances, all blocks of
the program at once, level by level. Units: mm, rad; table frame.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..api import IKResult, Status, concatenate, forward_kinematics
from ..kinematics.rows import cross, dots, norms, squares, take_rows
from ..machine import Machine
from .branch import PathIK, solve_with_theta2
from .poses import MachinePoses

#: Fractions of a block where the deviation is measured while splitting. The error of a
#: linear interpolation of a smooth map is close to a parabola, largest near the middle:
#: every block is measured at its middle, and at its quarters too where the middle shows more
#: than ``QUARTERS_FROM`` of the allowed deviation.
MIDDLE, QUARTERS = np.array([0.5]), np.array([0.25, 0.75])
QUARTERS_FROM = 0.3
#: Splitting aims at this share of the tolerance, so that denser checks also pass.
MARGIN = 0.8
MAX_LEVELS = 24
#: Inserted poses at most, per CL pose (and at least in all): a move that keeps splitting at
#: every level (a joint path crossing a fold of the kinematics) would otherwise double the work
#: at each of the levels; past the budget the moves still splitting are reported unresolved.
INSERT_BUDGET_PER_POSE, INSERT_BUDGET_MIN = 64, 100_000


def slerp(a: np.ndarray, b: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Spherical interpolation of unit vectors (N, 3) at fractions u (N,)."""
    cos = np.clip(dots(a, b), -1.0, 1.0)
    omega = np.arccos(cos)
    small = omega < 1e-9
    sin = np.where(small, 1.0, np.sin(omega))
    wa = np.where(small, 1.0 - u, np.sin((1.0 - u) * omega) / sin)
    wb = np.where(small, u, np.sin(u * omega) / sin)
    out = wa[:, None] * a + wb[:, None] * b
    return out / norms(out)[:, None]


def distance_to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance (mm) from points p (N, 3) to segments [a, b]."""
    d = b - a
    length2 = squares(d)
    t = np.clip(dots(p - a, d) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
    return norms(p - a - t[:, None] * d)


def _angle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return 2.0 * np.arcsin(np.clip(norms(u - v) / 2.0, 0.0, 1.0))


def angle_to_arc(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (rad) from unit vectors p to the shorter great-circle arcs from a to b."""
    normal = cross(a, b)
    norm = norms(normal)
    ends = np.minimum(_angle(p, a), _angle(p, b))
    safe = norm > 1e-12
    unit = normal / np.where(safe, norm, 1.0)[:, None]
    along = dots(p, unit)
    out_of_plane = np.arcsin(np.clip(np.abs(along), 0.0, 1.0))
    q = p - along[:, None] * unit
    q = q / np.maximum(norms(q), 1e-300)[:, None]
    inside = np.abs(_angle(a, q) + _angle(q, b) - _angle(a, b)) < 1e-9
    return np.where(safe & inside, out_of_plane, ends)


@dataclass(frozen=True)
class Blocks:
    """The program's block ends after linearisation, in order (M of them)."""

    tip: np.ndarray  # (M, 3) mm, table frame: the point on the CL path this block ends at
    axis: np.ndarray  # (M, 3) axis on the CL path (realised axis in the pole cone)
    pose: np.ndarray  # (M,) index of the CL pose whose move the block belongs to
    fraction: np.ndarray  # (M,) position along the move into that pose, 1 at the CL pose (moves between
    #                       cuts that leave the pose, to a tool change or home: above 1)
    result: IKResult  # per block: joints (mm, rad), status, margins, alpha, ...
    unresolved: np.ndarray  # (K,) CL pose indices whose move could not be brought within tolerance
    between: np.ndarray  # (M,) bool: a block of a move between cuts (verne_post.motion.safe_motion)

    @property
    def joints(self) -> np.ndarray:
        return self.result.joints

    def rows(self, index: np.ndarray | slice) -> Blocks:
        """The blocks ``index`` (in that order)."""
        return Blocks(take_rows(self.tip, index), take_rows(self.axis, index), self.pose[index],
                      self.fraction[index], self.result.rows(index), self.unresolved, self.between[index])

    def then(self, other: Blocks) -> Blocks:
        """These blocks, then those of ``other``."""
        return Blocks(np.concatenate([self.tip, other.tip]), np.concatenate([self.axis, other.axis]),
                      np.concatenate([self.pose, other.pose]), np.concatenate([self.fraction, other.fraction]),
                      concatenate([self.result, other.result]), np.concatenate([self.unresolved, other.unresolved]),
                      np.concatenate([self.between, other.between]))

    def shifted(self, first: int) -> Blocks:
        """The blocks of poses counted from ``first`` (a part of a program), counted from 0."""
        return replace(self, pose=self.pose + first, unresolved=self.unresolved + first)


def deviation(machine: Machine, q0: np.ndarray, q1: np.ndarray, tip0: np.ndarray, tip1: np.ndarray,
              axis0: np.ndarray, axis1: np.ndarray, lengths: np.ndarray, fractions: np.ndarray,
              alpha: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Largest tip distance (mm) and axis angle (rad) from the CL path over the given fractions
    of the joint-space blocks q0 -> q1 (tool lengths mm per block; ``alpha`` the platform
    tilts at both ends, rad, to start the FK iteration)."""
    m = len(q0)
    f = np.repeat(fractions[None, :], m, axis=0).ravel()
    rows = np.repeat(np.arange(m), len(fractions))
    guess = None if alpha is None else alpha[0][rows] + f * (alpha[1][rows] - alpha[0][rows])
    start = take_rows(q0, rows)
    fk = forward_kinematics(machine, start + f[:, None] * (take_rows(q1, rows) - start), tool_length=lengths[rows],
                            alpha_guess=guess)
    tip_error = distance_to_segment(fk.tip, take_rows(tip0, rows), take_rows(tip1, rows))
    axis_error = angle_to_arc(fk.axis, take_rows(axis0, rows), take_rows(axis1, rows))
    tip_error = np.where(fk.reachable, tip_error, np.inf).reshape(m, -1).max(axis=1)
    axis_error = np.where(fk.reachable, axis_error, np.inf).reshape(m, -1).max(axis=1)
    return tip_error, axis_error


def linearise(machine: Machine, poses: MachinePoses, path: PathIK, *, tol: float, axis_tol: float, cone: float,
              until_failure: bool = False) -> Blocks:
    """Insert poses into feed moves until the joint interpolation is within ``tol`` (mm) and
    ``axis_tol`` (rad) of the CL path. Rapids and moves across a tool change are left alone.

    With ``until_failure`` it stops as soon as the program is known to fail: a cut needs both
    angle pairs or a block end (CL pose or inserted) is not ok. Every block end it returns is
    one of the complete linearisation's, so the failing one is among them.
    """
    n = len(poses)
    result = path.result
    tip, axis = [poses.tip], [path.axis]
    seg, frac = [np.arange(n)], [np.ones(n)]
    results = [result]
    reached = result.status != Status.UNREACHABLE
    movable = np.r_[False, ~poses.rapid[1:] & (poses.tool_length[1:] == poses.tool_length[:-1])
                    & reached[1:] & reached[:-1]]
    left, right = np.flatnonzero(movable) - 1, np.flatnonzero(movable)
    unresolved: list[np.ndarray] = []
    size = n
    failing = until_failure and bool(path.pair_switch.any() or np.any(result.status != Status.OK))
    for level in range(MAX_LEVELS + 1):
        if left.size == 0 or failing:
            break
        all_tip, all_axis = np.concatenate(tip), np.concatenate(axis)
        all_joints = np.concatenate([r.joints for r in results])
        all_alpha = np.concatenate([r.alpha for r in results])
        all_seg, all_frac = np.concatenate(seg), np.concatenate(frac)
        k = all_seg[right]
        lengths = poses.tool_length[k]
        ends = tuple(take_rows(a, i) for a in (all_joints, all_tip, all_axis) for i in (left, right))
        tip_error, axis_error = deviation(machine, *ends, lengths, MIDDLE, (all_alpha[left], all_alpha[right]))
        # Quarters only where the middle alone does not already split the block: they could
        # only raise an error that is over the limit anyway.
        near = (((tip_error > QUARTERS_FROM * MARGIN * tol) | (axis_error > QUARTERS_FROM * MARGIN * axis_tol))
                & (tip_error <= MARGIN * tol) & (axis_error <= MARGIN * axis_tol))
        if near.any():
            more = deviation(machine, *(e[near] for e in ends), lengths[near], QUARTERS,
                             (all_alpha[left][near], all_alpha[right][near]))
            tip_error[near] = np.maximum(tip_error[near], more[0])
            axis_error[near] = np.maximum(axis_error[near], more[1])
        split = (tip_error > MARGIN * tol) | (axis_error > MARGIN * axis_tol)
        if level == MAX_LEVELS or size - n + np.count_nonzero(split) > max(INSERT_BUDGET_PER_POSE * n,
                                                                              INSERT_BUDGET_MIN):
            unresolved.append(k[split])
            break
        left, right, k, lengths = left[split], right[split], k[split], lengths[split]
        if left.size == 0:
            break
        u0 = np.where(all_seg[left] == k, all_frac[left], 0.0)
        u = 0.5 * (u0 + all_frac[right])
        start, end = take_rows(poses.tip, k - 1), take_rows(poses.tip, k)
        mid_tip = start + u[:, None] * (end - start)
        mid_axis = slerp(take_rows(path.axis, k - 1), take_rows(path.axis, k), u)
        theta2 = 0.5 * (all_joints[left, 4] + all_joints[right, 4])
        mid, realised = solve_with_theta2(machine, mid_tip, mid_axis, lengths, theta2, cone)
        failing = until_failure and bool(np.any(mid.status != Status.OK))
        bad = mid.status == Status.UNREACHABLE
        unresolved.append(k[bad])
        new = np.arange(size, size + len(u))
        size += len(u)
        tip.append(mid_tip)
        axis.append(realised)
        seg.append(k)
        frac.append(u)
        results.append(mid)
        keep = ~bad
        left, right = np.r_[left[keep], new[keep]], np.r_[new[keep], right[keep]]
    all_seg, all_frac = np.concatenate(seg), np.concatenate(frac)
    order = np.lexsort((all_frac, all_seg))
    merged = concatenate(results).rows(order)
    return Blocks(take_rows(np.concatenate(tip), order), take_rows(np.concatenate(axis), order), all_seg[order],
                  all_frac[order], merged,
                  np.unique(np.concatenate(unresolved)) if unresolved else np.empty(0, int), np.zeros(len(order), bool))
