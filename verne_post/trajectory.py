"""Timed joint trajectory as CSV (``verne-post part.cls -o part.csv``), streamed to disk.

Columns: ``t`` (s); ``rho1,rho2,rho3`` (mm); ``theta1,theta2`` (deg); their velocities ``v_*``
(mm/s, deg/s) and accelerations ``a_*`` (mm/s^2, deg/s^2); ``feed``: tool-tip speed relative
to the part (mm/min, from the Jacobian); ``motion``: ``feed`` or ``rapid``; ``line``: CL source
line of the block being run. Rows at a fixed ``period`` (s), or with period 0 one row per
block end. Memory stays bounded: the samples are made and written a chunk at a time.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from .api import JOINT_NAMES, forward_kinematics
from .atomic import atomic_write
from .errors import InputError
from .feed_planner import FeedPlan
from .kinematics import machine_jacobian
from .machine import Machine
from .numbers import csv_lines
from .schedule import Schedule

CHUNK = 50_000

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


def write_timed_csv(path: str | Path, machine: Machine, schedule: Schedule, tool_length: np.ndarray,
                    lines: np.ndarray, period: float) -> None:
    """Write the timed trajectory (see module docstring) atomically; tool_length and lines per block.

    Raises :class:`InputError` before writing when it would have more than :data:`MAX_ROWS` rows.
    """
    rows = schedule.total / period if period > 0 else 0.0  # with period 0: one row per block
    if not rows <= MAX_ROWS:
        raise InputError(f"the timed CSV would have {rows:.3g} rows (cycle time {schedule.total:.6g} s, period "
                         f"{period:g} s), more than {MAX_ROWS:.0e}: give a longer --period", str(path))
    degrees = np.array([1.0, 1.0, 1.0, 180 / np.pi, 180 / np.pi])
    with atomic_write(path) as handle:
        handle.write(HEADER + "\n")
        for t, q, qd, qdd, block, rapid in samples(schedule, period):
            feed = tip_speed(machine, q, qd, tool_length[block]) * 60.0
            columns = [(t, 6)] + [(q[:, j] * degrees[j], 6) for j in range(5)]
            columns += [(qd[:, j] * degrees[j], 5) for j in range(5)] + [(qdd[:, j] * degrees[j], 4) for j in range(5)]
            columns.append((feed, 3))
            motion = np.full(len(t), "rapid" if rapid else "feed")
            handle.write(csv_lines(columns, [motion, lines[block]]))
