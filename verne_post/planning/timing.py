"""Joint limits, time bounds and baselines of feed sequences, and rapids (ruckig).

Units: joints (N, 5) are rho1..3 in mm and theta1, theta2 in rad; tool tips in mm relative to
the part; times in s; limits per second (mm/s, rad/s, mm/s^2, ...). Nothing here reads files.

Feed sequences are planned by :mod:`verne_post.planning.feed_planner`; here are the limits, the bounds
and baselines that plans are compared with, and the rapids.

Rapids
------
ruckig, offline, time-optimal, jerk-limited, phase-synchronised (a straight line in joint space),
rest to rest.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from ruckig import InputParameter, Result, Ruckig, Synchronization, Trajectory

from ..errors import CheckError

__all__ = ["DoubleS", "Limits", "PlanningError", "RapidPlan", "baseline_time", "block_min_time", "lower_bound_time",
           "plan_rapid", "rest_to_rest"]

DOF = 5
TIP_EPS = 1e-4
"""mm: a block whose tool tip moves less than this is rotary-only (limited by ``angular_feed``)."""


class PlanningError(CheckError):
    """A feed sequence or rapid cannot be planned within the limits (or the planner failed).

    ``index`` is the waypoint index (of the sequence given) the failure is at, where known.
    """

    def __init__(self, reason: str, index: int | None = None) -> None:
        self.index = index
        super().__init__(reason)


@dataclass(frozen=True, eq=False)
class Limits:
    """Per-joint limits (rho1, rho2, rho3 in mm; theta1, theta2 in rad), all per second."""

    velocity: np.ndarray  # (5,) mm/s, rad/s
    acceleration: np.ndarray  # (5,) mm/s^2, rad/s^2
    jerk: np.ndarray  # (5,) mm/s^3, rad/s^3

    def __post_init__(self) -> None:
        for name in ("velocity", "acceleration", "jerk"):
            value = np.asarray(getattr(self, name), dtype=float).reshape(-1)
            if value.shape != (DOF,) or not np.all(np.isfinite(value)) or np.any(value <= 0):
                raise ValueError(f"Limits.{name} must be 5 finite positive values, got {value}")
            object.__setattr__(self, name, value)

    @classmethod
    def from_machine(cls, machine: Any) -> Limits:
        """The joint limits of a :class:`verne_post.Machine` (degrees converted to radians)."""
        names = ("rho1", "rho2", "rho3", "theta1", "theta2")
        scale = np.array([1.0, 1.0, 1.0, math.pi / 180.0, math.pi / 180.0])
        joints = [getattr(machine.joints, n) for n in names]
        return cls(np.array([j.velocity for j in joints]) * scale, np.array([j.acceleration for j in joints]) * scale,
                   np.array([j.jerk for j in joints]) * scale)

    def scaled(self, velocity: float = 1.0, acceleration: float = 1.0, jerk: float = 1.0) -> Limits:
        """These limits times the given factors."""
        return Limits(self.velocity * velocity, self.acceleration * acceleration, self.jerk * jerk)


def _check_limits(limits: Limits) -> Limits:
    if not isinstance(limits, Limits):
        raise TypeError("limits must be a verne_post.planning.timing.Limits")
    return limits


def checked_sequence(joints: np.ndarray, tip: np.ndarray, feed: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A feed sequence as float arrays, checked: joints (K + 1, 5) mm/rad, tip (K + 1, 3) mm,
    feed (K,) mm/s, finite, feeds positive; else ValueError naming the first bad index."""
    joints = np.asarray(joints, dtype=float)
    tip = np.asarray(tip, dtype=float)
    feed = np.asarray(feed, dtype=float).reshape(-1)
    if joints.ndim != 2 or joints.shape[1] != DOF or len(joints) < 2:
        raise ValueError(f"joints must be (K + 1, 5) with K >= 1, got {joints.shape}")
    if tip.shape != (len(joints), 3):
        raise ValueError(f"tip must be ({len(joints)}, 3), got {tip.shape}")
    if feed.shape != (len(joints) - 1,):
        raise ValueError(f"feed must be ({len(joints) - 1},) (one per block), got {feed.shape}")
    for name, value in (("joints", joints), ("tip", tip), ("feed", feed)):
        bad = np.flatnonzero(~np.all(np.isfinite(value.reshape(len(value), -1)), axis=1))
        if len(bad):
            raise ValueError(f"{name} is not finite at index {bad[0]}")
    bad = np.flatnonzero(feed <= 0)
    if len(bad):
        raise ValueError(f"feed must be positive (mm/s), block {bad[0]} has {feed[bad[0]]}")
    return joints, tip, feed


