"""Third-order time laws of feed sequences as a linear programme (``--optimize``).

The planner (:mod:`verne_post.planning.feed_planner`) meets the jerk limits by filtering a second-order
(TOPP2) profile with a moving average of width ``w = 1.1 max_j(a_j / J_j)``: every corner of
the profile becomes a jerk-limited ramp, at the cost of the window's lag and of caps lowered
around their points (the average mixes the faster speeds on one side of a corner into the
slower ones on the other). On a long row that climbs from a feed-limited stretch into a
rotary-limited one, that costs about 1 % over what a third-order method reaches.

Here the profile is chosen for the filter instead of filtered after the fact. On the planner's
grid s_0 < ... < s_N (path parameter, 0..1) the squared path speeds x_i (1/s^2) define the
profile sigma(t) with constant path acceleration ``u_i = (x_{i+1} - x_i) / (2 (s_{i+1} - s_i))``
on each interval; its moving average of a short width w (a few grid intervals) has the path
jerk ``(u(t) - u(t - w)) / w``, the difference of the accelerations of the two intervals that t
and t - w fall in. For every such pair of intervals the joint jerks
``q_j' sdddot + 3 q_j'' sdot sddot + q_j''' sdot^3`` are bounded in x, linearly (sdot taken
from a reference profile), beside the joint accelerations at both ends of every interval and
the caps; the time, linearised around the reference, is minimised. This is the third-order
problem of Pham & Pham's TOPP-RA family made linear the way copp-py's TOPP3-LP is (Wang et
al.; copp-py documentation), but with the jerk measured as the filter produces it, so that the
filtered law is a C2 piecewise cubic the planner verifies exactly like its own.

The pairs depend on the times, which depend on x: the programme is solved again with the pairs
of its own solution added until no new pair appears. Solved by HiGHS through
``scipy.optimize.linprog``. Nothing here reads files; units as in the planner (s local, times s,
limits per second).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Pairs", "ThirdOrderProblem", "interval_times", "merge_pairs", "solve", "solve_filtered", "window_pairs"]


@dataclass(frozen=True)
class ThirdOrderProblem:
    """One sequence on its grid: ``s`` (N + 1,) path parameter, ``ub`` (N + 1,) caps on x
    (1/s^2), ``q1, q2, q3`` (N + 1, 5) the path's first three derivatives in s at the
    gridpoints (mm, rad per unit s^k), limits (5,) each: acceleration and jerk (per s^2, s^3)
    already multiplied by their margins."""

    s: np.ndarray
    ub: np.ndarray
    q1: np.ndarray
    q2: np.ndarray
    q3: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray


Pairs = tuple[np.ndarray, np.ndarray]  # (later interval, earlier interval or -1 before the start)


def interval_times(s: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Duration (s) of each grid interval of the profile with squared speeds x (constant path
    acceleration on each: the distance over the mean speed)."""
    v = np.sqrt(np.maximum(x, 0.0))
    return 2.0 * np.diff(s) / np.maximum(v[:-1] + v[1:], 1e-300)


def window_pairs(s: np.ndarray, x: np.ndarray, w: float) -> Pairs:
    """Every pair (i, i') of grid intervals with some t in interval i and t - w in interval i' < i
    (i' = -1: before the start, at rest), for the profile x filtered with width w (s)."""
    nodes = np.r_[0.0, np.cumsum(interval_times(s, x))]
    count = len(nodes) - 1
    later = np.arange(count)
    first = np.clip(np.searchsorted(nodes, nodes[:-1] - w, side="right") - 1, -1, count - 1)
    last = np.minimum(np.clip(np.searchsorted(nodes, nodes[1:] - w, side="left") - 1, -1, count - 1), later - 1)
    hits = np.maximum(last - first + 1, 0)
    earlier = np.repeat(first, hits) + np.arange(int(hits.sum())) - np.repeat(np.cumsum(hits) - hits, hits)
    return np.repeat(later, hits), earlier


