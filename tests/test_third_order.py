"""The third-order programme's pieces (verne_post.planning.third_order), against brute force.

The plans themselves are checked in tests/test_timing.py (every limit at 1 ms and at their own
analytic derivatives); here the bookkeeping they rest on: which pairs of grid intervals a
moving average of width w mixes, and that a filtered law built from a programme's solution has
the path jerk the programme bounded.
"""

from __future__ import annotations

import numpy as np

from verne_post.planning import third_order


def _profile(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, float]:
    """A random grid s (N + 1,) on [0, 1], squared speeds x from rest to rest, and a width w (s)."""
    n = int(rng.integers(3, 40))
    s = np.r_[0.0, np.sort(rng.uniform(0.0, 1.0, n - 1)), 1.0]
    x = np.r_[0.0, rng.uniform(0.05, 4.0, n - 1), 0.0]
    tau = third_order.interval_times(s, x)
    return s, x, float(rng.uniform(0.1, 3.0) * np.median(tau))


def test_window_pairs_are_the_intervals_a_moving_average_mixes() -> None:
    """Every pair (i, i') with a stretch of t in interval i and t - w in interval i' < i (or
    before the start) is listed, and no pair that never meets."""
    rng = np.random.default_rng(3)
    for _ in range(300):
        s, x, w = _profile(rng)
        nodes = np.r_[0.0, np.cumsum(third_order.interval_times(s, x))]
        later, earlier = third_order.window_pairs(s, x, w)
        listed = set(zip(later.tolist(), earlier.tolist(), strict=True))
        count = len(nodes) - 1
        for i in range(count):
            lo, hi = nodes[i] - w, nodes[i + 1] - w  # where t - w runs while t is in interval i
            for j in range(-1, i):
                start, stop = (-np.inf, 0.0) if j < 0 else (nodes[j], nodes[j + 1])
                overlap = min(hi, stop) - max(lo, start)
                if overlap > 1e-9 * nodes[-1]:
                    assert (i, j) in listed
                elif overlap < -1e-9 * nodes[-1]:
                    assert (i, j) not in listed
        assert all(j < i for i, j in listed)


def test_merged_pairs_are_the_union() -> None:
    rng = np.random.default_rng(4)
    for _ in range(100):
        a = (rng.integers(0, 30, 40), rng.integers(-1, 30, 40))
        b = (rng.integers(0, 30, 10), rng.integers(-1, 30, 10))
        (later, earlier), changed = third_order.merge_pairs(a, b)
        union = set(zip(*a, strict=True)) | set(zip(*b, strict=True))
        assert set(zip(later.tolist(), earlier.tolist(), strict=True)) == union
        assert len(later) == len(union)
        assert changed == (not set(zip(*b, strict=True)) <= set(zip(*a, strict=True)))


def _acceleration_at(t: np.ndarray, nodes: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The path acceleration u of the interval each time t (s) falls in (0 at rest before and after)."""
    inside = (t >= 0.0) & (t < nodes[-1])
    return np.where(inside, u[np.clip(np.searchsorted(nodes, t, side="right") - 1, 0, len(u) - 1)], 0.0)


def test_a_straight_line_gets_the_jerk_the_programme_bounds() -> None:
    """On a straight line in joint space (q' constant, q'' = q''' = 0) the filtered law's joint
    jerk is q' (u(t) - u(t - w)) / w exactly: integrated independently here from the
    programme's squared speeds, it stays within the jerk limit, and the caps and the
    accelerations hold."""
    rng = np.random.default_rng(5)
    for _ in range(20):
        n = int(rng.integers(20, 60))
        s = np.linspace(0.0, 1.0, n + 1)
        direction = rng.normal(size=5)
        q1 = np.tile(direction, (n + 1, 1)) * rng.uniform(0.5, 2.0)
        zero = np.zeros_like(q1)
        acceleration, jerk = rng.uniform(5.0, 20.0, 5), rng.uniform(50.0, 400.0, 5)
        ub = np.full(n + 1, rng.uniform(0.5, 4.0))
        problem = third_order.ThirdOrderProblem(s, ub, q1, zero, zero, acceleration, jerk)
        reference = np.minimum(ub, 2.0 * np.min(acceleration / np.abs(direction)) * np.minimum(s, 1.0 - s))
        tau = third_order.interval_times(s, reference)
        w = float(np.max(tau[1:-1]))
        x = third_order.solve_filtered(problem, reference, w)
        assert x is not None
        assert np.all(x <= ub + 1e-9) and x[0] == 0.0 and x[-1] == 0.0
        u = np.diff(x) / (2.0 * np.diff(s))
        assert np.all(np.abs(np.outer(u, q1[0])) <= acceleration * (1 + 1e-6))
        # The filter's path jerk at dense t: the interval of t and of t - w from the law's own times.
        nodes = np.r_[0.0, np.cumsum(third_order.interval_times(s, x))]
        t = np.linspace(0.0, nodes[-1] + w, 20001)
        path_jerk = (_acceleration_at(t, nodes, u) - _acceleration_at(t - w, nodes, u)) / w
        assert np.max(np.abs(np.outer(path_jerk, q1[0])) / jerk) <= 1.0 + 1e-6
