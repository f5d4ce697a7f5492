"""The time law s(t) of planned sequences: the constant-acceleration profile of the squared
path speeds at the gridpoints, filtered when jerk is limited (module docstring of
:mod:`verne_post.planning.feed_planner`, step 3), and the plateau of a turn without cruise (step 4)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..timing import PlanningError
from .batch import Batch
from .segments import Pieces, ranges, segment_cumsum, sorted_points

# --------------------------------------------------------------------------------------------
# The planner
# --------------------------------------------------------------------------------------------


def peak_points(grid: Pieces, x: np.ndarray, seqs: np.ndarray) -> np.ndarray:
    """Per sequence of ``seqs``, the gridpoint (global index) where x is largest, the first if tied."""
    counts = grid.first[seqs + 1] - grid.first[seqs]
    gi = ranges(grid.first[seqs], grid.first[seqs + 1])
    owner = np.repeat(np.arange(len(seqs)), counts)
    top = np.maximum.reduceat(x[gi], np.r_[0, np.cumsum(counts)[:-1]])
    at_top = np.flatnonzero(x[gi] == top[owner])
    return gi[at_top[np.searchsorted(owner[at_top], np.arange(len(seqs)))]]


def plateau_levels(grid: Pieces, x: np.ndarray, seqs: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Per sequence of ``seqs``, the squared path speed L (1/s^2) below its peak at which the
    profile x (squared path speeds at the gridpoints, zero at both ends), capped at L, cruises
    for w (s); NaN where it already cruises that long at its peak.

    The cruise is the run of gridpoints around the peak where x >= L, at sqrt(L) once capped
    (where x crosses L within an interval, the capped profile still ramps there, only less
    steeply): its duration falls as L rises, so L is found by bisection, all the sequences at
    once.
    """
    gi = ranges(grid.first[seqs], grid.first[seqs + 1])
    owner = np.repeat(np.arange(len(seqs)), grid.first[seqs + 1] - grid.first[seqs])
    s, xs = grid.start[gi], np.maximum(x[gi], 0.0)
    peak = np.searchsorted(gi, peak_points(grid, x, seqs))  # local to gi
    top = xs[peak]
    index = np.arange(len(xs))

    def cruise(level: np.ndarray) -> np.ndarray:
        below = xs < level[owner]  # true at each sequence's ends, where x = 0 < level
        i = np.maximum.accumulate(np.where(below, index, -1))[peak]  # last node below, left of the peak
        j = np.minimum.accumulate(np.where(below, index, len(xs))[::-1])[::-1][peak]  # first, right
        return (s[j - 1] - s[i + 1]) / np.sqrt(level)

    hi = np.where(top > 0, top * (1.0 - 1e-9), 1.0)
    lo = np.zeros_like(hi)
    short = (top > 0) & (cruise(hi) < w)
    for _ in range(50):
        mid = np.where(short, 0.5 * (lo + hi), hi)
        long_enough = cruise(mid) >= w
        lo, hi = np.where(long_enough, mid, lo), np.where(long_enough, hi, mid)
    return np.where(short & (lo > 0), lo, np.nan)


@dataclass(frozen=True, eq=False)
class Profiles:
    """s(t) of some sequences: cubic pieces in local time, breaks per sequence (with the end)."""

    seqs: np.ndarray  # (S,) sequence numbers, in order
    breaks: np.ndarray  # (P + S,) local times
    bfirst: np.ndarray  # (S + 1,) offsets into breaks
    coef: np.ndarray  # (4, P), highest first

    @cached_property
    def pieces(self) -> Pieces:
        pfirst = self.bfirst - np.arange(len(self.bfirst))
        ends = self.bfirst[1:] - 1
        starts = np.delete(self.breaks, ends)
        return Pieces(starts, pfirst, self.coef)

    @property
    def total(self) -> np.ndarray:
        return self.breaks[self.bfirst[1:] - 1]


