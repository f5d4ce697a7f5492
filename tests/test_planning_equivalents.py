"""The feed planner's faster routes against the plain ones they replace, bit for bit: the S-curve
ramps evaluated for many speeds, the bisection on both ramps at once, and the verification in
chunks of any size."""

from __future__ import annotations

import numpy as np
import pytest

import verne_post as vp
from tests.paths import feed_pieces
from verne_post.planning.feed import scurve, verification
from verne_post.planning.feed_planner import FeedPlan, plan_feeds
from verne_post.planning.timing import Limits


def _log_uniform(rng: np.random.Generator, low: float, high: float, size: int) -> np.ndarray:
    return 10.0 ** rng.uniform(np.log10(low), np.log10(high), size)


def _limits_rows(rng: np.random.Generator, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random path accelerations (count, 2) and jerks (count, 4) over 6 decades (1/s^2, 1/s^3)."""
    return (_log_uniform(rng, 1e-2, 1e4, 2 * count).reshape(count, 2),
            _log_uniform(rng, 1e-1, 1e6, 4 * count).reshape(count, 4), _log_uniform(rng, 1e-3, 1e3, count))


def _ramp(speed: np.ndarray, acc: np.ndarray, rise: np.ndarray, fall: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The plain route: one ramp from rest to ``speed`` under ``acc`` with the jerks ``rise`` and
    ``fall``, every term from the speed (the three phase durations and the distance)."""
    bend = 0.5 / rise + 0.5 / fall
    full = speed >= acc ** 2 * bend
    peak = np.where(full, acc, np.sqrt(speed / bend))
    t1, t3 = peak / rise, peak / fall
    t2 = np.where(full, (speed - peak ** 2 * bend) / peak, 0.0)
    v1 = rise * t1 ** 2 / 2.0
    v2 = v1 + peak * t2
    distance = (rise * t1 ** 3 / 6.0 + v1 * t2 + peak * t2 ** 2 / 2.0
                + v2 * t3 + peak * t3 ** 2 / 2.0 - fall * t3 ** 3 / 6.0)
    return t1, t2, t3, distance


def test_ramp_distances_are_those_of_ramp() -> None:
    """_Ramps gives the plain ramp's phases and distance, bit for bit, below and above full acceleration."""
    rng = np.random.default_rng(3)
    n = 20_000
    acc, rise, fall = (_log_uniform(rng, 1e-3, 1e4, n) for _ in range(3))
    reach = acc ** 2 * (0.5 / rise + 0.5 / fall)
    speed = reach * _log_uniform(rng, 1e-4, 1e4, n)
    speed[:100] = reach[:100]  # exactly at full acceleration
    ramps = scurve._Ramps(acc, rise, fall)
    np.testing.assert_array_equal(ramps.distance(speed), _ramp(speed, acc, rise, fall)[3])
    for found, plain in zip(ramps.phases(speed), _ramp(speed, acc, rise, fall), strict=True):
        np.testing.assert_array_equal(found, plain)


def _scurve_one_ramp_at_a_time(cap: np.ndarray, acc: np.ndarray, jerk: np.ndarray
                               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """_scurve with its two ramps evaluated by _ramp, each on its own (the plain route)."""
    def covered(v: np.ndarray) -> np.ndarray:
        return (_ramp(v, acc[:, 0], jerk[:, 0], jerk[:, 1])[3]
                + _ramp(v, acc[:, 1], jerk[:, 3], jerk[:, 2])[3])

    low, high = np.zeros_like(cap), np.minimum(cap, np.sqrt(2.0 / (1.0 / acc[:, 0] + 1.0 / acc[:, 1])))
    short = covered(cap) > 1.0
    for _ in range(32):
        mid = 0.5 * (low + high)
        over = covered(mid) > 1.0
        low, high = np.where(over, low, mid), np.where(over, mid, high)
    speed = np.where(short, low, cap)
    a1, a2, a3, up = _ramp(speed, acc[:, 0], jerk[:, 0], jerk[:, 1])
    d1, d2, d3, down = _ramp(speed, acc[:, 1], jerk[:, 3], jerk[:, 2])
    cruise = np.maximum(1.0 - up - down, 0.0) / speed
    zero = np.zeros_like(speed)
    return (np.stack([a1, a2, a3, cruise, d3, d2, d1], axis=1),
            np.stack([jerk[:, 0], zero, -jerk[:, 1], zero, -jerk[:, 2], zero, jerk[:, 3]], axis=1), speed)


def test_scurve_bisects_both_ramps_as_the_plain_route() -> None:
    """_scurve (both ramps in one array, _Ramps) finds the plain route's phases and peak speed,
    bit for bit, for short moves and moves that cruise at their cap."""
    rng = np.random.default_rng(5)
    for count in (1, 2, 17, 5000):
        acc, jerk, cap = _limits_rows(rng, count)
        for found, plain in zip(scurve._scurve(cap, acc, jerk), _scurve_one_ramp_at_a_time(cap, acc, jerk),
                                strict=True):
            np.testing.assert_array_equal(found, plain)


def _arrays(plan: FeedPlan) -> list[np.ndarray]:
    return [plan.durations, plan.block_times, plan.waypoint_s, plan.path.coef, plan.profile.breaks,
            plan.profile.coef, plan.peak_ratios, np.array([plan.filter_width, plan.gridpoints, plan.refinements])]


def test_verification_in_chunks_of_any_size_gives_the_same_plans(machine: vp.Machine,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The verification's samples are evaluated in chunks to stay in cache: the plans (and the
    peaks they certify) are the same, bit for bit, for chunks of 2^16, 2^13 and 997 samples."""
    sequences, limits = feed_pieces(machine), Limits.from_machine(machine)
    plans = {}
    for chunk in (1 << 16, 1 << 13, 997):
        monkeypatch.setattr(verification, "_VERIFY_CHUNK", chunk)
        plans[chunk] = plan_feeds(sequences, limits, angular_feed=1.0)
    assert all(isinstance(plan, FeedPlan) for plan in plans[997])
    for chunk in (997, 1 << 13):
        for plan, other in zip(plans[1 << 16], plans[chunk], strict=True):
            for a, b in zip(_arrays(plan), _arrays(other), strict=True):  # type: ignore[arg-type]
                np.testing.assert_array_equal(a, b)