@dataclass(frozen=True, eq=False)
class _Blocks:
    """Per-block geometry of a sequence (K blocks)."""

    dq: np.ndarray  # (K, 5) joint displacement
    length: np.ndarray  # (K,) tip chord, mm
    rotary_only: np.ndarray  # (K,) bool
    rotary: np.ndarray  # (K,) |(d theta1, d theta2)|, rad


def _blocks(joints: np.ndarray, tip: np.ndarray) -> _Blocks:
    return _moves(np.diff(joints, axis=0), np.diff(tip, axis=0))


def _moves(dq: np.ndarray, dtip: np.ndarray) -> _Blocks:
    length = np.linalg.norm(dtip, axis=1)
    return _Blocks(dq, length, length < TIP_EPS, np.linalg.norm(dq[:, 3:], axis=1))


def _block_min_time(blocks: _Blocks, feed: np.ndarray, limits: Limits, angular_feed: float | None) -> np.ndarray:
    """Per-block time at the highest speed allowed along the block's chord (s), no acceleration."""
    t_joint = np.max(np.abs(blocks.dq) / limits.velocity, axis=1)
    t_feed = np.where(blocks.rotary_only, 0.0, blocks.length / feed)
    if angular_feed is not None:
        t_feed = np.where(blocks.rotary_only, blocks.rotary / angular_feed, t_feed)
    return np.maximum(t_joint, t_feed)


def block_min_time(dq: np.ndarray, dtip: np.ndarray, feed: np.ndarray, limits: Limits, *,
                   angular_feed: float | None = None) -> np.ndarray:
    """Per block, the time (s) at the highest speed allowed along its chord, no acceleration
    limit: dq (K, 5) joint displacements (mm, rad), dtip (K, 3) tool tip displacements (mm,
    relative to the part), feed (K,) mm/s; ``angular_feed`` (rad/s) as in :func:`lower_bound_time`."""
    return _block_min_time(_moves(np.asarray(dq, dtype=float), np.asarray(dtip, dtype=float)),
                           np.asarray(feed, dtype=float), _check_limits(limits), angular_feed)


@dataclass(frozen=True)
class DoubleS:
    """The time-optimal rest-to-rest move of one axis (:func:`rest_to_rest`), per row: its peak
    speed and acceleration, and the durations (s) of each of its four jerk phases, of each of
    its two constant-acceleration phases and of its cruise."""

    peak_speed: np.ndarray
    peak_acceleration: np.ndarray
    jerk_time: np.ndarray
    acceleration_time: np.ndarray
    cruise_time: np.ndarray

    @property
    def total(self) -> np.ndarray:
        """Duration (s) of the whole move."""
        return 4.0 * self.jerk_time + 2.0 * self.acceleration_time + self.cruise_time


