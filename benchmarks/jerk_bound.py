"""A lower bound on the time of any jerk-limited plan of a feed sequence, rest to rest.

No time law along the sequence, however planned, can be faster than this bound: the benchmark's
measure of how much of the jerk cost is left to win (``T / LB3``), and of what a target such as
``T / T0 <= 1.02`` asks (``LB3 / T0``, T0 being the plan without jerk limits).

Units: joints (K + 1, 5) mm and rad, tips (K + 1, 3) mm, feeds (K,) mm/s, times s, limits per
second. A sequence starts and ends at rest with zero acceleration (its jerk is bounded, so its
acceleration is continuous, and the machine stood still before it). Per sequence the bound is
the largest of three:

- LB (:func:`verne_post.planning.timing.lower_bound_time`): per block, each joint's displacement at its
  velocity limit, the tip's chord at the block's feed; no acceleration at all.
- Rest to rest: each joint makes its net displacement ``|q_j(end) - q_j(0)|`` from rest to rest
  within its velocity, acceleration and jerk limits, which takes at least the time of the
  7-segment S-curve over that distance.
- Start and end: from rest, a joint's speed after t is at most
  ``vr(t) = min(v, integral_0^t min(J tau, a) dtau)``, so after t it has moved at most
  ``reach(t) = integral_0^t vr``; the first k blocks take at least the time ``reach`` needs to
  make each joint's displacement over them. Where that is more than their share of LB, the
  difference is added to LB; likewise the last m blocks, time reversed. The start looks at the
  first half of the blocks, the end at the second half, so the two never count a block twice;
  each k and m gives a bound, the largest is taken.

The tip feed enters the last two the same way: along block i the controller moves the joints in
proportion, so the tip moves at ``l_i / |dq_ij|`` times joint j's speed (l_i its chord; the tip
stays within the chordal tolerance of it), at most ``rho_j`` times it with rho_j the largest such
ratio over the blocks looked at. The tip's path is at least the sum of the chords, and its speed
at most ``min(F, rho_j vr_j(t))``: a joint with limits ``rho_j (v_j, a_j, J_j)`` capped at the
highest feed F. The joint terms hold for any path through the waypoints; the tip terms up to
that chordal approximation. Rotary-only blocks (the tip still) give no tip term.

Everything is vectorised over all the blocks of all the sequences together.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from verne_post.planning.timing import TIP_EPS, Limits, block_min_time, checked_sequence, rest_to_rest

__all__ = ["jerk_lower_bounds", "rest_to_rest_time", "time_from_rest"]


def time_from_rest(distance: np.ndarray, v: np.ndarray, a: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Least time (s) to cover ``distance`` from rest, the end speed free, with speed, acceleration
    and jerk at most v, a, j: the inverse of ``reach`` (module docstring), in closed form.

    The speed bound runs up ``j t^2 / 2`` until ``t = a / j``, then ``a t - a^2 / (2 j)``, then
    stays at v from the time ``t_v`` it reaches it. All arguments broadcast; positive limits.
    """
    distance, v, a, j = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (distance, v, a, j)))
    knee = a * a / (2.0 * j)  # speed when the acceleration reaches a
    t_a = a / j
    t_v = np.where(v <= knee, np.sqrt(2.0 * v / j), (v + knee) / a)
    t_1 = np.minimum(t_a, t_v)  # end of the jerk phase
    d_1 = j * t_1 ** 3 / 6.0
    late = np.maximum(t_v - t_a, 0.0)  # duration of the acceleration phase, if any
    d_v = d_1 + knee * late + 0.5 * a * late ** 2  # distance when the speed reaches v
    with np.errstate(invalid="ignore", divide="ignore"):
        jerk_phase = np.cbrt(6.0 * distance / j)
        accel_phase = t_a + (np.sqrt(knee * knee + 2.0 * a * (distance - d_1)) - knee) / a
        cruise = t_v + (distance - d_v) / v
    return np.where(distance >= d_v, cruise, np.where(distance <= d_1, jerk_phase, accel_phase))


