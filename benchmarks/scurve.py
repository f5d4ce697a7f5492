"""A jerk-limited look-ahead baseline: per-block S-curve feed, as controllers with S-curve planning run G-code.

The block model is :func:`verne_post.planning.timing.baseline_time`'s (the trapezoidal baseline), kept here
on its own so the baseline does not move with the planner: per block a speed (the feed, clamped
so that no joint exceeds its velocity limit, the joints moving proportionally along the block),
a tangential acceleration and jerk (what the dominating joint allows); at a junction at most the
lower of the two speeds and the speed whose joint velocity jump stays within what each joint's
acceleration gives in one interpolation ``cycle``; rest at the start, the end and around
rotary-only blocks. What differs: every speed change is a 7-segment jerk-limited S-curve that
starts and ends with zero acceleration. Changing the speed by dv under a and J takes

    t = 2 sqrt(dv / J)           if dv <= a^2 / J  (the acceleration never reaches a)
    t = dv / a + a / J           otherwise

over the distance (v0 + v1) / 2 * t (the profile is point-symmetric about its middle). A backward
then a forward pass make every block's entry and exit speeds reachable within its length; each
block then accelerates to the highest speed it can reach (at most its own), cruises and slows down.

Units: joints (K + 1, 5) mm and rad, tips (K + 1, 3) mm, feeds (K,) mm/s, ``angular_feed`` rad/s.
"""

from __future__ import annotations

import math

import numpy as np

from verne_post.planning.timing import TIP_EPS, Limits

__all__ = ["ramp_distance", "ramp_time", "scurve_baseline_time"]


def ramp_time(v0: np.ndarray | float, v1: np.ndarray | float, a: np.ndarray | float, j: np.ndarray | float
              ) -> np.ndarray:
    """Time (s) of the jerk-limited S-curve from speed v0 to v1 (acceleration zero at both ends)."""
    dv = np.abs(np.asarray(v1, dtype=float) - v0)
    return np.where(dv * j <= np.square(a), 2.0 * np.sqrt(dv / j), dv / a + a / j)


def ramp_distance(v0: np.ndarray | float, v1: np.ndarray | float, a: np.ndarray | float, j: np.ndarray | float
                  ) -> np.ndarray:
    """Distance covered by that S-curve."""
    return 0.5 * (np.asarray(v0, dtype=float) + v1) * ramp_time(v0, v1, a, j)


def _fastest_from(v: float, length: float, a: float, j: float) -> float:
    """The highest speed from (or to) which speed ``v`` is reached within ``length``.

    The distance grows with the speed change dv. Within the jerk phases (dv <= a^2/J) it is
    (2 v + dv) sqrt(dv / J): with x = sqrt(dv), x^3 + 2 v x - length sqrt(J) = 0, one real root.
    Beyond, (2 v + dv) / 2 (dv / a + a / J): a quadratic in dv.
    """
    knee = a * a / j
    if (2.0 * v + knee) * a / j >= length:
        p, q = 2.0 * v, length * math.sqrt(j)
        if p == 0:
            x = q ** (1 / 3)
        else:  # x = 2 sqrt(p/3) sinh(theta) turns x^3 + p x = q into sinh(3 theta) = q/2 (3/p)^1.5
            x = 2.0 * math.sqrt(p / 3.0) * math.sinh(math.asinh(0.5 * q * (3.0 / p) ** 1.5) / 3.0)
        return v + x * x
    b = v / a + 0.5 * a / j
    c = v * a / j - length  # < 0 here
    return v - 2.0 * c / (b + math.sqrt(b * b - 2.0 * c / a))  # the positive root, without cancellation


