"""The jerk-limited lower bound (benchmarks/jerk_bound.py) against ruckig's time-optimal
rest-to-rest moves, a numerical integration of the fastest speed from rest, and verified plans:
no plan within the limits may be faster than the bound."""

from __future__ import annotations

import numpy as np
import pytest

import verne_post as vp
from benchmarks.jerk_bound import jerk_lower_bounds, rest_to_rest_time, time_from_rest
from tests.paths import helix, zigzag
from tests.reference import ruckig_time
from verne_post.planning.feed_planner import plan_feeds
from verne_post.planning.timing import Limits, lower_bound_time


def test_rest_to_rest_time_is_ruckigs_time_optimal_move() -> None:
    rng = np.random.default_rng(3)
    for _ in range(500):
        v, a, j, length = 10 ** rng.uniform(-1, 3), 10 ** rng.uniform(0, 5), 10 ** rng.uniform(1, 7), \
            10 ** rng.uniform(-4, 3)
        assert rest_to_rest_time(length, v, a, j) == pytest.approx(ruckig_time(length, v, a, j), rel=1e-7)


def test_time_from_rest_inverts_the_integrated_fastest_speed() -> None:
    """The farthest a joint gets from rest in time t, integrated numerically on a fine grid (the
    speed is at most v and at most the integral of min(J tau, a)): time_from_rest of that
    distance gives t back."""
    rng = np.random.default_rng(4)
    for _ in range(200):
        v, a, j = 10 ** rng.uniform(-1, 3), 10 ** rng.uniform(0, 5), 10 ** rng.uniform(1, 7)
        horizon = 3.0 * (v / a + a / j + np.sqrt(v / j))
        t = np.linspace(0.0, horizon, 200_001)
        dt = t[1] - t[0]
        acceleration = np.minimum(j * t, a)
        speed = np.minimum(np.r_[0.0, np.cumsum(0.5 * (acceleration[1:] + acceleration[:-1])) * dt], v)
        reach = np.r_[0.0, np.cumsum(0.5 * (speed[1:] + speed[:-1])) * dt]
        pick = rng.integers(1, len(t), 20)
        np.testing.assert_allclose(time_from_rest(reach[pick], v, a, j), t[pick], rtol=1e-4, atol=dt)


@pytest.fixture(scope="module")
def sequences() -> tuple[list[tuple[np.ndarray, np.ndarray, np.ndarray]], Limits]:
    """Windows of 1 to 300 blocks of a helix and of a zigzag with a swinging tool axis, each at
    its own feed (mm/s); and the machine's limits."""
    machine = vp.load_machine()
    rng = np.random.default_rng(8)
    out = []
    for joints, tip in (helix(machine), zigzag(machine)):
        for _ in range(30):
            blocks = int(rng.choice([1, 2, 5, 20, 80, 300]))
            first = int(rng.integers(0, len(joints) - blocks - 1))
            rows = slice(first, first + blocks + 1)
            out.append((joints[rows], tip[rows], np.full(blocks, rng.uniform(5.0, 200.0))))
    return out, Limits.from_machine(machine)


def test_no_verified_plan_beats_the_bound(sequences: tuple[list, Limits]) -> None:
    """Every plan the planner returns is verified within the limits, so it is a plan the bound must
    not exceed; and the bound is at least the velocity-only bound LB."""
    seqs, limits = sequences
    bounds = jerk_lower_bounds(seqs, limits, angular_feed=1.0)
    plans = plan_feeds(seqs, limits, angular_feed=1.0)
    for (joints, tip, feed), bound, plan in zip(seqs, bounds, plans, strict=True):
        assert lower_bound_time(joints, tip, feed, limits, angular_feed=1.0) <= bound * (1 + 1e-12)
        # a one-block plan is the optimum itself: the two may differ in the last bit
        assert bound <= plan.total * (1 + 1e-12), (len(feed), bound, plan.total)


def test_a_straight_move_bound_is_its_s_curve() -> None:
    """One block of one slider: the bound is the move's own S-curve at the feed (its tip moving
    twice as far as the slider), which the planner's plan (in closed form) is."""
    limits = Limits(np.full(5, 1000.0), np.full(5, 10_000.0), np.full(5, 200_000.0))
    rng = np.random.default_rng(6)
    seqs, expected = [], []
    for length, feed in zip(rng.uniform(0.5, 80.0, 10), rng.uniform(2.0, 300.0, 10), strict=True):
        joints = np.tile([600.0, 650.0, 700.0, 0.2, 0.5], (2, 1))
        joints[1, 0] += length
        tip = np.array([[0.0, 0.0, 0.0], [2.0 * length, 0.0, 0.0]])
        seqs.append((joints, tip, np.array([feed])))
        expected.append(ruckig_time(length, min(1000.0, feed / 2.0), 10_000.0, 200_000.0))
    bounds = jerk_lower_bounds(seqs, limits)
    np.testing.assert_allclose(bounds, expected, rtol=1e-7)
    plans = plan_feeds(seqs, limits, angular_feed=1.0)
    for bound, plan in zip(bounds, plans, strict=True):
        assert plan.total == pytest.approx(bound, rel=1e-9)