def rest_to_rest_time(distance: np.ndarray, v: np.ndarray, a: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Time (s) of the time-optimal move over ``distance`` from rest to rest with speed,
    acceleration and jerk at most v, a, j (one axis): the 7-segment S-curve
    (:func:`verne_post.planning.timing.rest_to_rest`), broadcast."""
    return rest_to_rest(*np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (distance, v, a, j)))).total


def _segment_scan(values: np.ndarray, seq: np.ndarray, op: np.ufunc) -> np.ndarray:
    """Running ``op`` (np.add, np.maximum) of ``values`` (N, ...) within each run of equal ``seq``
    (nondecreasing), by doubling: log2(longest run) vectorised steps."""
    out = values.copy()
    shift = 1
    while shift < len(out):
        same = seq[shift:] == seq[:-shift]
        if not same.any():
            break
        mask = same.reshape(-1, *([1] * (out.ndim - 1)))
        out[shift:] = np.where(mask, op(out[shift:], out[:-shift]), out[shift:])
        shift *= 2
    return out


def _least_time(move: Callable[..., np.ndarray], displacement: np.ndarray, tip_path: np.ndarray,
                fastest: np.ndarray, rho: np.ndarray, limits: Limits) -> np.ndarray:
    """Per row, the least time ``move`` (:func:`time_from_rest` or :func:`rest_to_rest_time`)
    allows for joint displacements (n, 5) and a tip path (n,) mm at feeds up to ``fastest``
    (n,) mm/s, the tip moving at most ``rho`` (n, 5) times each joint's speed (module
    docstring); a joint with no finite positive ratio gives no tip term."""
    need = np.max(move(displacement, limits.velocity, limits.acceleration, limits.jerk), axis=1)
    usable = np.isfinite(rho) & (rho > 0)
    r = np.where(usable, rho, 1.0)
    tip = move(tip_path[:, None], np.minimum(fastest[:, None], r * limits.velocity), r * limits.acceleration,
               r * limits.jerk)
    return np.maximum(need, np.max(np.where(usable, tip, 0.0), axis=1))


def _start_gains(dq: np.ndarray, chord: np.ndarray, feed: np.ndarray, block_time: np.ndarray,
                 tip_ratio: np.ndarray, seq: np.ndarray, allowed: np.ndarray, count: int,
                 limits: Limits) -> np.ndarray:
    """Per sequence, the most the first k blocks (k <= ``allowed`` of that sequence) take over
    their share of LB, from rest (module docstring); 0 if never more."""
    position = np.arange(len(seq)) - np.searchsorted(seq, seq)  # block index within its sequence
    displacement = np.abs(_segment_scan(dq, seq, np.add))
    tip_path = _segment_scan(chord, seq, np.add)
    fastest = _segment_scan(feed, seq, np.maximum)
    rho = _segment_scan(tip_ratio, seq, np.maximum)
    share = _segment_scan(block_time, seq, np.add)
    need = _least_time(time_from_rest, displacement, tip_path, fastest, rho, limits)
    gain = np.where(position < allowed[seq], need - share, 0.0)
    out = np.zeros(count)
    np.maximum.at(out, seq, gain)
    return out


def jerk_lower_bounds(sequences: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]], limits: Limits, *,
                      angular_feed: float | None = None) -> np.ndarray:
    """Per sequence ``(joints (K + 1, 5) mm/rad, tip (K + 1, 3) mm, feed (K,) mm/s)``, a lower
    bound (s) on the time of any plan within the joint velocity, acceleration and jerk limits and
    the feeds, from rest to rest (module docstring); ``angular_feed`` (rad/s) caps rotary-only
    blocks as in :func:`verne_post.planning.timing.lower_bound_time`."""
    checked = [checked_sequence(*sequence) for sequence in sequences]
    count = len(checked)
    sizes = np.array([len(feed) for _, _, feed in checked])
    seq = np.repeat(np.arange(count), sizes)
    dq = np.concatenate([np.diff(joints, axis=0) for joints, _, _ in checked])
    dtip = np.concatenate([np.diff(tip, axis=0) for _, tip, _ in checked])
    feed = np.concatenate([feed for _, _, feed in checked])
    net = np.abs(np.array([joints[-1] - joints[0] for joints, _, _ in checked])).reshape(count, 5)
    block_time = block_min_time(dq, dtip, feed, limits, angular_feed=angular_feed)
    velocity_bound = np.bincount(seq, block_time, minlength=count)
    chord = np.linalg.norm(dtip, axis=1)
    moving_tip = chord >= TIP_EPS
    chord = np.where(moving_tip, chord, 0.0)
    with np.errstate(divide="ignore"):
        tip_ratio = np.where(moving_tip[:, None] & (dq != 0), chord[:, None] / np.abs(dq), np.inf)

    # The whole sequence, rest to rest: each joint's net displacement, and the tip's path.
    rho = np.full((count, 5), -np.inf)
    np.maximum.at(rho, seq, tip_ratio)
    fastest = np.zeros(count)
    np.maximum.at(fastest, seq, feed)
    whole = _least_time(rest_to_rest_time, net, np.bincount(seq, chord, minlength=count), fastest, rho, limits)

    # Start (the first half of the blocks) and end (the second half, time reversed).
    half = sizes // 2
    start = _start_gains(dq, chord, feed, block_time, tip_ratio, seq, half, count, limits)
    end = _start_gains(dq[::-1], chord[::-1], feed[::-1], block_time[::-1], tip_ratio[::-1],
                       count - 1 - seq[::-1], (sizes - half)[::-1], count, limits)[::-1]
    return np.maximum(whole, velocity_bound + start + end)
