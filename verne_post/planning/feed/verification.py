"""The verification of a plan: when each waypoint is reached, and every limit at samples of
the time law (a plan is kept only within every limit)."""

from __future__ import annotations

import numpy as np

from ..timing import DOF, PlanningError
from .batch import Batch
from .profiles import Profiles
from .segments import Pieces, ranges

_MAX_PIECE_SAMPLES = 64  # verification samples per piece of the time law (see verify)
# Samples evaluated together: a chunk's (5, n) arrays (330 kB each) stay in a core's cache, where
# 65,536 samples' (2.6 MB) did not: the 105k job's verification 45 % faster (CPU). Chunks change
# no result (each sample is evaluated on its own; the peaks are maxima).
_VERIFY_CHUNK = 1 << 13
VERIFY_TOL = 1e-6  # relative excess tolerated by the verification (rounding)
_SHRINK = 0.97  # extra factor applied when lowering caps after a violation


def block_times(batch: Batch, profiles: Profiles) -> tuple[tuple[np.ndarray, np.ndarray], dict[int, PlanningError]]:
    """Times at which each sequence's s(t) reaches its waypoints: (times, offsets per sequence)."""
    pieces = profiles.pieces
    count = len(profiles.seqs)
    # s at every break (the end: the last piece at its end), made nondecreasing per sequence.
    at = np.empty(len(profiles.breaks))
    starts = np.delete(np.arange(len(at)), profiles.bfirst[1:] - 1)
    at[starts] = pieces.coef[3]
    ends = profiles.bfirst[1:] - 1
    last_piece = pieces.first[1:] - 1
    at[ends] = pieces(last_piece, profiles.breaks[ends])
    owner = np.repeat(np.arange(count), np.diff(profiles.bfirst))
    at = np.maximum.accumulate(owner + 1j * at).imag  # per sequence (complex order: lexicographic)
    levels = Pieces(at, profiles.bfirst)
    seqs = profiles.seqs
    wcount = batch.wfirst[seqs + 1] - batch.wfirst[seqs]
    tfirst = np.r_[0, np.cumsum(wcount)]
    targets_index = ranges(batch.wfirst[seqs] + 1, batch.wfirst[seqs + 1] - 1)
    k = np.repeat(np.arange(count), wcount - 2)
    targets = batch.s[targets_index]
    m = np.clip(levels.search(k, targets, "right") - 1, profiles.bfirst[k], profiles.bfirst[k + 1] - 2)
    piece = m - k
    h = profiles.breaks[m + 1] - profiles.breaks[m]
    c3, c2, c1, c0 = (pieces.coef[j, piece] for j in range(4))
    lo = np.zeros_like(targets)
    hi = h.copy()
    span = at[m + 1] - at[m]
    with np.errstate(divide="ignore", invalid="ignore"):
        tau = np.clip(np.where(span > 0, h * (targets - at[m]) / span, 0.5 * h), lo, hi)
    # A target, once converged, keeps its time: iterating on while others converge would move it
    # in its last bits, so that a sequence's times depended on the sequences planned with it.
    going = np.ones(len(tau), bool)
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
        tau = np.where((f == 0) | ~going, tau, new)
        going &= ~done
        if not going.any():
            break
    times = np.zeros(tfirst[-1])
    inner = np.delete(np.arange(tfirst[-1]), np.r_[tfirst[:-1], tfirst[1:] - 1])
    times[inner] = profiles.breaks[m] + tau
    times[tfirst[1:] - 1] = profiles.total
    broken: dict[int, PlanningError] = {}
    towner = np.repeat(np.arange(count), wcount)
    for i in np.flatnonzero((np.diff(times) <= 0) & (towner[1:] == towner[:-1])):
        r = int(seqs[towner[i]])
        if r not in broken:
            block = int(i - tfirst[towner[i]])
            broken[r] = PlanningError(f"block {block} got a non-positive duration (numerical failure)", block)
    return (times, tfirst), broken


