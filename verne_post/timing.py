"""Time laws: feed sequences (toppra + jerk limiting) and rapids (ruckig), pure numpy planning.

Units: joints (N, 5) are rho1..3 in mm and theta1, theta2 in rad; tool tips in mm relative to
the part; times in s; limits per second (mm/s, rad/s, mm/s^2, ...). Nothing here reads files.

Feed sequences
--------------
The controller moves linearly in joint space between the waypoints of a feed sequence; the
polyline is smooth (small turning angles), so the path toppra sees is a C2 cubic spline through
the waypoints, parametrised by the normalised cumulative joint-space arc length s in [0, 1]
(each joint weighted by 1 / its velocity limit, so mm and rad mix sensibly). The spline passes
through every waypoint exactly at its s value; between them it stays within the chordal
tolerance of the polyline. The plan is built in four steps:

1. Velocity caps on the path speed sdot(s) (1/s): per block the programmed feed as a limit on
   the tool-tip speed, ``|d tip/ds| * sdot <= F``, with ``|d tip/ds|`` both the block's tip
   chord over its s length and, pointwise, the derivative of a spline through the tips with
   the same parameter (rotary-only blocks: ``|d(theta1, theta2)/ds| * sdot <= angular_feed``);
   a minimum block duration; pointwise the joint velocity limits ``|q_j'(s)| sdot <= v_j`` and
   a centripetal-jerk cap ``|q_j'''(s)| sdot^3 <= 0.7 J_j``. The caps are evaluated at every
   waypoint, block middle and toppra gridpoint, so the feed holds on every block even when
   toppra's grid is coarser than the blocks.
2. toppra (TOPPRA, seidel solver, interpolation discretisation) with those caps as a velocity
   bound and the joint accelerations ``|q_j' sddot + q_j'' sdot^2| <= 0.97 a_j``, time-scaled so
   the squared path velocities are O(1). Gridpoints: a toppra interval every ``w / 4`` of
   travel at the capped speed (long blocks subdivided, runs of short blocks merged), at least
   64 and at most about two per block: the cost follows the path's duration, not its waypoint
   count. The resulting constant-acceleration profile sigma(t) (the ``ParametrizeConstAccel``
   model, evaluated vectorised) respects velocity and acceleration limits, but its path
   acceleration jumps.
3. Jerk: the profile is filtered by a moving average of width ``w = 1.25 max_j(a_j / J_j)`` in
   time (an FIR filter on the path parameter, as CNC controllers limit jerk, but along the
   path so the motion stays on it): ``s(t) = 1/w * integral_{t-w}^{t} sigma``, exactly a
   piecewise cubic. Its path jerk is ``(sigma''(t) - sigma''(t-w)) / w``: a path acceleration
   swing of up to 1.25 times its limit takes at least the time the jerk limit needs. The
   filtered speed mixes the speeds within half a window of travel, so each cap is imposed on
   toppra over ``w / 2 * (its own speed)`` of travel on either side (a step down of the feed
   is reached that much early), and the path acceleration is bounded by
   ``a_j / max |q_j'|`` over the window.
4. Verification of the exact trajectory (joint velocity, acceleration, jerk, tip feed,
   angular feed, analytic derivatives) at several samples of every polynomial piece of the
   time law and both sides of every waypoint. Where a limit is exceeded, the speed caps (for
   excess due to speed and curvature) or the acceleration limit (for excess due to path
   acceleration and jerk) are lowered around it in proportion and the plan is redone. A plan
   that still exceeds a limit after ``max_refinements`` rounds raises :class:`PlanningError`:
   nothing is returned unchecked.

Block durations are the times between the path parameter values of the waypoints, so sampling
at the cumulative durations gives back the waypoints.

Rapids
------
ruckig, offline, time-optimal, jerk-limited, phase-synchronised (a straight line in joint space),
rest to rest.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import toppra
import toppra.algorithm
from ruckig import InputParameter, Result, Ruckig, Synchronization, Trajectory
from scipy.interpolate import CubicSpline, PPoly
from toppra.constraint import DiscretizationType, LinearConstraint, canlinear_colloc_to_interpolate

from .errors import CheckError

__all__ = [
    "FeedPlan", "Limits", "PlanningError", "RapidPlan", "baseline_time", "lower_bound_time", "plan_feed",
    "plan_rapid",
]

logger = logging.getLogger(__name__)

DOF = 5
TIP_EPS = 1e-4
"""mm: a block whose tool tip moves less than this is rotary-only (limited by ``angular_feed``)."""

_ACC_MARGIN = 0.97  # share of the acceleration limits given to toppra (the filter mixes neighbours)
_JERK_CAP_MARGIN = 0.7  # share of the jerk limits for the centripetal-jerk velocity cap
_FIR_FACTOR = 1.25  # filter width w = factor * max_j(a_j / J_j): a path acceleration swing of up to
# 1.25 x its limit (accelerate, then slow down a little) stays within the jerk limit
_ERODE = 0.5  # a cap holds over _ERODE * w * (its own speed) of travel on either side of its point
_GRID_PER_WINDOW = 4  # target toppra grid intervals per filter width, at the capped speed
_MIN_INTERVALS = 32
_MAX_INTERVALS_PER_BLOCK = 1.0  # toppra grid intervals per block, on average at most (plus a constant)
# (acceleration factor, time-scale factor) tried in turn when toppra fails numerically
_TOPPRA_RETRIES = ((1.0, 1.0), (0.999, 0.1), (0.99, 0.43), (0.98, 2.3), (0.97, 10.0))
_MAX_PIECE_SAMPLES = 64  # verification samples per piece of the time law (see _verify)
_VERIFY_TOL = 1e-6  # relative excess tolerated by the verification (rounding)
_SHRINK = 0.97  # extra factor applied when lowering caps after a violation


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


# --------------------------------------------------------------------------------------------
# Feed plan
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class FeedPlan:
    """Time law of one feed sequence.

    ``durations[k]`` (s) is the time from waypoint k to k + 1; ``block_times`` (K + 1,) their
    cumulative sum from 0. ``path`` is the joint-space spline q(s) through the waypoints
    (at ``waypoint_s``), ``profile`` the path parameter s(t) (piecewise polynomial in t, C2
    when planned with jerk limits).
    """

    durations: np.ndarray  # (K,) s
    block_times: np.ndarray  # (K + 1,) s, block_times[0] = 0, block_times[-1] = total
    waypoint_s: np.ndarray  # (K + 1,) path parameter of the waypoints, 0 .. 1
    path: CubicSpline  # q(s): (5,) mm/rad
    profile: PPoly  # s(t)
    filter_width: float  # s, width of the jerk filter (0 without jerk limiting)
    gridpoints: int  # toppra gridpoints used
    refinements: int  # local cap reductions needed to meet every limit

    @property
    def total(self) -> float:
        """Duration of the whole sequence (s)."""
        return float(self.block_times[-1])

    def sample_path(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Path parameter s and its first three time derivatives at times ``t`` (s, clipped to 0..total)."""
        t = np.clip(np.asarray(t, dtype=float).reshape(-1), 0.0, self.total)
        s = np.clip(self.profile(t), 0.0, 1.0)
        return s, self.profile(t, 1), self.profile(t, 2), self.profile(t, 3)

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Joint positions, velocities, accelerations (n, 5) each (mm, rad, per s) at times ``t`` (s)."""
        q, qd, qdd, _ = self.sample_all(t)
        return q, qd, qdd

    def sample_all(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Joint positions, velocities, accelerations and jerks (n, 5) each at times ``t`` (s)."""
        s, sd, sdd, sddd = self.sample_path(t)
        return _joint_motion(self.path, s, sd, sdd, sddd)

    def block_index(self, t: np.ndarray) -> np.ndarray:
        """Index of the block (0..K-1) being run at times ``t`` (s)."""
        t = np.asarray(t, dtype=float)
        return np.clip(np.searchsorted(self.block_times, t, side="right") - 1, 0, len(self.durations) - 1)