def merge_pairs(a: Pairs, b: Pairs) -> tuple[Pairs, bool]:
    """The union of two pair sets, and whether b added any pair."""
    count = max(int(np.max(part, initial=0)) for part in (*a, *b)) + 2  # a key per (i, i' + 1)
    keys_a, keys_b = a[0] * count + a[1] + 1, b[0] * count + b[1] + 1
    union = np.union1d(keys_a, keys_b)
    return (union // count, union % count - 1), len(union) > len(np.unique(keys_a))


def solve(problem: ThirdOrderProblem, reference: np.ndarray, w: float, pairs: Pairs) -> np.ndarray | None:
    """The squared path speeds x (N + 1,) of least linearised time within the limits, from rest
    to rest, for the filter width w (s) and the interval pairs ``pairs``; sdot in the curvature
    terms and the time's weights from ``reference`` (x, 1/s^2). None if HiGHS finds no solution."""
    from scipy.optimize import linprog
    from scipy.sparse import csr_matrix

    p = problem
    n = len(p.s)
    count = n - 1
    d = np.diff(p.s)
    speed = np.sqrt(np.maximum(reference, 0.0))
    row_of: list[np.ndarray] = []
    col_of: list[np.ndarray] = []
    value_of: list[np.ndarray] = []
    limit_of: list[np.ndarray] = []
    rows = 0

    def bound(terms: list[tuple[np.ndarray, np.ndarray]], limit: np.ndarray) -> None:
        """|sum of coefficient * x[column]| <= limit, one row per element."""
        nonlocal rows
        for sign in (1.0, -1.0):
            index = np.arange(rows, rows + len(limit))
            for column, coefficient in terms:
                row_of.append(index)
                col_of.append(column)
                value_of.append(sign * coefficient)
            limit_of.append(limit)
            rows += len(limit)

    def acceleration_of(i: np.ndarray, scale: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """scale * u_i, u_i = (x_{i+1} - x_i) / (2 d_i) the path acceleration on interval i."""
        return [(i + 1, scale / (2.0 * d[i])), (i, -scale / (2.0 * d[i]))]

    interval = np.arange(count)
    for node in (interval, interval + 1):  # joint accelerations q1 u + q2 x at both ends of each interval
        for j in range(p.q1.shape[1]):
            bound([*acceleration_of(interval, p.q1[node, j]), (node, p.q2[node, j])], np.full(count, p.acceleration[j]))
    # Joint jerks of the filtered law where t is in interval i and t - w in i' (before the start:
    # at rest), at the gridpoint between them: q1 (u_i - u_i') / w + 3 q2 sdot (u_i + u_i') / 2 + q3 sdot x.
    later, earlier = pairs
    started = earlier >= 0
    k = earlier + 1
    for j in range(p.q1.shape[1]):
        tangential, curvature = p.q1[k, j] / w, 1.5 * p.q2[k, j] * speed[k]
        bound([*acceleration_of(later, tangential + curvature),
               *acceleration_of(np.maximum(earlier, 0), np.where(started, curvature - tangential, 0.0)),
               (k, p.q3[k, j] * speed[k])], np.full(len(later), p.jerk[j]))
    # ... and where t - w is in interval i but t past the end (at rest again).
    ends = np.r_[0.0, np.cumsum(interval_times(p.s, reference))]
    tail = np.flatnonzero(ends[1:] > ends[-1] - w)
    for j in range(p.q1.shape[1]):
        bound(acceleration_of(tail, p.q1[tail + 1, j] / w), np.full(len(tail), p.jerk[j]))
    upper = np.minimum(p.ub, 1e300)
    upper[[0, -1]] = 0.0
    rows_index, columns, values = (np.concatenate(a) for a in (row_of, col_of, value_of))
    limits = np.concatenate(limit_of)
    # Rows no x within the bounds can violate are left out.
    reach = np.bincount(rows_index, weights=np.maximum(values, 0.0) * upper[columns], minlength=rows)
    needed = reach > limits
    renumber = np.cumsum(needed) - 1
    keep = needed[rows_index]
    matrix = csr_matrix((values[keep], (renumber[rows_index[keep]], columns[keep])), shape=(int(needed.sum()), n))
    weight = 0.5 * (np.r_[d, 0.0] + np.r_[0.0, d])  # dT/dx_i ~ -weight_i / (2 x_i^1.5)
    floor = 1e-3 * max(float(np.max(reference)), 1e-300)
    cost = -weight / np.maximum(reference, floor) ** 1.5
    result = linprog(cost / np.max(np.abs(cost)), A_ub=matrix, b_ub=limits[needed],
                     bounds=np.c_[np.zeros(n), upper], method="highs", options={"presolve": False})
    if result.status != 0:
        return None
    return np.clip(result.x, 0.0, upper)


def solve_filtered(problem: ThirdOrderProblem, reference: np.ndarray, w: float, iterations: int = 6
                   ) -> np.ndarray | None:
    """:func:`solve` with the pairs of the reference, then again around each solution with its
    own pairs added, until a solution brings no new pair (its times are those the pairs were
    taken from, up to pairs met before) or ``iterations`` are done; None if HiGHS fails."""
    pairs = window_pairs(problem.s, reference, w)
    for _ in range(iterations):
        x = solve(problem, reference, w, pairs)
        if x is None:
            return None
        pairs, changed = merge_pairs(pairs, window_pairs(problem.s, x, w))
        if not changed:
            return x
        reference = np.maximum(x, 1e-12 * float(np.max(x)))
    return x  # the pairs still changing: the verification decides