def verify(batch: Batch, widest: float, profiles: Profiles, times: tuple[np.ndarray, np.ndarray], good: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Worst excess over the limits at samples of the time laws of the good sequences.

    Returns, for the samples that exceed a limit: their path parameter s, the factor on the
    squared speed cap, the factor on the acceleration bound, their sequence, and their
    (velocity, acceleration, jerk) ratios (n, 3); and per profile the largest |velocity|,
    |acceleration|, |jerk| of each joint over its limit at the samples (S, 3, 5).
    """
    pieces = profiles.pieces
    times, tfirst = times
    pk = pieces.owner
    h = np.diff(profiles.breaks)[np.delete(np.arange(len(profiles.breaks) - 1), profiles.bfirst[1:-1] - 1)]
    fill_dt = max(widest / 8.0, 1e-3) if batch.jerk else 5e-3
    # A piece lies within one grid interval, where the path and the cubic s(t) are smooth: a
    # bounded number of samples resolves it however long it lasts (a very slow feed gives
    # pieces of hours, which at fill_dt would not fit in memory).
    chosen = np.flatnonzero(good[pk])
    gaps = np.clip(np.ceil(h[chosen] / fill_dt), 2, _MAX_PIECE_SAMPLES).astype(int)
    piece = np.repeat(chosen, gaps)
    step = np.arange(int(gaps.sum())) - np.repeat(np.cumsum(gaps) - gaps, gaps)
    t = pieces.start[piece] + h[piece] * step / np.repeat(gaps, gaps)
    # s(t) is C2: at a break only the path jerk sddd changes, so the first sample of a piece
    # also carries the previous piece's sddd (the left side of the break), 6 c3 of that piece.
    left = np.full(len(t), np.nan)
    after = (step == 0) & (piece > pieces.first[pk[piece]])
    left[after] = 6.0 * pieces.coef[0, piece[after] - 1]
    towner = np.repeat(np.arange(len(profiles.seqs)), np.diff(tfirst))
    interior = np.flatnonzero((towner[1:] == towner[:-1]) & good[towner[1:]])
    interior = interior[np.isin(interior + 1, tfirst[1:] - 1, invert=True)]  # waypoints 1 .. K - 1
    dt = np.diff(times)
    around_t = np.concatenate([times[interior + 1] - 1e-7 * dt[interior],
                               times[interior + 1] + 1e-7 * dt[interior + 1]])
    around_k = np.concatenate([towner[interior + 1]] * 2)
    final_k = np.flatnonzero(good)  # the end of the last piece: the end of the motion
    t = np.concatenate([t, around_t, profiles.total[final_k]])
    piece = np.concatenate([piece, pieces.locate(around_k, around_t), pieces.first[final_k + 1] - 1])
    left = np.concatenate([left, np.full(len(around_t) + len(final_k), np.nan)])
    order = np.argsort(pieces.owner[piece], kind="stable")  # by profile, for the peaks per profile
    piece, t, left = piece[order], t[order], left[order]
    peaks = np.zeros((len(profiles.seqs), 3 * DOF))
    found = []
    for chunk in np.array_split(np.arange(len(t)), max(1, -(-len(t) // _VERIFY_CHUNK))):
        *excess, (k, peak) = _excess(batch, profiles, piece[chunk], t[chunk], left[chunk])
        np.maximum.at(peaks, k, peak)
        found.append(excess)
    bad = tuple(np.concatenate(parts) for parts in zip(*found, strict=True))
    return (*bad, peaks.reshape(-1, 3, DOF))  # type: ignore[return-value]


def _excess(batch: Batch, profiles: Profiles, piece: np.ndarray, t: np.ndarray, left: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """verify's findings at samples t, each in its profile piece, sorted by profile (see
    there); ``left`` the path jerk just before a sample at a break (NaN elsewhere). The
    peaks as (profiles present, their (3 * 5) peaks)."""
    pieces, lim = profiles.pieces, batch.limits
    k = pieces.owner[piece]
    t = np.clip(t, 0.0, profiles.total[k])
    s, sd, sdd, sddd = pieces.derivatives(piece, t, (0, 1, 2, 3))
    s = np.clip(s, 0.0, 1.0)
    r = profiles.seqs[k]
    blk = batch.path.locate(r, s, "right")
    q1, q2, q3 = batch.path.derivatives(blk, s, (1, 2, 3))  # (5, n)
    v, a, j = lim.velocity[:, None], lim.acceleration[:, None], lim.jerk[:, None]
    joint_vel = np.abs(q1) / v * sd
    r_vel = np.max(joint_vel, axis=0)
    r_vel = np.maximum(r_vel, sd / batch.block_cap[blk])
    r_vel = np.maximum(r_vel, np.linalg.norm(batch.tip(blk, s, 1), axis=0) * sd / batch.tip_feed[blk])
    # Acceleration and jerk split into the tangential part (from the path acceleration and
    # jerk: lowered through the acceleration bound) and the rest (from the path's curvature:
    # lowered through the speed).
    acc_c = q2 * sd ** 2
    joint_acc = np.abs(q1 * sdd + acc_c) / a
    r_acc = np.max(joint_acc, axis=0)
    share_acc = np.max(np.abs(acc_c) / a, axis=0) / np.maximum(r_acc, 1e-300)
    if batch.jerk:
        jerk_c = 3.0 * q2 * (sd * sdd) + q3 * sd ** 3
        joint_jerk = np.abs(q1 * sddd + jerk_c) / j
        at_break = np.flatnonzero(~np.isnan(left))
        joint_jerk[:, at_break] = np.maximum(joint_jerk[:, at_break],
                                             np.abs(q1[:, at_break] * left[at_break] + jerk_c[:, at_break]) / j)
        r_jerk = np.max(joint_jerk, axis=0)
        share_jerk = np.max(np.abs(jerk_c) / j, axis=0) / np.maximum(r_jerk, 1e-300)
    else:
        joint_jerk = np.zeros_like(joint_acc)
        r_jerk = share_jerk = np.zeros_like(r_acc)
    starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    peaks = (k[starts], np.maximum.reduceat(np.vstack([joint_vel, joint_acc, joint_jerk]), starts, axis=1).T)
    bad = (r_vel > 1 + VERIFY_TOL) | (r_acc > 1 + VERIFY_TOL) | (r_jerk > 1 + VERIFY_TOL)
    r_vel, r_acc, r_jerk = (np.maximum(ratio[bad], 1.0) for ratio in (r_vel, r_acc, r_jerk))
    curv_acc = share_acc[bad] > 0.5
    curv_jerk = share_jerk[bad] > 0.5
    fx = np.minimum(r_vel ** -2.0, np.where(curv_acc, r_acc ** -1.0, 1.0))
    fx = np.minimum(fx, np.where(curv_jerk, r_jerk ** (-2.0 / 3.0), 1.0))
    fa = np.minimum(np.where(curv_acc, 1.0, r_acc ** -1.0), np.where(curv_jerk, 1.0, r_jerk ** -1.0))
    fx = np.where(fx < 1.0, fx * _SHRINK, 1.0)
    fa = np.where(fa < 1.0, fa * _SHRINK, 1.0)
    return s[bad], fx, fa, r[bad], np.stack([r_vel, r_acc, r_jerk], axis=1), peaks