def scurve_baseline_time(joints: np.ndarray, tip: np.ndarray, feed: np.ndarray, limits: Limits, *,
                         angular_feed: float | None = None, cycle: float = 0.002) -> float:
    """Time (s) of the sequence under jerk-limited look-ahead S-curve planning (module docstring).

    Same inputs as :func:`verne_post.planning.timing.baseline_time`: joints (K + 1, 5) mm/rad, tips (K + 1, 3)
    mm, feed (K,) mm/s per block, ``angular_feed`` rad/s for rotary-only blocks, ``cycle`` s.
    """
    joints = np.asarray(joints, dtype=float)
    tip = np.asarray(tip, dtype=float)
    feed = np.asarray(feed, dtype=float).reshape(-1)
    if joints.ndim != 2 or joints.shape[1] != 5 or len(joints) < 2 or tip.shape != (len(joints), 3) \
            or feed.shape != (len(joints) - 1,):
        raise ValueError(f"joints (K + 1, 5), tip (K + 1, 3) and feed (K,) expected, got {joints.shape}, "
                         f"{tip.shape}, {feed.shape}")
    dq = np.diff(joints, axis=0)
    length = np.linalg.norm(np.diff(tip, axis=0), axis=1)
    rotary_only = length < TIP_EPS
    rotary = np.linalg.norm(dq[:, 3:], axis=1)
    ell = np.where(rotary_only, np.linalg.norm(dq / limits.velocity, axis=1), length)  # mm, or s at the limits
    if np.any(ell <= 0):
        raise ValueError(f"block {int(np.flatnonzero(ell <= 0)[0])} has no motion")
    adq = np.abs(dq)
    with np.errstate(divide="ignore", invalid="ignore"):
        per_joint = np.where(adq > 0, ell[:, None] / adq, np.inf)  # path length per unit of each joint
        rate = dq / ell[:, None]  # joint motion per unit of path
        speed = np.min(limits.velocity * per_joint, axis=1)
        accel = np.min(limits.acceleration * per_joint, axis=1)
        jerk = np.min(limits.jerk * per_joint, axis=1)
        speed = np.where(rotary_only, speed, np.minimum(speed, feed))
        if angular_feed is not None:
            speed = np.where(rotary_only & (rotary > 0), np.minimum(speed, angular_feed * ell / rotary), speed)
        jump = np.abs(rate[1:] - rate[:-1])
        allowed = np.min(np.where(jump > 0, limits.acceleration * cycle / jump, np.inf), axis=1)
    junction = np.zeros(len(ell) + 1)
    same_kind = rotary_only[:-1] == rotary_only[1:]
    junction[1:-1] = np.where(same_kind, np.minimum(np.minimum(speed[:-1], speed[1:]), allowed), 0.0)
    v = junction.tolist()
    ell_, a_, j_ = ell.tolist(), accel.tolist(), jerk.tolist()
    for i in range(len(ell_) - 1, -1, -1):  # slow down in time for what follows
        v[i] = min(v[i], _fastest_from(v[i + 1], ell_[i], a_[i], j_[i]))
    for i in range(len(ell_)):  # and only as fast as the block before can reach
        v[i + 1] = min(v[i + 1], _fastest_from(v[i], ell_[i], a_[i], j_[i]))
    v0, v1 = np.array(v[:-1]), np.array(v[1:])

    def ramps(peak: np.ndarray) -> np.ndarray:
        return ramp_distance(v0, peak, accel, jerk) + ramp_distance(peak, v1, accel, jerk)

    # The peak speed: the block's own where it fits, else the highest whose two ramps fit in the
    # block (the passes made the lower end, max(v0, v1), fit), by bisection on all blocks at once.
    low, high = np.maximum(v0, v1), speed.copy()
    fits = ramps(high) <= ell
    low = np.where(fits, high, low)
    for _ in range(100):
        middle = 0.5 * (low + high)
        ok = ramps(middle) <= ell
        low, high = np.where(ok, middle, low), np.where(ok, high, middle)
        if np.all(high - low <= 1e-12 * high):
            break
    peak = low
    cruise = np.maximum(ell - ramps(peak), 0.0) / peak
    return float(np.sum(ramp_time(v0, peak, accel, jerk) + ramp_time(peak, v1, accel, jerk) + cruise))