def time_laws(grid: Pieces, batch: Batch, w: np.ndarray, seqs: np.ndarray, x: np.ndarray
              ) -> tuple[Profiles, dict[int, PlanningError]]:
    """s(t) of the sequences ``seqs`` from their squared path speeds x at the gridpoints: the
    constant-acceleration profile, filtered when jerk is limited."""
    stuck: dict[int, PlanningError] = {}
    v_all = np.sqrt(np.maximum(x, 0.0))
    zero = np.flatnonzero((v_all[:-1] + v_all[1:] <= 0) & (grid.owner[:-1] == grid.owner[1:]))
    for i in zero[np.isin(grid.owner[zero], seqs)]:
        r = int(grid.owner[i])
        if r not in stuck:
            where = batch.waypoint_at(r, float(grid.start[i]))
            stuck[r] = PlanningError(f"the planned path speed drops to zero near waypoint {where}", where)
    seqs = np.array([r for r in seqs if r not in stuck], dtype=int)
    counts = grid.first[seqs + 1] - grid.first[seqs]
    gi = ranges(grid.first[seqs], grid.first[seqs + 1])
    nfirst = np.r_[0, np.cumsum(counts)]
    owner = np.repeat(np.arange(len(seqs)), counts)
    s_nodes, v = grid.start[gi], v_all[gi]
    inner = np.flatnonzero(owner[1:] == owner[:-1])
    dgrid = s_nodes[inner + 1] - s_nodes[inner]
    dt = 2.0 * dgrid / (v[inner] + v[inner + 1])
    u = (x[gi][inner + 1] - x[gi][inner]) / (2.0 * dgrid)
    ifirst = nfirst - np.arange(len(nfirst))
    t_nodes = np.zeros(len(gi))
    t_nodes[inner + 1] = segment_cumsum(dt, ifirst)
    if not batch.jerk:
        coef = np.stack([np.zeros_like(u), 0.5 * u, v[inner], s_nodes[inner]])
        return Profiles(seqs, t_nodes, nfirst, coef), stuck
    total = t_nodes[nfirst[1:] - 1]
    w = w[seqs]
    sigma = Pieces(t_nodes[inner], ifirst)
    s0, v0 = s_nodes[inner], v[inner]
    area = s0 * dt + v0 * dt ** 2 / 2.0 + u * dt ** 3 / 6.0
    # Integrals of sigma in long double, restarting at each sequence: ~1e-16 precision in s.
    running = segment_cumsum(area, ifirst, np.longdouble)  # through each piece
    total_area = running[ifirst[1:] - 1]
    prefix = np.concatenate([[np.longdouble(0.0)], running[:-1]])  # before each piece
    prefix[ifirst[:-1]] = 0.0

    def derivatives(k: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        i = sigma.locate(k, t)
        tau = t - sigma.start[i]
        before, after = t < 0.0, t >= total[k]
        value = np.where(before, 0.0, np.where(after, 1.0, s0[i] + v0[i] * tau + u[i] * tau ** 2 / 2.0))
        rest = before | after
        return value, np.where(rest, 0.0, v0[i] + u[i] * tau), np.where(rest, 0.0, u[i])

    def integral(k: np.ndarray, t: np.ndarray) -> np.ndarray:
        i = sigma.locate(k, t)
        tau = t - sigma.start[i]
        local = (s0[i] * tau + v0[i] * tau ** 2 / 2.0 + u[i] * tau ** 3 / 6.0).astype(np.longdouble)
        out = np.where(t <= 0.0, np.longdouble(0.0), prefix[i] + local)
        return np.where(t >= total[k], total_area[k] + (t - total[k]).astype(np.longdouble),
                        out)

    bseq, breaks, bfirst = sorted_points(np.concatenate([owner, owner]),
                                          np.concatenate([t_nodes, t_nodes + w[owner]]), len(seqs))
    # Breakpoints t[i] and t[j] + w can nearly coincide: a sliver piece between them would get
    # its third derivative from the wrong side by rounding. Pieces under a nanosecond are merged.
    last = np.zeros(len(breaks), bool)
    last[bfirst[1:] - 1] = True
    keep = last.copy()
    keep[bfirst[:-1]] = True
    keep[:-1] |= (breaks[1:] - breaks[:-1] > 1e-9) & ~last[:-1]
    bseq, breaks = bseq[keep], breaks[keep]
    bfirst = np.searchsorted(bseq, np.arange(len(seqs) + 1))
    ends = bfirst[1:] - 1
    k = np.delete(bseq, ends)
    left = np.delete(breaks, ends)
    mid = left + 0.5 * (np.delete(breaks, bfirst[:-1]) - left)
    wk = w[k]
    value = ((integral(k, left) - integral(k, left - wk)) / wk.astype(np.longdouble)).astype(float)
    a1, b1, _ = derivatives(k, left)
    a0, b0, _ = derivatives(k, left - wk)
    third = (derivatives(k, mid)[2] - derivatives(k, mid - wk)[2]) / wk
    coef = np.stack([third / 6.0, (b1 - b0) / (2.0 * wk), (a1 - a0) / wk, value])
    return Profiles(seqs, breaks, bfirst, coef), stuck