def _joint_motion(path: CubicSpline, s: np.ndarray, sd: np.ndarray, sdd: np.ndarray, sddd: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    q = path(s)
    q1, q2, q3 = path(s, 1), path(s, 2), path(s, 3)
    sd_, sdd_, sddd_ = sd[:, None], sdd[:, None], sddd[:, None]
    return (q, q1 * sd_, q1 * sdd_ + q2 * sd_ ** 2, q1 * sddd_ + 3.0 * q2 * sd_ * sdd_ + q3 * sd_ ** 3)


class _Path(toppra.interpolator.AbstractGeometricPath):
    """The joint spline q(s), s in [0, 1], as toppra's geometric path."""

    def __init__(self, spline: CubicSpline) -> None:
        self.spline = spline

    def __call__(self, path_positions: Any, order: int = 0) -> np.ndarray:
        return self.spline(path_positions, order)

    @property
    def dof(self) -> int:
        return DOF

    @property
    def path_interval(self) -> np.ndarray:
        return np.array([0.0, 1.0])


class _PathBound(LinearConstraint):
    """Bounds on the squared path velocity x = sdot^2 and on |u| = |sddot| at each gridpoint."""

    def __init__(self, xmax: np.ndarray, umax: np.ndarray | None) -> None:
        super().__init__()
        self.dof = DOF
        self.xmax, self.umax = xmax, umax
        self._format_string = "    path velocity and acceleration bounds per gridpoint\n"

    def compute_constraint_params(self, path: Any, gridpoints: np.ndarray, *args: Any, **kwargs: Any) -> tuple:
        xbound = np.zeros((len(gridpoints), 2))
        xbound[:, 1] = self.xmax
        ubound = None if self.umax is None else np.stack([-self.umax, self.umax], axis=1)
        return None, None, None, None, None, ubound, xbound


class _AccelerationBound(LinearConstraint):
    """|q'(s_i) u + q''(s_i) x| <= 1 per joint, rows pre-divided by the (local) acceleration limit."""

    def __init__(self, q1: np.ndarray, q2: np.ndarray) -> None:
        super().__init__()
        self.dof = DOF
        self.q1, self.q2 = q1, q2
        self.set_discretization_type(DiscretizationType.Interpolation)
        self.identical = True
        self._format_string = "    joint acceleration, scaled per gridpoint\n"

    def compute_constraint_params(self, path: Any, gridpoints: np.ndarray, *args: Any, **kwargs: Any) -> tuple:
        f = np.vstack([np.eye(DOF), -np.eye(DOF)])
        g = np.ones(2 * DOF)
        return canlinear_colloc_to_interpolate(self.q1, self.q2, np.zeros_like(self.q1), f, g, None, None,
                                               gridpoints, identical=True)


class _RangeExtreme:
    """Range minimum (or maximum) queries along axis 0 of a fixed array (sparse table, vectorised)."""

    def __init__(self, values: np.ndarray, maximum: bool = False) -> None:
        self.sign = -1.0 if maximum else 1.0
        v = self.sign * np.asarray(values, dtype=float)
        n = len(v)
        levels = [v]
        step = 1
        while 2 * step <= n:
            prev = levels[-1]
            nxt = np.full_like(v, np.inf)
            nxt[: n - 2 * step + 1] = np.minimum(prev[: n - 2 * step + 1], prev[step: n - step + 1])
            levels.append(nxt)
            step *= 2
        self.table = np.stack(levels)

    def query(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Extreme of values[lo..hi] (inclusive index arrays, lo <= hi)."""
        length = hi - lo + 1
        level = np.floor(np.log2(length)).astype(int)
        a = self.table[level, lo]
        b = self.table[level, hi - (1 << level) + 1]
        return self.sign * np.minimum(a, b)


def _range_chmin(n: int, lo: np.ndarray, hi: np.ndarray, values: np.ndarray) -> np.ndarray:
    """out[i] = min(values[m] for every m with lo[m] <= i <= hi[m]) (inf where none), vectorised.

    Each update is written to the two power-of-two blocks covering its range, then the blocks
    are pushed down level by level (a sparse table used in reverse).
    """
    length = hi - lo + 1
    level = np.floor(np.log2(np.maximum(length, 1))).astype(int)
    top = int(level.max()) if len(level) else 0
    table = np.full((top + 1, n), np.inf)
    np.minimum.at(table, (level, lo), values)
    np.minimum.at(table, (level, hi - (1 << level) + 1), values)
    for k in range(top, 0, -1):
        half = 1 << (k - 1)
        np.minimum(table[k - 1], table[k], out=table[k - 1])
        table[k - 1, half:] = np.minimum(table[k - 1, half:], table[k, : n - half])
    return table[0]


def _check_limits(limits: Limits) -> Limits:
    if not isinstance(limits, Limits):
        raise TypeError("limits must be a verne_post.timing.Limits")
    return limits


def _as_sequence(joints: np.ndarray, tip: np.ndarray, feed: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
    dq = np.diff(joints, axis=0)
    length = np.linalg.norm(np.diff(tip, axis=0), axis=1)
    return _Blocks(dq, length, length < TIP_EPS, np.linalg.norm(dq[:, 3:], axis=1))


def _block_min_time(blocks: _Blocks, feed: np.ndarray, limits: Limits, angular_feed: float | None) -> np.ndarray:
    """Per-block time at the highest speed allowed along the block's chord (s), no acceleration."""
    t_joint = np.max(np.abs(blocks.dq) / limits.velocity, axis=1)
    t_feed = np.where(blocks.rotary_only, 0.0, blocks.length / feed)
    if angular_feed is not None:
        t_feed = np.where(blocks.rotary_only, blocks.rotary / angular_feed, t_feed)
    return np.maximum(t_joint, t_feed)


def lower_bound_time(joints: np.ndarray, tip: np.ndarray, feed: np.ndarray, limits: Limits, *,
                     angular_feed: float | None = None) -> float:
    """A lower bound (s) on the time of any plan of the sequence: no acceleration limit at all.

    The integral over the polyline of ds / min(F, min_j v_j / |dq_j/ds|) with s the tip arc
    length and F the block's feed; a rotary-only block (tip still) takes its slowest joint at
    its velocity limit, or its rotary angle at ``angular_feed`` (rad/s) where that is given.
    """
    joints, tip, feed = _as_sequence(joints, tip, feed)
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
    joints, tip, feed = _as_sequence(joints, tip, feed)
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


def plan_feed(joints: np.ndarray, tip: np.ndarray, feed: np.ndarray, limits: Limits, *, angular_feed: float,
              min_duration: float = 1e-4, jerk: bool = True, max_turn: float = math.radians(30.0),
              max_refinements: int = 12) -> FeedPlan:
    """Plan the time law of one continuous feed sequence.

    Parameters
    ----------
    joints : (K + 1, 5) waypoints (block end positions) in mm and rad; the controller moves
        linearly between them.
    tip : (K + 1, 3) tool tip at the waypoints, mm, relative to the part.
    feed : (K,) programmed feed of each block, mm/s: the maximum tip speed relative to the part.
    limits : joint velocity, acceleration and jerk limits.
    angular_feed : rad/s, the speed limit of the rotary joints (theta1, theta2 together) on
        rotary-only blocks (tip still).
    min_duration : s, no block is shorter than this.
    jerk : limit joint jerk too (otherwise the constant-acceleration toppra profile is used).
    max_turn : rad, the largest angle between consecutive blocks (in joint space weighted by
        1 / velocity limit) that is accepted; sharper corners must be split by the caller.
    max_refinements : rounds of local slow-down allowed to meet every limit.

    Raises
    ------
    ValueError : malformed input.
    PlanningError : a corner is too sharp, a block has no motion, toppra failed, or no plan
        within the limits was found; the message names the waypoint.
    """
    joints, tip, feed = _as_sequence(joints, tip, feed)
    limits = _check_limits(limits)
    if not (math.isfinite(angular_feed) and angular_feed > 0):
        raise ValueError(f"angular_feed must be positive (rad/s), got {angular_feed}")
    if not (math.isfinite(min_duration) and min_duration >= 0):
        raise ValueError(f"min_duration must be >= 0 (s), got {min_duration}")
    return _FeedPlanner(joints, tip, feed, limits, angular_feed, min_duration, jerk, max_turn,
                        max_refinements).plan()


class _FeedPlanner:
    """One feed sequence: path, caps, toppra, filter, verification (see the module docstring)."""

    def __init__(self, joints: np.ndarray, tip: np.ndarray, feed: np.ndarray, limits: Limits, angular_feed: float,
                 min_duration: float, jerk: bool, max_turn: float, max_refinements: int) -> None:
        self.joints, self.limits, self.jerk, self.max_refinements = joints, limits, jerk, max_refinements
        self.blocks = blocks = _blocks(joints, tip)
        k = len(feed)
        self.k = k
        weighted = np.linalg.norm(blocks.dq / limits.velocity, axis=1)
        scale = max(float(weighted.sum()), 1e-300)
        empty = np.flatnonzero(weighted <= 1e-12 * scale)
        if len(empty):
            b = int(empty[0])
            raise PlanningError(f"feed block {b} (waypoints {b} to {b + 1}) has no joint motion: drop repeated "
                                f"waypoints", b)
        direction = blocks.dq / limits.velocity / weighted[:, None]
        turn = np.arccos(np.clip(np.sum(direction[:-1] * direction[1:], axis=1), -1.0, 1.0))
        sharp = np.flatnonzero(turn > max_turn)
        if len(sharp):
            i = int(sharp[0]) + 1
            raise PlanningError(f"corner of {math.degrees(turn[i - 1]):.1f} deg at waypoint {i} is sharper than "
                                f"{math.degrees(max_turn):.1f} deg: split the feed sequence there", i)
        s = np.concatenate([[0.0], np.cumsum(weighted)]) / weighted.sum()
        s[-1] = 1.0
        self.s = s
        self.ds = np.diff(s)
        self.spline = CubicSpline(s, joints, axis=0, bc_type="not-a-knot")
        # The tip along the path, as a spline through the tips with the same parameter: the tip
        # speed factor |d tip/ds| pointwise, used besides each block's chord ratio.
        self.tip_spline = CubicSpline(s, tip, axis=0, bc_type="not-a-knot")
        self.tip_feed = np.where(blocks.rotary_only, np.inf, feed)  # mm/s, inf where rotary-only
        # Block caps on sdot (1/s): tip feed, angular feed, minimum duration.
        with np.errstate(divide="ignore"):
            tip_cap = np.where(blocks.rotary_only, np.inf, feed * self.ds / np.maximum(blocks.length, 1e-300))
            rot_cap = np.where(blocks.rotary_only & (blocks.rotary > 0),
                               angular_feed * self.ds / np.maximum(blocks.rotary, 1e-300), np.inf)
            dur_cap = self.ds / min_duration if min_duration > 0 else np.full(k, np.inf)
        self.block_cap = np.minimum(np.minimum(tip_cap, rot_cap), dur_cap)  # sdot, per block
        self.w = _FIR_FACTOR * float(np.max(limits.acceleration / limits.jerk)) if jerk else 0.0
        self._grid()

    # -- geometry and caps ------------------------------------------------------------------

    def _point_cap(self, c: np.ndarray) -> np.ndarray:
        """Squared path-speed cap at path parameters c: joint velocity, tip feed, centripetal jerk."""
        lim, s, k = self.limits, self.s, self.k
        q1 = np.abs(self.spline(c, 1))
        right = np.clip(np.searchsorted(s, c, side="right") - 1, 0, k - 1)
        left = np.clip(np.searchsorted(s, c, side="left") - 1, 0, k - 1)
        feed = np.minimum(self.tip_feed[left], self.tip_feed[right])
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.min((lim.velocity / q1) ** 2, axis=1)
            x = np.minimum(x, np.nan_to_num((feed / np.linalg.norm(self.tip_spline(c, 1), axis=1)) ** 2, nan=np.inf))
            if self.jerk:
                q3 = np.abs(self.spline(c, 3))
                x = np.minimum(x, np.min((_JERK_CAP_MARGIN * lim.jerk / q3) ** (2.0 / 3.0), axis=1))
        return x

    def _grid(self) -> None:
        s, ds, k = self.s, self.ds, self.k
        mids = s[:-1] + 0.5 * ds
        x_mid = np.minimum(self._point_cap(mids), self.block_cap ** 2)
        tau = ds / np.sqrt(x_mid)  # s per block at its cap
        t_est = float(tau.sum())
        self.t_scale = max(t_est, 1e-6)
        delta = (self.w if self.jerk else 0.05) / _GRID_PER_WINDOW
        delta = min(delta, t_est / _MIN_INTERVALS)
        delta = max(delta, t_est / (_MAX_INTERVALS_PER_BLOCK * k + _MIN_INTERVALS))
        cum = np.concatenate([[0.0], np.cumsum(tau)])
        bucket = np.floor(cum / delta)
        keep = np.zeros(k + 1, bool)
        keep[[0, k]] = True
        keep[1:] |= bucket[1:] != bucket[:-1]
        long = tau > delta
        keep[:-1] |= long
        keep[1:] |= long
        parts = np.maximum(np.round(tau[long] / delta), 1).astype(int)
        starts, widths = s[:-1][long], ds[long]
        total = int(parts.sum())
        owner = np.repeat(np.arange(len(parts)), parts)
        step = np.arange(total) - np.repeat(np.cumsum(parts) - parts, parts)
        interior = (starts[owner] + widths[owner] * step / parts[owner])[step > 0]
        # The start and the end (acceleration from and to rest) get a geometrically refined grid.
        ends = np.minimum(s[keep][1], 1.0 - s[keep][-2]) * 0.5 ** np.arange(1, 5)
        grid = np.unique(np.concatenate([s[keep], interior, ends, 1.0 - ends]))
        grid[0], grid[-1] = 0.0, 1.0
        self.grid = grid
        gm = grid[:-1] + 0.5 * np.diff(grid)
        self.check = np.unique(np.concatenate([grid, gm, s, mids]))
        # Raw squared caps at the check points: pointwise, and of the block(s) they lie in.
        right = np.clip(np.searchsorted(s, self.check, side="right") - 1, 0, k - 1)
        left = np.clip(np.searchsorted(s, self.check, side="left") - 1, 0, k - 1)
        raw = np.minimum(self._point_cap(self.check), np.minimum(self.block_cap[left], self.block_cap[right]) ** 2)
        raw = np.minimum(raw, 1e300)
        # With the filter, the speed at a point mixes the speeds within half a filter width of
        # travel around it: each check point imposes its cap over _ERODE * w * (its own capped
        # speed) on either side (a low cap reaches only a short way), and a gridpoint takes the
        # lowest cap reaching its two grid intervals (toppra's x is linear in s between gridpoints).
        n = len(grid)
        reach = _ERODE * self.w * np.sqrt(raw) if self.jerk else np.zeros_like(raw)
        first = np.clip(np.searchsorted(grid, self.check - reach, side="left") - 1, 0, n - 1)
        last = np.clip(np.searchsorted(grid, self.check + reach, side="right"), 0, n - 1)
        self.xcap = _range_chmin(n, first, last, raw)
        lo0 = grid[np.maximum(np.arange(n) - 1, 0)]
        hi0 = grid[np.minimum(np.arange(n) + 1, n - 1)]
        r = _ERODE * self.w * np.sqrt(self.xcap)
        self.radius = np.maximum(r, np.maximum(grid - lo0, hi0 - grid))
        # Path acceleration bound: the filter spreads a path acceleration over its window, where
        # |q_j'| may be larger than at the gridpoint; |sddot| <= a_j / max over the window |q_j'|.
        a, b = self._check_range(np.minimum(grid - r, lo0), np.maximum(grid + r, hi0))
        q1_check = np.abs(self.spline(self.check, 1))
        with np.errstate(divide="ignore"):
            self.umax = np.min(self.limits.acceleration / _RangeExtreme(q1_check, maximum=True).query(a, b), axis=1)
        self.umax = np.minimum(self.umax, 1e300)
        self.q1 = self.spline(grid, 1)
        self.q2 = self.spline(grid, 2)

    def _check_range(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a = np.searchsorted(self.check, lo, side="left")
        b = np.searchsorted(self.check, hi, side="right") - 1
        a = np.clip(a, 0, len(self.check) - 1)
        return a, np.clip(np.maximum(a, b), 0, len(self.check) - 1)

    def _waypoint_at(self, path_s: float) -> int:
        return int(np.clip(np.searchsorted(self.s, path_s - 1e-12, side="left"), 0, self.k))

    # -- toppra ---------------------------------------------------------------------------------

    def _toppra(self, xmax: np.ndarray, acc_scale: np.ndarray) -> np.ndarray:
        """Squared path velocities (1/s^2) at the gridpoints, time-optimal under xmax and accelerations.

        toppra's seidel solver occasionally loses a controllable set to rounding (a known
        weakness of its 1-D LPs); the same problem is then solved again at another time scale,
        with the acceleration limits 0.1 to 2 % lower (stricter, never looser). If that fails too,
        :class:`PlanningError` names the waypoint.
        """
        for tighten, rescale in _TOPPRA_RETRIES:
            t0 = self.t_scale * rescale
            scale = acc_scale * tighten
            inv = 1.0 / (scale[:, None] * self.limits.acceleration[None, :] * t0 ** 2)
            umax = scale * self.umax * t0 ** 2 if self.jerk else None
            constraints = [_PathBound(np.maximum(xmax, 0.0) * t0 ** 2, umax),
                           _AccelerationBound(self.q1 * inv, self.q2 * inv)]
            try:
                instance = toppra.algorithm.TOPPRA(constraints, _Path(self.spline), gridpoints=self.grid,
                                                   solver_wrapper="seidel")
                _, sd, _, controllable = instance.compute_parameterization(0.0, 0.0, return_data=True)
            except Exception as exc:  # any toppra failure is reported, never planned around
                raise PlanningError(f"toppra failed on the feed sequence ({type(exc).__name__}: {exc})", 0) from exc
            if sd is not None and np.all(np.isfinite(sd)):
                x = np.asarray(sd, dtype=float) ** 2 / t0 ** 2
                x[0] = x[-1] = 0.0
                return x
            logger.debug("toppra failed (accelerations x %s, time scale x %s), retrying", tighten, rescale)
        where = 0
        if controllable is not None:
            bad = np.flatnonzero(~np.all(np.isfinite(controllable), axis=1))
            where = self._waypoint_at(float(self.grid[bad.max()])) if len(bad) else 0
        if sd is not None:
            bad = np.flatnonzero(~np.isfinite(sd))
            where = self._waypoint_at(float(self.grid[bad.min()])) if len(bad) else where
        raise PlanningError(f"toppra found no feasible time law near waypoint {where} (instance not "
                            f"controllable or numerically ill-conditioned)", where)

    # -- the time law ---------------------------------------------------------------------------

    def _profile(self, x: np.ndarray) -> PPoly:
        """s(t): the constant-acceleration toppra profile, filtered when jerk is limited."""
        grid = self.grid
        v = np.sqrt(x)
        speed_sum = v[:-1] + v[1:]
        stuck = np.flatnonzero(speed_sum <= 0)
        if len(stuck):
            where = self._waypoint_at(float(grid[stuck[0]]))
            raise PlanningError(f"the planned path speed drops to zero near waypoint {where}", where)
        dgrid = np.diff(grid)
        dt = 2.0 * dgrid / speed_sum
        t = np.concatenate([[0.0], np.cumsum(dt)])
        u = (x[1:] - x[:-1]) / (2.0 * dgrid)
        if not self.jerk:
            return PPoly(np.stack([0.5 * u, v[:-1], grid[:-1]]), t, extrapolate=True)
        return _filtered_profile(t, grid, v, u, self.w)

    def _block_times(self, profile: PPoly) -> np.ndarray:
        total = float(profile.x[-1])
        inner = _invert_profile(profile, self.s[1:-1])
        times = np.concatenate([[0.0], inner, [total]])
        if np.any(np.diff(times) <= 0):
            bad = int(np.flatnonzero(np.diff(times) <= 0)[0])
            raise PlanningError(f"block {bad} got a non-positive duration (numerical failure)", bad)
        return times

    def _verify(self, profile: PPoly, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Worst excess over the limits at samples of the time law.

        Returns (s of the samples, factor on the squared speed, factor on the acceleration limit),
        only for samples that exceed a limit (empty arrays if none does).
        """
        b = profile.x
        h = np.diff(b)
        fill_dt = max(self.w / 8.0, 1e-3) if self.jerk else 5e-3
        # A piece lies within one grid interval, where the path and the cubic s(t) are smooth: a
        # bounded number of samples resolves it however long it lasts (a very slow feed gives
        # pieces of hours, which at fill_dt would not fit in memory).
        gaps = np.clip(np.ceil(h / fill_dt), 2, _MAX_PIECE_SAMPLES).astype(int)
        owner = np.repeat(np.arange(len(h)), gaps)
        step = np.arange(int(gaps.sum())) - np.repeat(np.cumsum(gaps) - gaps, gaps)
        pieces = b[:-1][owner] + h[owner] * step / gaps[owner]
        ends = b[1:] - 1e-9 * h
        dtimes = np.diff(times)
        around = np.concatenate([times[1:-1] - 1e-7 * dtimes[:-1], times[1:-1] + 1e-7 * dtimes[1:]])
        t = np.concatenate([pieces, ends, around, [b[-1]]])
        t = np.clip(t, 0.0, b[-1])
        s = np.clip(profile(t), 0.0, 1.0)
        sd, sdd, sddd = profile(t, 1), profile(t, 2), profile(t, 3)
        q1, q2 = self.spline(s, 1), self.spline(s, 2)
        lim = self.limits
        blk = np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, self.k - 1)
        r_vel = np.max(np.abs(q1) / lim.velocity, axis=1) * sd
        r_vel = np.maximum(r_vel, sd / self.block_cap[blk])
        r_vel = np.maximum(r_vel, np.linalg.norm(self.tip_spline(s, 1), axis=1) * sd / self.tip_feed[blk])
        # Acceleration and jerk split into the tangential part (from the path acceleration and
        # jerk: lowered through the acceleration limit handed to toppra) and the rest (from the
        # path's curvature: lowered through the speed).
        acc_t = q1 * sdd[:, None]
        acc_c = q2 * (sd ** 2)[:, None]
        r_acc = np.max(np.abs(acc_t + acc_c) / lim.acceleration, axis=1)
        share_acc = np.max(np.abs(acc_c) / lim.acceleration, axis=1) / np.maximum(r_acc, 1e-300)
        if self.jerk:
            jerk_t = q1 * sddd[:, None]
            jerk_c = 3.0 * q2 * (sd * sdd)[:, None] + self.spline(s, 3) * (sd ** 3)[:, None]
            r_jerk = np.max(np.abs(jerk_t + jerk_c) / lim.jerk, axis=1)
            share_jerk = np.max(np.abs(jerk_c) / lim.jerk, axis=1) / np.maximum(r_jerk, 1e-300)
        else:
            r_jerk = share_jerk = np.zeros_like(r_acc)
        bad = (r_vel > 1 + _VERIFY_TOL) | (r_acc > 1 + _VERIFY_TOL) | (r_jerk > 1 + _VERIFY_TOL)
        if not np.any(bad):
            return np.empty(0), np.empty(0), np.empty(0)
        r_vel, r_acc, r_jerk = (np.maximum(r[bad], 1.0) for r in (r_vel, r_acc, r_jerk))
        share_acc, share_jerk = share_acc[bad], share_jerk[bad]
        curv_acc = share_acc > 0.5
        curv_jerk = share_jerk > 0.5
        fx = np.minimum(r_vel ** -2.0, np.where(curv_acc, r_acc ** -1.0, 1.0))
        fx = np.minimum(fx, np.where(curv_jerk, r_jerk ** (-2.0 / 3.0), 1.0))
        fa = np.minimum(np.where(curv_acc, 1.0, r_acc ** -1.0), np.where(curv_jerk, 1.0, r_jerk ** -1.0))
        fx = np.where(fx < 1.0, fx * _SHRINK, 1.0)
        fa = np.where(fa < 1.0, fa * _SHRINK, 1.0)
        self.worst = (float(r_vel.max()), float(r_acc.max()), float(r_jerk.max()))
        self.worst_s = float(s[bad][np.argmax(np.maximum(np.maximum(r_vel, r_acc), r_jerk))])
        return s[bad], fx, fa

    def plan(self) -> FeedPlan:
        n = len(self.grid)
        cap = np.full(n, np.inf)
        acc_scale = np.full(n, _ACC_MARGIN if self.jerk else 1.0)
        base = self.xcap * (1.0 - 4e-5)  # toppra may exceed its bounds by rounding: keep clear
        for attempt in range(self.max_refinements + 1):
            x = self._toppra(np.minimum(base, cap), acc_scale)
            profile = self._profile(x)
            times = self._block_times(profile)
            where, fx, fa = self._verify(profile, times)
            if len(where) == 0:
                return FeedPlan(np.diff(times), times, self.s, self.spline, profile, self.w, n, attempt)
            # Lower the caps and the acceleration limit around each violation, in proportion, over
            # the stretch the filter window there can span (twice the erosion radius, and the
            # neighbouring gridpoints).
            nearest = np.clip(np.searchsorted(self.grid, where), 1, n - 1)
            reach = 2.0 * np.maximum(self.radius[nearest], self.radius[nearest - 1])
            lo = np.clip(np.searchsorted(self.grid, where - reach, side="left") - 1, 0, n - 1)
            hi = np.clip(np.searchsorted(self.grid, where + reach, side="right"), 0, n - 1)
            fx_grid = np.minimum(_range_chmin(n, lo, hi, fx), 1.0)
            fa_grid = np.minimum(_range_chmin(n, lo, hi, fa), 1.0)
            cap = np.minimum(cap, np.where(fx_grid < 1.0, fx_grid * np.maximum(x, 0.0), np.inf))
            acc_scale = acc_scale * fa_grid
            logger.debug("feed plan round %d: %d samples over the limits, worst (vel, acc, jerk) ratios %s",
                         attempt, len(where), self.worst)
        index = self._waypoint_at(self.worst_s)
        kinds = ("velocity or feed", "acceleration", "jerk")
        ratios = self.worst
        kind = kinds[int(np.argmax(ratios))]
        raise PlanningError(f"no time law within the joint {kind} limits found near waypoint {index} after "
                            f"{self.max_refinements} refinements (worst ratio {max(ratios):.3f}): the "
                            f"jerk/acceleration limits cannot be met along this path", index)


def _filtered_profile(t: np.ndarray, grid: np.ndarray, v: np.ndarray, u: np.ndarray, w: float) -> PPoly:
    """Moving average of width w of the piecewise-quadratic sigma(t); returns s(t) on [0, T + w].

    sigma(t) = grid[i] + v[i] tau + u[i] tau^2 / 2 on [t[i], t[i + 1]], 0 before, 1 after.
    s(t) = 1/w int_{t-w}^{t} sigma is piecewise cubic with breakpoints t and t + w. Integrals of
    sigma are accumulated in long double so long sequences keep ~1e-16 precision in s.
    """
    n = len(t) - 1
    dt = np.diff(t)
    s0 = grid[:-1]
    v0 = v[:-1]
    piece = s0 * dt + v0 * dt ** 2 / 2.0 + u * dt ** 3 / 6.0
    prefix = np.concatenate([[0.0], np.cumsum(piece.astype(np.longdouble))])
    total_t = float(t[-1])

    def locate(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        i = np.clip(np.searchsorted(t, x, side="right") - 1, 0, n - 1)
        return i, x - t[i]

    def sigma_derivs(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        i, tau = locate(x)
        before, after = x < 0.0, x >= total_t
        s = s0[i] + v0[i] * tau + u[i] * tau ** 2 / 2.0
        sd = v0[i] + u[i] * tau
        sdd = u[i].copy()
        s = np.where(before, 0.0, np.where(after, 1.0, s))
        sd = np.where(before | after, 0.0, sd)
        sdd = np.where(before | after, 0.0, sdd)
        return s, sd, sdd

    def integral(x: np.ndarray) -> np.ndarray:
        """int_0^x sigma, long double."""
        i, tau = locate(x)
        local = s0[i] * tau + v0[i] * tau ** 2 / 2.0 + u[i] * tau ** 3 / 6.0
        out = prefix[i] + local.astype(np.longdouble)
        out = np.where(x <= 0.0, np.longdouble(0.0), out)
        return np.where(x >= total_t, prefix[-1] + (x - total_t).astype(np.longdouble), out)

    breaks = np.unique(np.concatenate([t, t + w]))
    # Breakpoints t[i] and t[j] + w can nearly coincide: a sliver piece between them would get its
    # third derivative from the wrong side by rounding. Pieces under a nanosecond are merged.
    keep = np.concatenate([[True], np.diff(breaks) > 1e-9])
    if not keep[-1]:
        keep[np.flatnonzero(keep)[-1]] = len(np.flatnonzero(keep)) == 1
        keep[-1] = True
    breaks = breaks[keep]
    left = breaks[:-1]
    mid = left + 0.5 * np.diff(breaks)
    value = ((integral(left) - integral(left - w)) / np.longdouble(w)).astype(float)
    a1, b1, _ = sigma_derivs(left)
    a0, b0, _ = sigma_derivs(left - w)
    _, _, c1 = sigma_derivs(mid)
    _, _, c0 = sigma_derivs(mid - w)
    first = (a1 - a0) / w
    second = (b1 - b0) / w
    third = (c1 - c0) / w
    return PPoly(np.stack([third / 6.0, second / 2.0, first, value]), breaks, extrapolate=True)


def _invert_profile(profile: PPoly, targets: np.ndarray) -> np.ndarray:
    """Times at which the nondecreasing s(t) reaches each of the (sorted) targets."""
    if len(targets) == 0:
        return np.empty(0)
    b = profile.x
    c = profile.c
    if c.shape[0] < 4:
        c = np.vstack([np.zeros((4 - c.shape[0], c.shape[1])), c])
    at_breaks = np.maximum.accumulate(profile(b))
    m = np.clip(np.searchsorted(at_breaks, targets, side="right") - 1, 0, len(b) - 2)
    h = b[m + 1] - b[m]
    c3, c2, c1, c0 = c[0, m], c[1, m], c[2, m], c[3, m]
    lo = np.zeros_like(targets)
    hi = h.copy()
    span = at_breaks[m + 1] - at_breaks[m]
    with np.errstate(divide="ignore", invalid="ignore"):
        tau = np.where(span > 0, h * (targets - at_breaks[m]) / span, 0.5 * h)
    tau = np.clip(tau, lo, hi)
    for _ in range(60):
        f = ((c3 * tau + c2) * tau + c1) * tau + c0 - targets
        df = (3.0 * c3 * tau + 2.0 * c2) * tau + c1
        lo = np.where(f < 0, tau, lo)
        hi = np.where(f > 0, tau, hi)
        with np.errstate(divide="ignore", invalid="ignore"):
            newton = tau - f / df
        ok = (df > 0) & (newton > lo) & (newton < hi)
        new = np.where(ok, newton, 0.5 * (lo + hi))
        done = (f == 0) | (np.abs(new - tau) <= 1e-15 * np.maximum(h, 1.0))
        tau = np.where(f == 0, tau, new)
        if np.all(done):
            break
    return b[m] + tau


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

    @property
    def total(self) -> float:
        return self.duration

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
        return RapidPlan(start, start.copy(), 0.0, None)
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
    result = Ruckig(DOF).calculate(inp, trajectory)
    if result not in (Result.Working, Result.Finished):
        raise PlanningError(f"ruckig could not plan the rapid from {start.tolist()} to {end.tolist()}: {result}")
    return RapidPlan(start, end, float(trajectory.duration), trajectory)
