"""Angle-pair (branch) choice and rotary-axis continuity along a toolpath.

Every tool axis has two working-mode solutions, one per angle pair (theta1 ~ -phi1 with
theta2 = -phi2, or theta1 ~ +phi1 with theta2 turned by pi). Switching pair in the middle of
a cut would swing the table by 180 degrees, so one pair is kept along each sequence (a run
of poses the caller says must be continuous, e.g. a feed sequence between rapids).
Angles in radians, tips in mm, table frame.
"""

from __future__ import annotations

import numpy as np

from .api import IKResult, Status, inverse_kinematics_pairs
from .kinematics.full import POLE_EPS
from .machine import Machine


def _usable(result: IKResult) -> np.ndarray:
    return result.status == Status.OK


def _travel(result: IKResult, rows: np.ndarray) -> tuple[float, float]:
    """Rotary travel (rad) along the rows, then mean |theta1| to break ties."""
    joints = result.joints[rows]
    theta2 = np.unwrap(joints[:, 4])
    travel = float(np.sum(np.abs(np.diff(joints[:, 3]))) + np.sum(np.abs(np.diff(theta2))))
    return round(travel, 9), float(np.mean(np.abs(joints[:, 3])))


def choose_pairs(plus: IKResult, minus: IKResult, sequence: np.ndarray) -> np.ndarray:
    """True where pair +1 is used. One pair per sequence where possible.

    Per sequence: of the pairs usable (status ok) at every pose, the one with the least
    rotary travel; if neither is usable throughout, each pose takes the pair it can use,
    poses that could use both keep the pair of the nearest constrained pose before them.
    """
    use_plus = np.ones(len(sequence), bool)
    ok_plus, ok_minus = _usable(plus), _usable(minus)
    starts = np.flatnonzero(np.r_[True, sequence[1:] != sequence[:-1]])
    ends = np.r_[starts[1:], len(sequence)]
    for start, end in zip(starts, ends, strict=False):
        rows = np.arange(start, end)
        all_plus, all_minus = ok_plus[rows].all(), ok_minus[rows].all()
        if all_plus and all_minus:
            use_plus[rows] = _travel(plus, rows) <= _travel(minus, rows)
        elif all_plus or all_minus:
            use_plus[rows] = all_plus
        else:
            forced = ok_plus[rows] != ok_minus[rows]
            choice = np.where(forced, ok_plus[rows], True)
            if forced.any():
                last = np.maximum.accumulate(np.where(forced, np.arange(len(rows)), -1))
                first_forced = np.flatnonzero(forced)[0]
                last[last < 0] = first_forced
                choice = choice[last]
            use_plus[rows] = choice
    return use_plus


def solve_path(machine: Machine, tip: np.ndarray, axis: np.ndarray, sequence: np.ndarray | None = None,
               *, tool_length: float | np.ndarray = 0.0) -> IKResult:
    """Working-mode joints along a path of N poses (tip mm, unit axis, table frame).

    Keeps one angle pair per ``sequence`` id (default: one sequence), holds theta2 across
    poses whose axis is exactly the table normal (theta2 free there), and unwraps theta2 so
    it never jumps by a turn. ``tool_length`` (mm) may vary per pose (tool changes).
    """
    n = len(tip)
    sequence = np.zeros(n, int) if sequence is None else np.asarray(sequence)
    lengths = np.broadcast_to(np.asarray(tool_length, dtype=float), (n,))
    plus, minus = _pairs_by_tool(machine, tip, axis, lengths, np.zeros(n))
    chosen = plus.take(choose_pairs(plus, minus, sequence), minus)
    pole = np.hypot(axis[:, 0], axis[:, 1]) <= POLE_EPS * np.linalg.norm(axis, axis=-1)
    defined = np.flatnonzero(~pole & np.isfinite(chosen.joints[:, 4]))
    theta2 = np.zeros(n)
    if defined.size:
        # Unwrap over the poses where theta2 is defined; hold it across the others.
        theta2[defined] = np.unwrap(chosen.joints[defined, 4])
        source = np.maximum.accumulate(np.where(np.isin(np.arange(n), defined), np.arange(n), -1))
        source[source < 0] = defined[0]
        theta2 = theta2[source]
    if pole.any():
        rows = np.flatnonzero(pole)
        p, m = _pairs_by_tool(machine, tip[rows], axis[rows], lengths[rows], theta2[rows])
        chosen = chosen.scatter(rows, p.take(chosen.pair[rows] > 0, m))
    joints = chosen.joints.copy()
    joints[:, 4] = np.where(np.isfinite(joints[:, 4]), theta2, np.nan)
    return chosen.with_joints(joints)


def _pairs_by_tool(machine: Machine, tip: np.ndarray, axis: np.ndarray, lengths: np.ndarray,
                   theta2_at_pole: np.ndarray) -> tuple[IKResult, IKResult]:
    plus = minus = None
    for length in np.unique(lengths):
        rows = np.flatnonzero(lengths == length)
        p, m = inverse_kinematics_pairs(machine, tip[rows], axis[rows], tool_length=float(length),
                                        theta2_at_pole=theta2_at_pole[rows])
        if plus is None:  # first tool: allocate full-length results, then fill per tool
            plus, minus = (r.rows(np.zeros(len(tip), int)) for r in (p, m))
        plus, minus = plus.scatter(rows, p), minus.scatter(rows, m)
    return plus, minus
