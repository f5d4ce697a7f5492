"""Grid and caps: where the planner looks along each sequence, and how fast it may go there."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .batch import Batch
from .segments import Pieces, range_chmin, range_max, ranges, segment_cumsum, sorted_points

# Widest filter: w = factor * max_j(a_j / J_j), where full acceleration is used. The safe try
# (below) keeps 1.25, room for a path acceleration swinging past its limit within one window; the
# tight try has 1.1, since a turn without cruise now gets a plateau instead (step 4): on the 105k
# job 1.1 saves 4.8 s of 1966 (1.05 and 1.0 about 1 s more, planning 30 to 50 % more sequences
# twice). With the S-curves (_scurve_plans), 1.0 saves 1.5 s of 1941 for 15 to 20 % more
# planning time, and tighter margins (erosion 0.05, _ACC_MARGIN and _SHRINK 0.99) 2.2 s more for
# 45 % more in all: kept as they are.
_FIR_FACTOR = 1.1
SAFE_FIR_FACTOR = 1.25
_GRID_PER_WINDOW = 4  # target grid intervals per filter width, at the capped speed
_MIN_INTERVALS = 32
_END_HALVINGS, _MAX_END_HALVINGS = 4, 16  # halvings of each end's interval, at least and at most
_MAX_INTERVALS_PER_BLOCK = 1.0  # grid intervals per block, on average at most (plus a constant)


@dataclass(eq=False)
class Grid:
    """The gridpoints of a batch's sequences and what is known at them before any planning.

    ``w`` (filter width per sequence, s) is the planner's to narrow; the rest is fixed."""

    points: Pieces  # the gridpoints, per sequence
    t_scale: np.ndarray  # s, per sequence: its duration at the caps (the engines' time scale)
    widest: float  # s: the widest filter
    w: np.ndarray  # s, per sequence: its filter width
    scurve_floor: np.ndarray  # s, per sequence: no S-curve along it is faster
    xcap: np.ndarray  # 1/s^2, per gridpoint: the squared path speed cap
    radius: np.ndarray  # per gridpoint: the stretch of s a filter window there spans
    need_acc: np.ndarray  # per gridpoint: max_j |q_j'| / a_j over the window
    need_jerk: np.ndarray | None  # per gridpoint: max_j |q_j'| / J_j over the window (None: no jerk limit)
    q1: np.ndarray  # (G, 5) path derivatives at the gridpoints
    q2: np.ndarray  # (G, 5)


def build_grid(batch: Batch, erode: float, widest: bool, grid_factor: float = 1.0) -> Grid:
    """Grid and caps of every sequence of ``batch`` (module docstring of
    :mod:`verne_post.planning.feed_planner`, steps 1 and 2)."""
    points, t_scale, widest_w, w, gseq, wseq, bseq, mids = _gridpoints(batch, widest, grid_factor)
    return _caps(batch, erode, points, t_scale, widest_w, w, gseq, wseq, bseq, mids)


