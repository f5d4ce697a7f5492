"""S-curves along a path: the one-block sequences, in closed form, and short moves such as
re-orientations."""

from __future__ import annotations

import numpy as np

from ..timing import rest_to_rest
from .batch import Batch
from .plan import Cubics, FeedPlan
from .profiles import Profiles

# --------------------------------------------------------------------------------------------
# S-curves along a path: short moves such as re-orientations
# --------------------------------------------------------------------------------------------
#
# A short sequence (a re-orientation of the table over a few blocks) has no cruise worth the
# name: the filtered TOPP2 profile spends a filter width on each of its few corners, and a turn
# without cruise costs a plateau (feed_planner's docstring, step 4). Its time-optimal third-order law is
# close to an S-curve in s whose phases each have their own limits: the ramp up at the
# acceleration the stretch it covers allows, the ramp down at its own, and each of the four jerk
# phases at the jerk left where the path's curvature takes part of the joint jerk (the terms
# 3 q'' sdot sddot + q''' sdot^3). Each phase's limits are the tangential ones over the path
# parameters it covers (min over joints of a_j / |q_j'|, J_j / |q_j'|) times a factor of that
# phase, lowered by every excess found at its samples, until no sample exceeds a limit; the
# plan is then verified as every other plan (verification.verify) and kept only if it is faster.
# The 105k job's 342 re-orientations take 96.7 s instead of 100.2 s (the filtered plans), 2.3 %
# above their jerk-limited lower bound (benchmarks/jerk_bound.py) in all; on one of them copp-py's
# TOPP3-LP (benchmarks/topp3.py) gets 0.2707 s, this 0.2743 s, the filter 0.2948 s.

_SCURVE_ROUNDS = 8
_SCURVE_SAMPLES = 9  # per phase, both ends included
SCURVE_MARGIN = 1.001  # a limit is lowered a little past the excess found at the samples
_SCURVE_START_SAMPLES = 64  # uniform path samples for the first limits


