"""Timed joint trajectory as CSV (``verne-post part.cls -o part.csv``), streamed to disk.

Columns: ``t`` (s); ``rho1,rho2,rho3`` (mm); ``theta1,theta2`` (deg); their velocities ``v_*``
(mm/s, deg/s) and accelerations ``a_*`` (mm/s^2, deg/s^2); ``feed``: tool-tip speed relative
to the part (mm/min, from the Jacobian); ``motion``: ``feed`` or ``rapid``; ``line``: CL source
line of the block being run. Rows at a fixed ``period`` (s), or with period 0 one row per
block end. Memory stays bounded: the samples are made and written a chunk at a time.

``t`` and the positions carry enough decimals that finite differences at the period reproduce
the plan: rounding each value to d decimals moves a third difference x3 - 3 x2 + 3 x1 - x0 by
at most (1 + 3 + 3 + 1) * 0.5e-d, a jerk estimate by 4e-d / period^3; at 1 ms and 9 decimals
that is 4 units/s^3 (6 decimals gave 4,000 deg/s^3, 12 % of the rotary jerk limit). Velocities
(5 decimals) and accelerations (4) are only ever differenced once: 1e-5 / period and 1e-4 /
period, at most 0.1 and 1 unit at the shortest period, so they keep their fixed decimals.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..api import JOINT_NAMES, forward_kinematics
from ..errors import InputError
from ..kinematics import machine_jacobian
from ..machine import Machine
from ..planning.feed_planner import FeedPlan
from ..planning.schedule import Schedule
from .atomic import atomic_write
from .numbers import csv_lines

CHUNK = 50_000

#: Decimals of ``t`` and the positions at periods of 1 ms and longer (and per block end).
DECIMALS = 9
#: Most decimals: float64 positions of 10^3 mm or degrees carry about 13.
MAX_DECIMALS = 12

#: Most rows written (about 17 GB): beyond, the cycle time and period make no usable file.
MAX_ROWS = 10**8
HEADER = ",".join(["t", *JOINT_NAMES, *(f"v_{n}" for n in JOINT_NAMES), *(f"a_{n}" for n in JOINT_NAMES),
                   "feed", "motion", "line"])


def samples(schedule: Schedule, period: float) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                                  np.ndarray, bool]]:
    """(t, q, qd, qdd, block, rapid) chunks in time order; SI units, rad."""
    for segment in schedule.segments:
        plan = segment.plan
        if period > 0:
            first = np.ceil(segment.start / period - 1e-9)
            last = np.floor((segment.start + plan.total) / period - 1e-9)
            times = np.arange(first, last + 1) * period
        elif isinstance(plan, FeedPlan):
            times = segment.start + plan.block_times[1:]
        else:
            times = np.array([segment.start + plan.total])
        for k in range(0, len(times), CHUNK):
            t = times[k:k + CHUNK]
            local = t - segment.start
            q, qd, qdd = plan.sample(local)
            if isinstance(plan, FeedPlan):
                block = segment.first + plan.block_index(np.maximum(local - 1e-12, 0.0))
            else:
                block = np.full(len(t), segment.first)
            yield t, q, qd, qdd, block, segment.rapid


def tip_speed(machine: Machine, q: np.ndarray, qd: np.ndarray, tool_length: np.ndarray) -> np.ndarray:
    """Tool-tip speed relative to the part (mm/s) for joints q (N, 5) and rates qd (N, 5)."""
    fk = forward_kinematics(machine, q, tool_length=tool_length)
    speed = np.empty(len(q))
    for length in np.unique(tool_length):
        rows = tool_length == length
        jac = machine_jacobian(machine.kinematic_geometry(float(length)), q[rows], fk.platform[rows], fk.alpha[rows])
        speed[rows] = np.linalg.norm(np.einsum("nij,nj->ni", jac[:, :3], qd[rows]), axis=1)
    return speed


def default_decimals(period: float) -> int:
    """Decimals of ``t`` and the positions that keep the rounding of a third difference at
    ``period`` (s) within 4 units/s^3: :data:`DECIMALS`, three more per factor 10 below 1 ms."""
    if period <= 0 or period >= 1e-3:
        return DECIMALS
    return min(MAX_DECIMALS, DECIMALS + math.ceil(3 * math.log10(1e-3 / period) - 1e-9))


def write_timed_csv(path: str | Path, machine: Machine, schedule: Schedule, tool_length: np.ndarray,
                    lines: np.ndarray, period: float, decimals: int | None = None) -> None:
    """Write the timed trajectory (see module docstring) atomically; tool_length and lines per block.

    ``decimals`` of ``t`` and the positions (default :func:`default_decimals` of the period).
    Raises :class:`InputError` when it would have more than :data:`MAX_ROWS` rows (before
    writing) or a value too large for its decimals (nothing is left written).
    """
    decimals = default_decimals(period) if decimals is None else decimals
    rows = schedule.total / period if period > 0 else 0.0  # with period 0: one row per block
    if not rows <= MAX_ROWS:
        raise InputError(f"the timed CSV would have {rows:.3g} rows (cycle time {schedule.total:.6g} s, period "
                         f"{period:g} s), more than {MAX_ROWS:.0e}: give a longer --period", str(path))
    degrees = np.array([1.0, 1.0, 1.0, 180 / np.pi, 180 / np.pi])
    with atomic_write(path) as handle:
        handle.write(HEADER + "\n")
        for t, q, qd, qdd, block, rapid in samples(schedule, period):
            position = q * degrees
            largest = max(float(np.max(np.abs(t))), float(np.max(np.abs(position))))
            if largest >= 2.0**63 / 10.0**decimals:  # the scaled integers of the formatting overflow
                raise InputError(f"a value of {largest:.6g} in the timed CSV does not fit {decimals} decimals: "
                                 f"give fewer --decimals", str(path))
            feed = tip_speed(machine, q, qd, tool_length[block]) * 60.0
            columns = [(t, decimals)] + [(position[:, j], decimals) for j in range(5)]
            columns += [(qd[:, j] * degrees[j], 5) for j in range(5)] + [(qdd[:, j] * degrees[j], 4) for j in range(5)]
            columns.append((feed, 3))
            motion = np.full(len(t), "rapid" if rapid else "feed")
            handle.write(csv_lines(columns, [motion, lines[block]]))