def _gridpoints(batch: Batch, widest: bool, grid_factor: float
                ) -> tuple[Pieces, np.ndarray, float, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The gridpoints, the time scale and the filter widths (and the sequence of each gridpoint,
    waypoint and block, and the blocks' middles, for the caps)."""
    lim = batch.limits
    count = batch.count
    path, s, bfirst = batch.path, batch.s, batch.bfirst
    bseq = path.owner
    ds = np.diff(s)[np.arange(len(bseq)) + bseq]
    mids = path.start + 0.5 * ds
    x_mid, tangent_mid = batch.point_cap(bseq, mids)
    tau = ds / np.sqrt(x_mid)  # s per block at its cap
    t_est = np.add.reduceat(tau, bfirst[:-1])
    t_scale = np.maximum(t_est, 1e-6)
    # Filter width per sequence (feed_planner's docstring, step 3): long enough to ramp the fastest
    # joint to its capped speed with its jerk limit, at most where full acceleration pays.
    widest_w = (SAFE_FIR_FACTOR if widest else _FIR_FACTOR) * float(np.max(lim.acceleration / lim.jerk))
    if not batch.jerk:
        w = np.zeros(count)
    elif widest:
        w = np.full(count, widest_w)
    else:
        speed = tangent_mid * np.sqrt(x_mid)  # joints at the block caps
        ramp = np.sqrt(np.max(speed / lim.jerk[:, None], axis=0))
        w = np.minimum(np.maximum.reduceat(ramp, bfirst[:-1]), widest_w)
    blocks = np.diff(bfirst)
    window = (w if batch.jerk else np.full(count, 0.05)) / (grid_factor * _GRID_PER_WINDOW)
    per_block = grid_factor * _MAX_INTERVALS_PER_BLOCK
    delta = np.maximum(np.minimum(window, t_est / _MIN_INTERVALS), t_est / (per_block * blocks + _MIN_INTERVALS))
    # Gridpoints: waypoints where the travel time at the caps crosses a multiple of delta,
    # long blocks subdivided, and a geometrically refined start and end (from and to rest).
    wseq = np.repeat(np.arange(count), np.diff(batch.wfirst))
    cum = np.zeros(len(s))
    cum[np.arange(len(bseq)) + bseq + 1] = segment_cumsum(tau, bfirst)
    bucket = np.floor(cum / delta[wseq])
    keep = np.r_[True, (bucket[1:] != bucket[:-1]) | (wseq[1:] != wseq[:-1])]
    keep[batch.wfirst[1:] - 1] = True
    long = tau > delta[bseq]
    left = np.flatnonzero(long) + bseq[long]
    keep[left] = keep[left + 1] = True
    parts = np.maximum(np.round(tau[long] / delta[bseq[long]]), 1).astype(int)
    owner = np.repeat(np.arange(len(parts)), parts)
    step = np.arange(int(parts.sum())) - np.repeat(np.cumsum(parts) - parts, parts)
    inner = step > 0
    owner, step = owner[inner], step[inner]
    interior = path.start[long][owner] + ds[long][owner] * step / parts[owner]
    kept = np.flatnonzero(keep)
    kfirst = np.searchsorted(kept, batch.wfirst)
    # The first and last intervals halved until they take at most w / 4 at the caps: TOPP2
    # holds the path acceleration over an interval, so a ramp from rest lasts the whole
    # first interval (a long block at a slow feed, coarsely gridded, lost one interval at
    # each end: 6 % of a plunge).
    piece = ds.copy()
    piece[long] /= parts
    first_block, last_block = bfirst[:-1], bfirst[1:] - 1
    start_gap = np.minimum(s[kept[kfirst[:-1] + 1]], piece[first_block])
    end_gap = np.minimum(1.0 - s[kept[kfirst[1:] - 2]], piece[last_block])
    ends, end_seq = [], []
    for gap, block, mirror in ((start_gap, first_block, False), (end_gap, last_block, True)):
        seconds = gap * tau[block] / ds[block]
        halvings = np.clip(np.ceil(np.log2(seconds / window)), _END_HALVINGS, _MAX_END_HALVINGS).astype(int)
        at = ranges(np.zeros(count, int), halvings) + 1
        point = np.repeat(gap, halvings) * 0.5 ** at
        ends.append(1.0 - point if mirror else point)
        end_seq.append(np.repeat(np.arange(count), halvings))
    gseq, grid, gfirst = sorted_points(np.concatenate([wseq[kept], bseq[long][owner], *end_seq]),
                                        np.concatenate([s[kept], interior, *ends]), count)
    points = Pieces(grid, gfirst)
    return points, t_scale, widest_w, w, gseq, wseq, bseq, mids


def _caps(batch: Batch, erode: float, points: Pieces, t_scale: np.ndarray, widest_w: float, w: np.ndarray,
          gseq: np.ndarray, wseq: np.ndarray, bseq: np.ndarray, mids: np.ndarray) -> Grid:
    """The caps and the path acceleration bounds' parts at the gridpoints (feed_planner's docstring,
    step 1, and the filter's reach)."""
    lim, count, s = batch.limits, batch.count, batch.s
    grid, gfirst, n = points.start, points.first, len(points.start)
    # Check points: the gridpoints, the middles of their intervals, the waypoints, the block middles.
    inner_grid = np.flatnonzero(np.diff(gseq) == 0)
    cseq, check, cfirst = sorted_points(
        np.concatenate([gseq, gseq[inner_grid], wseq, bseq]),
        np.concatenate([grid, 0.5 * (grid[inner_grid] + grid[inner_grid + 1]), s, mids]), count)
    checks = Pieces(check, cfirst)
    raw, tangent = batch.point_cap(cseq, check)
    # No S-curve along a sequence (_scurve_plans) is faster than the whole path at its lowest cap.
    scurve_floor = 1.0 / np.sqrt(np.minimum.reduceat(raw, cfirst[:-1]))
    # With the filter, the speed at a point mixes the speeds within half a filter width of
    # travel around it: each check point imposes its cap over erode * w * (its own capped
    # speed) on either side. The squared speed is linear in s between gridpoints, so the
    # gridpoints within that range take the cap, and the two intervals it ends in are
    # lowered at both ends until their line meets it at the range's ends.
    reach = erode * w[cseq] * np.sqrt(raw)
    lo = points.search(cseq, check - reach, "left")
    hi = points.search(cseq, check + reach, "right") - 1
    inside = lo <= hi
    xcap = range_chmin(n, lo[inside], hi[inside], raw[inside])
    scale = np.ones(n)  # per interval, by its left gridpoint
    # The gridpoint at or before each end of the range: the one before the first inside it,
    # the last inside it (an end on a gridpoint gives a weight of 1 or 0: the same line).
    for end, left in ((np.clip(check - reach, 0.0, 1.0), lo - 1), (np.clip(check + reach, 0.0, 1.0), hi)):
        left = points.clip(cseq, left)
        right = np.minimum(left + 1, gfirst[cseq + 1] - 1)
        span = grid[right] - grid[left]
        weight = np.divide(end - grid[left], span, out=np.zeros_like(span), where=span > 0)
        line = xcap[left] + weight * (xcap[right] - xcap[left])
        np.minimum.at(scale, left, np.minimum(raw / line, 1.0))
    before = np.r_[1.0, scale[:-1]]
    before[gfirst[:-1]] = 1.0
    xcap = xcap * np.minimum(scale, before)
    index = np.arange(n)
    lo0 = grid[np.maximum(index - 1, gfirst[gseq])]
    hi0 = grid[np.minimum(index + 1, gfirst[gseq + 1] - 1)]
    r = erode * w[gseq] * np.sqrt(xcap)
    radius = np.maximum(r, np.maximum(grid - lo0, hi0 - grid))
    # Path acceleration bound: the filter spreads a path acceleration over its window, where
    # |q_j'| may be larger than at the gridpoint; |sddot| <= a_j / max over the window |q_j'|,
    # and u / w within the jerk limit: |sddot| <= w J_j / max |q_j'|.
    a = checks.clip(gseq, checks.search(gseq, np.minimum(grid - r, lo0), "left"))
    b = np.maximum(a, checks.clip(gseq, checks.search(gseq, np.maximum(grid + r, hi0), "right") - 1))
    # 1 / bound = max(max_j |q_j'| / a_j, max_j |q_j'| / J_j / w): both kept, for a new w.
    need_acc = range_max(np.max(tangent / lim.acceleration[:, None], axis=0), a, b)
    need_jerk = range_max(np.max(tangent / lim.jerk[:, None], axis=0), a, b) if batch.jerk else None
    piece = batch.path.locate(gseq, grid)
    q1, q2 = (d.T for d in batch.path.derivatives(piece, grid, (1, 2)))  # (G, 5)
    return Grid(points, t_scale, widest_w, w, scurve_floor, xcap, radius, need_acc, need_jerk, q1, q2)