class _Ramps:
    """Ramps from rest to a speed with the acceleration at most ``acc``, its jerk ``rise`` while the
    acceleration grows and ``fall`` while it returns to 0 (any unit of length; all per s^k), at
    many speeds in turn: what does not depend on the speed is computed once."""

    def __init__(self, acc: np.ndarray, rise: np.ndarray, fall: np.ndarray) -> None:
        self.acc, self.rise, self.fall = acc, rise, fall
        self.bend = 0.5 / rise + 0.5 / fall  # speed gained over the two jerk phases, per acceleration^2
        self.reach = acc ** 2 * self.bend  # the speed at the end of two jerk phases to acc

    def phases(self, speed: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """To ``speed``: the durations (s) of the three phases, the middle one at constant
        acceleration, and the distance covered."""
        acc, rise, fall, bend = self.acc, self.rise, self.fall, self.bend
        full = speed >= self.reach
        peak = np.where(full, acc, np.sqrt(speed / bend))
        t1, t3 = peak / rise, peak / fall
        t2 = np.where(full, (speed - self.reach) / acc, 0.0)  # peak is acc there: (speed - peak^2 bend) / peak
        v1 = rise * t1 ** 2 / 2.0
        v2 = v1 + peak * t2
        distance = (rise * t1 ** 3 / 6.0 + v1 * t2 + peak * t2 ** 2 / 2.0
                    + v2 * t3 + peak * t3 ** 2 / 2.0 - fall * t3 ** 3 / 6.0)
        return t1, t2, t3, distance

    def distance(self, speed: np.ndarray) -> np.ndarray:
        """The distance covered to ``speed`` (any unit of length, per s)."""
        return self.phases(speed)[3]


def _scurve(cap: np.ndarray, acc: np.ndarray, jerk: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rest to rest over s in [0, 1], row by row: the ramp up under acc[:, 0] with the jerks
    jerk[:, 0] (rising) and jerk[:, 1], a cruise at the peak speed (at most ``cap``, 1/s), the
    ramp down under acc[:, 1] with the jerks jerk[:, 2] and jerk[:, 3] (the last, back to rest).
    Returns the 7 phase durations (S, 7) in s, their path jerks (S, 7) and the peak speed (S,)."""
    # The bisection's 32 steps each need both ramps at the same speeds: as one array (the ramp
    # up in the first S rows, the ramp down in the last S), half the numpy calls, the same
    # values element by element.
    count = len(cap)
    ramps = _Ramps(np.concatenate([acc[:, 0], acc[:, 1]]), np.concatenate([jerk[:, 0], jerk[:, 3]]),
                   np.concatenate([jerk[:, 1], jerk[:, 2]]))

    def covered(v: np.ndarray) -> np.ndarray:
        both = ramps.distance(np.concatenate([v, v]))
        return both[:count] + both[count:]

    # Two ramps to v cover at least v^2 / (2 acc) each: the peak is below the speed where those make 1.
    low, high = np.zeros_like(cap), np.minimum(cap, np.sqrt(2.0 / (1.0 / acc[:, 0] + 1.0 / acc[:, 1])))
    short = covered(cap) > 1.0
    for _ in range(32):  # the peak whose two ramps cover the whole distance (covered grows with it)
        mid = 0.5 * (low + high)
        over = covered(mid) > 1.0
        low, high = np.where(over, low, mid), np.where(over, mid, high)
    speed = np.where(short, low, cap)
    ramp_up, ramp_down = zip(*(np.split(x, [count]) for x in ramps.phases(np.concatenate([speed, speed]))),
                             strict=True)
    a1, a2, a3, up = ramp_up
    d1, d2, d3, down = ramp_down
    cruise = np.maximum(1.0 - up - down, 0.0) / speed
    zero = np.zeros_like(speed)
    durations = np.stack([a1, a2, a3, cruise, d3, d2, d1], axis=1)
    jerks = np.stack([jerk[:, 0], zero, -jerk[:, 1], zero, -jerk[:, 2], zero, jerk[:, 3]], axis=1)
    return durations, jerks, speed


def phase_starts(durations: np.ndarray, jerks: np.ndarray, acc: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """s, sdot, sddot at the start of each phase (S, P), from rest at s = 0: the acceleration
    integrated from the jerks, or ``acc`` where it is given (a trapezoid's steps)."""
    s, v = np.zeros(durations.shape), np.zeros(durations.shape)
    a = np.zeros(durations.shape) if acc is None else acc
    for k in range(durations.shape[1] - 1):
        h, j = durations[:, k], jerks[:, k]
        s[:, k + 1] = s[:, k] + v[:, k] * h + a[:, k] * h ** 2 / 2.0 + j * h ** 3 / 6.0
        v[:, k + 1] = v[:, k] + a[:, k] * h + j * h ** 2 / 2.0
        if acc is None:
            a[:, k + 1] = a[:, k] + j * h
    return s, v, a


def scurve_laws(batch: Batch, seqs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per sequence of ``seqs``, the fastest S-curve (:func:`_scurve`) found within every limit
    at its samples: phase durations (S, 7), s, and path jerks (S, 7); durations inf where none."""
    lim = batch.limits
    count = len(seqs)
    uniform = np.linspace(0.0, 1.0, _SCURVE_START_SAMPLES)
    x, tangent = batch.point_cap(np.repeat(seqs, len(uniform)), np.tile(uniform, count))
    cap = np.sqrt(np.min(x.reshape(count, -1), axis=1))
    with np.errstate(divide="ignore"):  # a joint that does not move limits nothing
        acc = np.min(lim.acceleration[:, None] / tangent, axis=0).reshape(count, -1).min(axis=1)
        jerk = np.min(lim.jerk[:, None] / tangent, axis=0).reshape(count, -1).min(axis=1)
    acc, jerk = np.repeat(acc[:, None], 2, axis=1), np.repeat(jerk[:, None], 4, axis=1)
    acc_factor, jerk_factor = np.ones((count, 2)), np.ones((count, 4))
    best_durations, best_jerks = np.full((count, 7), np.inf), np.zeros((count, 7))
    fraction = np.linspace(0.0, 1.0, _SCURVE_SAMPLES)
    sample_seq = np.repeat(seqs, 7 * _SCURVE_SAMPLES)
    shape = (count, 7, _SCURVE_SAMPLES)
    for _ in range(_SCURVE_ROUNDS):
        durations, jerks, peak = _scurve(cap, acc, jerk)
        s0, v0, a0 = (state[:, :, None] for state in phase_starts(durations, jerks))
        tau, j = durations[:, :, None] * fraction, jerks[:, :, None]
        s = np.clip(s0 + v0 * tau + a0 * tau ** 2 / 2.0 + j * tau ** 3 / 6.0, 0.0, 1.0).ravel()
        sd = (v0 + a0 * tau + j * tau ** 2 / 2.0).ravel()
        sdd = (a0 + j * tau).ravel()
        sddd = np.broadcast_to(j, shape).ravel()
        q1, q2, q3 = batch.path.derivatives(batch.path.locate(sample_seq, s), s, (1, 2, 3))
        speed_ratio = (sd / np.sqrt(batch.point_cap(sample_seq, s)[0])).reshape(shape)
        acc_ratio = np.max(np.abs(q1 * sdd + q2 * sd ** 2) / lim.acceleration[:, None], axis=0).reshape(shape)
        jerk_ratio = np.max(np.abs(q1 * sddd + 3.0 * q2 * sd * sdd + q3 * sd ** 3) / lim.jerk[:, None],
                            axis=0).reshape(shape)
        worst = np.maximum(np.maximum(speed_ratio, acc_ratio), jerk_ratio).max(axis=(1, 2))
        better = (worst <= 1.0) & (durations.sum(axis=1) < best_durations.sum(axis=1))
        best_durations[better], best_jerks[better] = durations[better], jerks[better]
        # Next: the speed capped below any excess; each phase's limits the tangential ones over
        # the stretch it now covers, times its factor, lowered past any excess it had.
        with np.errstate(divide="ignore"):
            tangent_acc = np.min(lim.acceleration[:, None] / np.abs(q1), axis=0).reshape(shape)
            tangent_jerk = np.min(lim.jerk[:, None] / np.abs(q1), axis=0).reshape(shape)
        excess = speed_ratio.max(axis=(1, 2))
        cap = np.where(excess > 1.0, np.minimum(cap, peak) / (excess * SCURVE_MARGIN), cap)
        for k, half in enumerate((slice(0, 3), slice(4, 7))):
            excess = acc_ratio[:, half].max(axis=(1, 2))
            acc_factor[:, k] /= np.where(excess > 1.0, excess * SCURVE_MARGIN, 1.0)
            acc[:, k] = acc_factor[:, k] * tangent_acc[:, half].min(axis=(1, 2))
        for k, phase in enumerate((0, 2, 4, 6)):
            excess = jerk_ratio[:, phase].max(axis=1)
            jerk_factor[:, k] /= np.where(excess > 1.0, excess * SCURVE_MARGIN, 1.0)
            jerk[:, k] = jerk_factor[:, k] * tangent_jerk[:, phase].min(axis=1)
    return best_durations, best_jerks


def scurve_profiles(seqs: np.ndarray, durations: np.ndarray, jerks: np.ndarray) -> Profiles:
    """The S-curves (:func:`_scurve`) of the sequences ``seqs`` as profiles (phases of no duration left out)."""
    s0, v0, a0 = phase_starts(durations, jerks)
    keep = durations > 0
    bfirst = np.r_[0, np.cumsum(keep.sum(axis=1) + 1)]
    breaks = np.empty(bfirst[-1])
    ends = bfirst[1:] - 1
    breaks[np.delete(np.arange(len(breaks)), ends)] = (np.cumsum(durations, axis=1) - durations)[keep]
    breaks[ends] = durations.sum(axis=1)
    return Profiles(seqs, breaks, bfirst, np.stack([jerks[keep] / 6.0, a0[keep] / 2.0, v0[keep], s0[keep]]))


# --------------------------------------------------------------------------------------------
# One-block sequences: in closed form
# --------------------------------------------------------------------------------------------


def straight_plans(batch: Batch) -> list[FeedPlan]:
    """Plans of one-block sequences (the batch holds only those).

    A block is a line in joint space, q(s) = q0 + s dq for s in [0, 1], and the tip's spline
    through two points the chord: every cap is the same all along it. The time-optimal move
    from rest to rest is then known exactly: the 7-segment S-curve in s (the trapezoid without
    jerk limits) under the path speed of :meth:`Batch.point_cap`, the path acceleration
    ``min_j a_j / |dq_j|`` and the path jerk ``min_j J_j / |dq_j|``, at the limits themselves.
    Its peaks are those limits, exactly (the peak ratios are computed, not sampled).
    """
    count = batch.count
    lim = batch.limits
    x, slope = batch.point_cap(np.arange(count), np.full(count, 0.5))  # slope (5, M): |dq| (s spans 1)
    with np.errstate(divide="ignore"):
        acc = np.min(lim.acceleration[:, None] / slope, axis=0)
        jerk = np.min(lim.jerk[:, None] / slope, axis=0) if batch.jerk else np.full(count, np.inf)
    move = rest_to_rest(np.ones(count), np.sqrt(x), acc, jerk)
    top, peak_acc, tj, ta = move.peak_speed, move.peak_acceleration, move.jerk_time, move.acceleration_time
    # Segments: jerk up, hold, jerk down, cruise, then the mirror; acceleration at each start.
    durations = np.stack([tj, ta, tj, move.cruise_time, tj, ta, tj], axis=1)
    zero = np.zeros(count)
    start_acc = np.stack([zero, peak_acc, peak_acc, zero, zero, -peak_acc, -peak_acc], axis=1)
    j = np.where(np.isfinite(jerk), jerk, 0.0)
    seg_jerk = np.stack([j, zero, -j, zero, -j, zero, j], axis=1)
    start_s, start_v, _ = phase_starts(durations, seg_jerk, start_acc)
    ratios = np.stack([top * slope / lim.velocity[:, None], peak_acc * slope / lim.acceleration[:, None],
                       (jerk * slope / lim.jerk[:, None]) if batch.jerk else np.zeros_like(slope)], axis=1)
    plans = []
    for r in range(count):
        keep = durations[r] > 0
        breaks = np.r_[0.0, np.cumsum(durations[r, keep])]
        coef = np.stack([seg_jerk[r, keep] / 6.0, start_acc[r, keep] / 2.0, start_v[r, keep], start_s[r, keep]])
        total = breaks[-1]
        plans.append(FeedPlan(np.array([total]), np.array([0.0, total]), *batch.sequence_path(r), Cubics(breaks, coef),
                              float(tj[r]), 0, 0, ratios[:, :, r].T.copy()))
    return plans