def rest_to_rest(distance: np.ndarray, speed: np.ndarray, acc: np.ndarray, jerk: np.ndarray) -> DoubleS:
    """The time-optimal move over ``distance`` from rest to rest under a speed, an acceleration
    and a jerk limit (jerk inf: the trapezoid), row by row (same-shape arrays, any unit of
    length: the limits per s, s^2, s^3 of it).

    A ramp from rest to v takes tj = sqrt(v / J) of jerk each way where v J <= A^2 (no
    acceleration limit reached), else tj = A / J and A for v / A - A / J between; it covers
    v (2 tj + ta) / 2. Two ramps to the speed limit that cover more than the distance D give way
    to the peak speed whose two ramps cover exactly D (the double S profile of Biagiotti &
    Melchiorri, Trajectory Planning for Automatic Machines and Robots, 2008, sec. 3.4).
    """
    with np.errstate(divide="ignore", invalid="ignore"):

        def ramp(v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            full = v * jerk >= acc ** 2  # the acceleration limit is reached
            tj = np.where(full, acc / jerk, np.sqrt(v / jerk))
            return full, tj, np.where(full, v / acc - tj, 0.0)

        _, tj, ta = ramp(speed)
        short = speed * (2.0 * tj + ta) > distance
        # no cruise: the peak from 2 v^1.5 / sqrt(J) = D, else from v^2 / A + v A / J = D
        free = (distance * np.sqrt(jerk) / 2.0) ** (2.0 / 3.0)
        b = acc ** 2 / jerk
        capped = 2.0 * acc * distance / (b + np.sqrt(b ** 2 + 4.0 * acc * distance))  # without cancellation
        top = np.where(short, np.where(free * jerk <= acc ** 2, free, capped), speed)
        full, tj, ta = ramp(top)
        tv = np.where(short, 0.0, (distance - top * (2.0 * tj + ta)) / top)
        peak_acc = np.where(full, acc, jerk * tj)
    return DoubleS(top, peak_acc, np.where(np.isfinite(jerk), tj, 0.0), np.maximum(ta, 0.0), np.maximum(tv, 0.0))


def lower_bound_time(joints: np.ndarray, tip: np.ndarray, feed: np.ndarray, limits: Limits, *,
                     angular_feed: float | None = None) -> float:
    """A lower bound (s) on the time of any plan of the sequence: no acceleration limit at all.

    The integral over the polyline of ds / min(F, min_j v_j / |dq_j/ds|) with s the tip arc
    length and F the block's feed; a rotary-only block (tip still) takes its slowest joint at
    its velocity limit, or its rotary angle at ``angular_feed`` (rad/s) where that is given.
    """
    joints, tip, feed = checked_sequence(joints, tip, feed)
    limits = _check_limits(limits)
    return float(np.sum(_block_min_time(_blocks(joints, tip), feed, limits, angular_feed)))


def baseline_time(joints: np.ndarray, tip: np.ndarray, feed: np.ndarray, limits: Limits, *,
                  angular_feed: float | None = None, cycle: float = 0.002) -> float:
    """Time (s) a common CNC look-ahead planner would take: trapezoidal feed along the tip path.

    Each block's feed is clamped so that no joint exceeds its velocity limit on that block
    (the joints move proportionally along a block), its tangential acceleration is the one
    the dominating joint allows, and a backward then a forward pass make every block reachable
    (decelerating ahead of a slower block). At a block junction the speed is at most the lower
    of the two feeds and, as controllers limit the velocity jump of each joint at a block
    transition, at most the speed whose joint velocity change stays within what the joint's
    acceleration gives in one interpolation ``cycle`` (s; 2 ms is common). Start and end at
    rest; no jerk limit, no curvature limit. Rotary-only blocks are planned along the weighted
    joint displacement, capped by ``angular_feed`` (rad/s), and the machine stops before and
    after them (speeds in different units).
    """
    joints, tip, feed = checked_sequence(joints, tip, feed)
    limits = _check_limits(limits)
    blocks = _blocks(joints, tip)
    weighted = np.linalg.norm(blocks.dq / limits.velocity, axis=1)
    ell = np.where(blocks.rotary_only, weighted, blocks.length)  # mm, or s at the velocity limits
    adq = np.abs(blocks.dq)
    with np.errstate(divide="ignore", invalid="ignore"):
        speed = np.min(np.where(adq > 0, limits.velocity * ell[:, None] / adq, np.inf), axis=1)
        accel = np.min(np.where(adq > 0, limits.acceleration * ell[:, None] / adq, np.inf), axis=1)
        speed = np.where(blocks.rotary_only, speed, np.minimum(speed, feed))
        if angular_feed is not None:
            speed = np.where(blocks.rotary_only & (blocks.rotary > 0),
                             np.minimum(speed, angular_feed * ell / np.maximum(blocks.rotary, 1e-300)), speed)
    keep = ell > 0
    if not np.all(keep):
        raise PlanningError(f"block {int(np.flatnonzero(~keep)[0])} has no motion", int(np.flatnonzero(~keep)[0]))
    k = len(ell)
    junction = np.zeros(k + 1)
    same_kind = blocks.rotary_only[:-1] == blocks.rotary_only[1:]
    junction[1:-1] = np.where(same_kind, np.minimum(speed[:-1], speed[1:]), 0.0)
    # Velocity jump at the junction: joint rates per unit of path before and after.
    rate = adq * np.sign(blocks.dq) / np.maximum(ell, 1e-300)[:, None]
    jump = np.abs(rate[1:] - rate[:-1])
    with np.errstate(divide="ignore"):
        allowed = np.min(np.where(jump > 0, limits.acceleration * cycle / jump, np.inf), axis=1)
    junction[1:-1] = np.minimum(junction[1:-1], allowed)
    reach = 2.0 * accel * ell
    j = junction.tolist()
    r = reach.tolist()
    for i in range(k - 1, -1, -1):
        j[i] = min(j[i], math.sqrt(j[i + 1] ** 2 + r[i]))
    for i in range(k):
        j[i + 1] = min(j[i + 1], math.sqrt(j[i] ** 2 + r[i]))
    v0, v1 = np.array(j[:-1]), np.array(j[1:])
    peak = np.minimum(speed, np.sqrt((reach + v0 ** 2 + v1 ** 2) / 2.0))
    peak = np.maximum(peak, np.maximum(v0, v1))
    ramp = (2 * peak ** 2 - v0 ** 2 - v1 ** 2) / (2.0 * accel)
    cruise = np.maximum(ell - ramp, 0.0) / peak
    return float(np.sum((2 * peak - v0 - v1) / accel + cruise))


# --------------------------------------------------------------------------------------------
# Rapids
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class RapidPlan:
    """A rest-to-rest, jerk-limited, time-optimal joint move along the straight joint segment."""

    start: np.ndarray  # (5,) mm, rad
    end: np.ndarray  # (5,) mm, rad
    duration: float  # s (0 for a move of zero length)
    trajectory: Trajectory | None  # ruckig trajectory (None for a move of zero length)
    limits: Limits | None = None  # what it was planned with

    @property
    def total(self) -> float:
        return self.duration

    def __reduce__(self) -> tuple:
        # ruckig's Trajectory cannot be pickled: a plan sent between processes is planned
        # again from its ends and limits on arrival (ruckig is deterministic: the same plan).
        if self.trajectory is None:
            return RapidPlan, (self.start, self.end, self.duration, None, self.limits)
        if self.limits is None:
            raise TypeError("a RapidPlan with a trajectory crosses processes with the limits it was planned with")
        return plan_rapid, (self.start, self.end, self.limits)

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Joint positions, velocities, accelerations (n, 5) at times ``t`` (s, clipped to 0..duration)."""
        t = np.clip(np.asarray(t, dtype=float).reshape(-1), 0.0, self.duration)
        if self.trajectory is None:
            return np.tile(self.start, (len(t), 1)), np.zeros((len(t), DOF)), np.zeros((len(t), DOF))
        out = np.array([self.trajectory.at_time(float(x)) for x in t]).reshape(len(t), 3, DOF)
        return out[:, 0], out[:, 1], out[:, 2]


def plan_rapid(start: np.ndarray, end: np.ndarray, limits: Limits) -> RapidPlan:
    """Rapid from rest at ``start`` to rest at ``end`` (5,) mm/rad with ruckig (phase-synchronised).

    Phase synchronisation scales every joint's profile to the same shape, so the move is a
    straight line in joint space; the slowest joint sets the time and is time-optimal.
    """
    limits = _check_limits(limits)
    start = np.asarray(start, dtype=float).reshape(-1)
    end = np.asarray(end, dtype=float).reshape(-1)
    if start.shape != (DOF,) or end.shape != (DOF,):
        raise ValueError("start and end must be 5 joint values")
    if not (np.all(np.isfinite(start)) and np.all(np.isfinite(end))):
        raise ValueError("start and end must be finite")
    if np.all(np.abs(end - start) <= 1e-12 * np.maximum(1.0, np.abs(start))):
        return RapidPlan(start, start.copy(), 0.0, None, limits)
    inp = InputParameter(DOF)
    inp.current_position = start.tolist()
    inp.current_velocity = [0.0] * DOF
    inp.current_acceleration = [0.0] * DOF
    inp.target_position = end.tolist()
    inp.target_velocity = [0.0] * DOF
    inp.target_acceleration = [0.0] * DOF
    inp.max_velocity = limits.velocity.tolist()
    inp.max_acceleration = limits.acceleration.tolist()
    inp.max_jerk = limits.jerk.tolist()
    inp.synchronization = Synchronization.Phase
    trajectory = Trajectory(DOF)
    try:
        result = Ruckig(DOF).calculate(inp, trajectory)
    except ValueError as error:  # an error code the binding has no name for (-101: duration too long)
        raise PlanningError(f"ruckig could not plan the rapid from {start.tolist()} to {end.tolist()}: {error}"
                            ) from error
    if result not in (Result.Working, Result.Finished):
        raise PlanningError(f"ruckig could not plan the rapid from {start.tolist()} to {end.tolist()}: {result}")
    return RapidPlan(start, end, float(trajectory.duration), trajectory, limits)
