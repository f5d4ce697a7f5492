"""The jerk-limited look-ahead baseline (benchmarks/scurve.py) against closed forms of the S-curve,
ruckig's time-optimal rest-to-rest moves, and the trapezoidal baseline and lower bound."""

from __future__ import annotations

import math

import numpy as np
import pytest

import verne_post as vp
from benchmarks.scurve import scurve_baseline_time
from tests.paths import helix
from tests.reference import ruckig_time
from verne_post.planning.timing import Limits, baseline_time, lower_bound_time

V, A, J = 1000.0, 10_000.0, 200_000.0  # a^2 / J = 500 mm/s: the speed above which a full ramp reaches a
LIMITS = Limits(np.full(5, V), np.full(5, A), np.full(5, J))


def _line(lengths: list[float], tip_per_joint: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """rho1 moves through blocks of these lengths (mm); the tip ``tip_per_joint`` times as far, along x."""
    joints = np.zeros((len(lengths) + 1, 5))
    joints[1:, 0] = np.cumsum(lengths)
    tip = np.zeros((len(lengths) + 1, 3))
    tip[:, 0] = joints[:, 0] * tip_per_joint
    return joints, tip


# One block; blocks that each hold a whole ramp with 1 mm blocks between them (a per-block
# S-curve starts and ends every speed change inside a block, at zero acceleration).
@pytest.mark.parametrize("lengths", [[500.0], [200.0, *[1.0] * 100, 200.0], [100.0, 150.0, 150.0, 100.0]])
@pytest.mark.parametrize(("feed", "cruise"), [(800.0, 800.0), (5000.0, V)])  # the feed, or rho1's velocity limit
def test_a_long_straight_move_takes_length_over_speed_plus_speed_over_a_plus_a_over_j(lengths: list[float],
                                                                                    feed: float, cruise: float
                                                                                    ) -> None:
    # Each full ramp (0 -> cruise, cruise >= a^2/J) takes cruise/a + a/J at cruise/2 on average:
    # L/cruise + 2 (cruise/a + a/J) / 2. Collinear blocks of one feed do not slow down between them.
    length = sum(lengths)
    time = scurve_baseline_time(*_line(lengths), np.full(len(lengths), feed), LIMITS)
    assert time == pytest.approx(length / cruise + cruise / A + A / J, rel=1e-9)


def test_a_short_move_that_never_reaches_the_acceleration_limit() -> None:
    # Jerk +J, -J, -J, +J for a quarter of the time each: L = 2 J (T/4)^3.
    length = 1.0
    time = scurve_baseline_time(*_line([length]), np.array([800.0]), LIMITS)
    assert time == pytest.approx(4.0 * (length / (2.0 * J)) ** (1 / 3), rel=1e-9)


def test_a_short_move_that_reaches_a_but_not_the_feed() -> None:
    # Up to the peak vp and down: L = vp (vp/a + a/J), a quadratic in vp; T = 2 (vp/a + a/J).
    length = 80.0
    vp_ = A / 2 * (-A / J + math.sqrt((A / J) ** 2 + 4 * length / A))
    assert A * A / J < vp_ < 800.0
    time = scurve_baseline_time(*_line([length]), np.array([800.0]), LIMITS)
    assert time == pytest.approx(2 * (vp_ / A + A / J), rel=1e-9)


def test_single_blocks_take_ruckigs_time_optimal_rest_to_rest_time() -> None:
    # One straight block from rest to rest: the 7-segment S-curve is time-optimal, as ruckig finds
    # it; the tip moving k times as far as rho1 scales the block's speed, a and J by k.
    rng = np.random.default_rng(10)
    for _ in range(300):
        velocity, acceleration, jerk = 10 ** rng.uniform(1, 3), 10 ** rng.uniform(2, 5), 10 ** rng.uniform(3, 7)
        length, k = 10 ** rng.uniform(-3, 3), 10 ** rng.uniform(-1, 1)
        limits = Limits(np.full(5, velocity), np.full(5, acceleration), np.full(5, jerk))
        feed = rng.choice([1e9, rng.uniform(0.2, 1.0) * k * velocity])  # the joint's limit or a lower feed
        time = scurve_baseline_time(*_line([length], k), np.array([feed]), limits)
        expected = ruckig_time(length, min(velocity, feed / k), acceleration, jerk)
        assert time == pytest.approx(expected, rel=1e-6, abs=1e-9)


def _random_sequence(rng: np.random.Generator, blocks: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A random joint polyline (mm, rad) with tips, a fifth of its blocks rotary-only, and feeds (mm/s)."""
    step = rng.normal(size=(blocks, 5)) * np.array([2.0, 2.0, 2.0, 0.01, 0.02]) * rng.uniform(0.01, 3.0)
    joints = np.vstack([np.zeros(5), np.cumsum(step, axis=0)])
    tip_step = rng.normal(size=(blocks, 3)) * rng.uniform(0.01, 3.0)
    tip_step[rng.random(blocks) < 0.2] = 0.0
    tip = np.vstack([np.zeros(3), np.cumsum(tip_step, axis=0)])
    return joints, tip, rng.uniform(5.0, 500.0, blocks)


def test_never_below_the_trapezoidal_baseline_nor_the_lower_bound_and_the_same_without_jerk_limit() -> None:
    # Every S-curve ramp is slower than the constant-acceleration ramp between the same speeds, so
    # junction speeds can only be lower and blocks only slower; as J grows the S-curve becomes
    # the trapezoid.
    machine = vp.load_machine()
    limits = Limits.from_machine(machine)
    rng = np.random.default_rng(11)
    joints, tip = helix(machine, 401, 1.0, pitch=2.0)
    cases = [(joints, tip, np.full(400, f)) for f in (20.0, 200.0, 2000.0)]
    cases += [_random_sequence(rng, int(rng.integers(1, 300))) for _ in range(40)]
    for joints, tip, feed in cases:
        options = {"angular_feed": 1.0, "cycle": float(rng.choice([0.001, 0.002, 0.004]))}
        time = scurve_baseline_time(joints, tip, feed, limits, **options)
        assert time >= baseline_time(joints, tip, feed, limits, **options) * (1 - 1e-12)
        assert time >= lower_bound_time(joints, tip, feed, limits, angular_feed=1.0)
        stiff = limits.scaled(jerk=1e9)
        assert scurve_baseline_time(joints, tip, feed, stiff, **options) == pytest.approx(
            baseline_time(joints, tip, feed, stiff, **options), rel=1e-5)
