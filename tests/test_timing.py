"""Time laws of feed sequences (toppra + jerk filter) and rapids (ruckig), checked at 1 ms.

The joint polylines come from the machine's IK of smooth Cartesian tool paths in the table
frame; every plan is resampled at 1 ms and checked with finite differences against the joint
limits, and the tool tip (FK of the sampled joints) against the programmed feed.
"""

from __future__ import annotations

import math

import copp_py as copp
import numpy as np
import pytest
import toppra.algorithm
from scipy.interpolate import CubicSpline

import verne_post as vp
from tests.paths import TOOL, axis_from, feed_pieces, helix, joints_along, zigzag
from tests.reference import ruckig_time
from verne_post.planning import feed_planner, schedule
from verne_post.planning.feed import rounds, scurve, segments
from verne_post.planning.feed.segments import not_a_knot
from verne_post.planning.feed_planner import FeedPlan, plan_feed, plan_feeds
from verne_post.planning.timing import Limits, PlanningError, baseline_time, lower_bound_time, plan_rapid

DT = 1e-3
SLACK = 1.02  # finite differences at 1 ms against the limits


# ---------------------------------------------------------------------------------------------
# Paths
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def limits(machine: vp.Machine) -> Limits:
    return Limits.from_machine(machine)


@pytest.fixture(scope="module")
def helix_path(machine: vp.Machine) -> tuple[np.ndarray, np.ndarray]:
    return helix(machine)


@pytest.fixture(scope="module")
def zigzag_path(machine: vp.Machine) -> tuple[np.ndarray, np.ndarray]:
    return zigzag(machine)


# ---------------------------------------------------------------------------------------------
# Checks
# ---------------------------------------------------------------------------------------------


def _uniform(total: float) -> tuple[np.ndarray, float]:
    n = max(math.ceil(total / DT), 4) + 1
    return np.linspace(0.0, total, n), total / (n - 1)


def _finite_difference_ratios(q: np.ndarray, dt: float, limits: Limits) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per joint, the largest |velocity|, |acceleration|, |jerk| by finite differences over its limit."""
    vel = np.abs(np.diff(q, axis=0)).max(axis=0) / dt / limits.velocity
    acc = np.abs(np.diff(q, 2, axis=0)).max(axis=0) / dt ** 2 / limits.acceleration
    jerk = np.abs(np.diff(q, 3, axis=0)).max(axis=0) / dt ** 3 / limits.jerk
    return vel, acc, jerk


def check_feed_plan(machine: vp.Machine, plan: FeedPlan, joints: np.ndarray, tip: np.ndarray, feed: np.ndarray,
                    limits: Limits, *, jerk: bool = True) -> dict[str, float]:
    """Every check of a feed plan at 1 ms; returns the worst ratios found."""
    k = len(feed)
    assert plan.durations.shape == (k,)
    assert np.all(plan.durations > 0)
    assert plan.durations.sum() == pytest.approx(plan.total, rel=1e-12)
    ends = np.concatenate([[0.0], np.cumsum(plan.durations)])
    q_ends, qd_ends, _ = plan.sample(ends)
    assert np.abs(q_ends - joints).max() <= 1e-9  # block ends are the waypoints
    assert np.abs(qd_ends[[0, -1]]).max() <= 1e-9  # from rest to rest

    t, dt = _uniform(plan.total)
    q, qd, qdd = plan.sample(t)
    assert q.shape == qd.shape == qdd.shape == (len(t), 5)
    vel, acc, jrk = _finite_difference_ratios(q, dt, limits)
    assert vel.max() <= SLACK
    assert acc.max() <= SLACK
    if jerk:
        assert jrk.max() <= SLACK
    # The analytic derivatives agree with the positions.
    assert np.abs(np.diff(q, axis=0) / dt - 0.5 * (qd[1:] + qd[:-1])).max() <= 1e-3 * limits.velocity.max()

    tip_t = vp.forward_kinematics(machine, q, tool_length=TOOL).tip
    speed = np.linalg.norm(np.diff(tip_t, axis=0), axis=1) / dt
    block = plan.block_index(0.5 * (t[1:] + t[:-1]))
    feed_ratio = float(np.max(speed / feed[block]))
    assert feed_ratio <= SLACK
    return {"vel": float(vel.max()), "acc": float(acc.max()), "jerk": float(jrk.max()), "feed": feed_ratio}


# ---------------------------------------------------------------------------------------------
# Feed sequences
# ---------------------------------------------------------------------------------------------


def test_limits_from_machine_in_radians(machine: vp.Machine, limits: Limits) -> None:
    assert limits.velocity[0] == machine.joints.rho1.velocity
    assert limits.velocity[3] == pytest.approx(math.radians(machine.joints.theta1.velocity))
    assert limits.jerk[4] == pytest.approx(math.radians(machine.joints.theta2.jerk))
    with pytest.raises(ValueError):
        Limits(np.ones(5), np.ones(5), -np.ones(5))


def test_feed_limited_helix_takes_length_over_feed(machine: vp.Machine, limits: Limits,
                                                   helix_path: tuple[np.ndarray, np.ndarray]) -> None:
    joints, tip = helix_path
    feed = np.full(len(joints) - 1, 50.0)
    plan = plan_feed(joints, tip, feed, limits, angular_feed=1.0)
    worst = check_feed_plan(machine, plan, joints, tip, feed, limits)
    assert worst["feed"] >= 0.99  # it does run at the feed
    length = np.linalg.norm(np.diff(tip, axis=0), axis=1).sum()
    assert length / 50.0 <= plan.total <= 1.03 * length / 50.0
    bound = lower_bound_time(joints, tip, feed, limits)
    assert bound == pytest.approx(length / 50.0, rel=1e-9)
    assert bound <= plan.total
    base = baseline_time(joints, tip, feed, limits)
    assert bound <= base <= plan.total * 1.05


def test_joint_limited_helix_runs_at_the_joint_limits(machine: vp.Machine, limits: Limits,
                                                      helix_path: tuple[np.ndarray, np.ndarray]) -> None:
    joints, tip = helix_path
    feed = np.full(len(joints) - 1, 1e5)  # far above what the joints allow
    plan = plan_feed(joints, tip, feed, limits, angular_feed=1.0)
    worst = check_feed_plan(machine, plan, joints, tip, feed, limits)
    assert worst["feed"] < 0.1
    assert worst["vel"] >= 0.97  # the slowest joint reaches its velocity limit
    bound = lower_bound_time(joints, tip, feed, limits)
    assert bound <= plan.total <= 1.3 * bound


def test_zigzag_with_swinging_tool_axis(machine: vp.Machine, limits: Limits,
                                        zigzag_path: tuple[np.ndarray, np.ndarray]) -> None:
    joints, tip = zigzag_path
    feed = np.full(len(joints) - 1, 100.0)
    plan = plan_feed(joints, tip, feed, limits, angular_feed=1.0)
    check_feed_plan(machine, plan, joints, tip, feed, limits)
    bound = lower_bound_time(joints, tip, feed, limits)
    base = baseline_time(joints, tip, feed, limits)
    assert bound <= base <= plan.total
    assert plan.total <= 2.0 * bound  # curvature and jerk slow it down, but not without limit


def test_feed_changes_along_the_sequence(machine: vp.Machine, limits: Limits,
                                         helix_path: tuple[np.ndarray, np.ndarray]) -> None:
    joints, tip = helix_path
    feed = np.full(len(joints) - 1, 80.0)
    feed[300:500] = 20.0
    feed[700:] = 150.0
    plan = plan_feed(joints, tip, feed, limits, angular_feed=1.0)
    check_feed_plan(machine, plan, joints, tip, feed, limits)
    # The slow stretch runs at about its own feed: no block there is faster than 20 mm/s.
    length = np.linalg.norm(np.diff(tip, axis=0), axis=1)
    assert np.all(length[300:500] / plan.durations[300:500] <= 20.0 * (1 + 1e-9))
    assert plan.durations[350:450].sum() == pytest.approx(length[350:450].sum() / 20.0, rel=0.01)
    assert lower_bound_time(joints, tip, feed, limits) <= plan.total


def test_without_jerk_limit_velocity_and_acceleration_hold(machine: vp.Machine, limits: Limits,
                                                           zigzag_path: tuple[np.ndarray, np.ndarray]) -> None:
    joints, tip = zigzag_path
    feed = np.full(len(joints) - 1, 100.0)
    plan = plan_feed(joints, tip, feed, limits, angular_feed=1.0, jerk=False)
    check_feed_plan(machine, plan, joints, tip, feed, limits, jerk=False)
    assert plan.filter_width == 0.0
    assert plan.total <= plan_feed(joints, tip, feed, limits, angular_feed=1.0).total


def test_rotary_only_blocks_use_the_angular_feed(machine: vp.Machine, limits: Limits) -> None:
    n = 121
    a = np.linspace(0.0, 1.0, n)
    tip = np.tile([10.0, 5.0, 70.0], (n, 1))  # the tip stays on the part, the tool swings
    joints = joints_along(machine, tip, axis_from(np.radians(25.0 + 10.0 * a), 1.5 * a))
    feed = np.full(n - 1, 50.0)
    plan = plan_feed(joints, tip, feed, limits, angular_feed=0.5)
    check_feed_plan(machine, plan, joints, tip, feed, limits)
    t, dt = _uniform(plan.total)
    q, _, _ = plan.sample(t)
    rotary_rate = np.linalg.norm(np.diff(q[:, 3:], axis=0), axis=1) / dt
    assert rotary_rate.max() <= 0.5 * SLACK
    assert rotary_rate.max() >= 0.49
    tip_t = vp.forward_kinematics(machine, q, tool_length=TOOL).tip
    assert np.abs(tip_t - tip[0]).max() < 1e-3
    angle = np.linalg.norm(np.diff(joints[:, 3:], axis=0), axis=1).sum()
    assert angle / 0.5 <= plan.total <= 1.1 * angle / 0.5
    assert lower_bound_time(joints, tip, feed, limits, angular_feed=0.5) == pytest.approx(angle / 0.5, rel=1e-9)
    assert baseline_time(joints, tip, feed, limits, angular_feed=0.5) <= plan.total


def test_single_block_and_minimum_duration(machine: vp.Machine, limits: Limits,
                                           helix_path: tuple[np.ndarray, np.ndarray]) -> None:
    joints, tip = helix_path
    one = plan_feed(joints[:2], tip[:2], np.array([50.0]), limits, angular_feed=1.0)
    check_feed_plan(machine, one, joints[:2], tip[:2], np.array([50.0]), limits)
    feed = np.full(20, 1e4)
    short = plan_feed(joints[:21], tip[:21], feed, limits, angular_feed=1.0, min_duration=0.02)
    assert short.durations.min() >= 0.02 * (1 - 1e-9)
    check_feed_plan(machine, short, joints[:21], tip[:21], feed, limits)


def test_sharp_corner_is_refused_with_its_waypoint(limits: Limits) -> None:
    joints = np.tile([600.0, 600.0, 600.0, 0.2, 0.5], (11, 1))
    joints[:6, 0] += np.arange(6) * 1.0
    joints[6:, 0] += 5.0
    joints[6:, 1] += np.arange(1, 6) * 1.0  # 90 degree corner at waypoint 5
    tip = np.cumsum(np.ones((11, 3)), axis=0)
    with pytest.raises(PlanningError, match="waypoint 5") as info:
        plan_feed(joints, tip, np.full(10, 50.0), limits, angular_feed=1.0)
    assert info.value.index == 5
    assert info.value.exit_code == 3


def test_repeated_waypoint_is_refused(limits: Limits, helix_path: tuple[np.ndarray, np.ndarray]) -> None:
    joints, tip = helix_path
    joints = np.insert(joints[:10], 4, joints[4], axis=0)
    tip = np.insert(tip[:10], 4, tip[4], axis=0)
    with pytest.raises(PlanningError, match="block 4") as info:
        plan_feed(joints, tip, np.full(10, 50.0), limits, angular_feed=1.0)
    assert info.value.index == 4


@pytest.mark.parametrize("engine", ["copp", "toppra"])
def test_engine_failure_raises_with_the_waypoint(monkeypatch: pytest.MonkeyPatch, limits: Limits,
                                                 helix_path: tuple[np.ndarray, np.ndarray], engine: str) -> None:
    """Each engine's own way of failing half way along the path comes back naming that waypoint."""
    joints, tip = helix_path

    def toppra_fails(self: toppra.algorithm.TOPPRA, *args: object, **kwargs: object) -> tuple:
        controllable = np.ones((len(self.gridpoints), 2))
        controllable[: len(controllable) // 2] = np.nan  # backward pass broke down half way
        return None, None, None, controllable

    def copp_fails(problem: copp.solver.topp2_ra.Problem, options: object = None) -> np.ndarray:
        middle = problem.s_len // 2
        raise copp.CoppError(f"reach_set2 reported an infeasibility: The reachable set is empty at index {middle} "
                             f"during the backward pass where a_max = NaN, a_min = NaN")

    if engine == "toppra":
        monkeypatch.setattr(toppra.algorithm.TOPPRA, "compute_parameterization", toppra_fails)
    else:
        monkeypatch.setattr(copp.solver.topp2_ra, "solve", copp_fails)
    with pytest.raises(PlanningError, match=rf"{engine} found no feasible time law near waypoint \d+") as info:
        plan_feed(joints[:201], tip[:201], np.full(200, 50.0), limits, angular_feed=1.0, engine=engine)
    assert 80 <= info.value.index <= 120


def test_unmet_jerk_limit_raises_instead_of_returning(machine: vp.Machine, limits: Limits,
                                                      helix_path: tuple[np.ndarray, np.ndarray],
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """A short move needs a local slow-down round to meet the jerk limit: with none allowed it fails.
    (An S-curve along the path, rounds.Planner._scurve_plans, plans it within the limits at once:
    here the filtered plan alone.)"""
    joints, tip = helix_path
    feed = np.full(5, 50.0)
    plan = plan_feed(joints[:6], tip[:6], feed, limits, angular_feed=1.0, max_refinements=0)
    assert plan.gridpoints == 0  # the S-curve
    check_feed_plan(machine, plan, joints[:6], tip[:6], feed, limits)
    monkeypatch.setattr(rounds.Planner, "_scurve_plans", lambda self, seqs, planned: {})
    with pytest.raises(PlanningError, match="jerk limits found near waypoint"):
        plan_feed(joints[:6], tip[:6], feed, limits, angular_feed=1.0, max_refinements=0)
    plan = plan_feed(joints[:6], tip[:6], feed, limits, angular_feed=1.0)
    assert plan.refinements >= 1
    check_feed_plan(machine, plan, joints[:6], tip[:6], feed, limits)


def _reorientation(machine: vp.Machine, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A re-orientation as CAM writes it between two cuts: the tool axis tilts by 10 to 25 deg and
    turns by 0.2 to 0.5 rad about the table normal over 12 to 30 blocks while the tip creeps 0.5
    to 2 mm: (joints, tips)."""
    while True:
        n = int(rng.integers(13, 31))
        start = np.array([rng.uniform(-30, 30), rng.uniform(-30, 30), rng.uniform(60, 80)])
        creep = rng.normal(size=3)
        tip = start + np.linspace(0.0, 1.0, n)[:, None] * creep / np.linalg.norm(creep) * rng.uniform(0.5, 2.0)
        tilt0 = rng.uniform(5.0, 25.0)
        tilt = np.radians(np.linspace(tilt0, tilt0 + rng.choice([-1, 1]) * rng.uniform(10.0, 25.0), n))
        azimuth = rng.uniform(0, 2 * np.pi) + np.linspace(0.0, rng.choice([-1, 1]) * rng.uniform(0.2, 0.5), n)
        if tilt.min() < np.radians(3.0):
            continue
        try:
            return joints_along(machine, tip, axis_from(tilt, azimuth)), tip
        except ValueError:
            continue


def test_reorientations_take_a_faster_s_curve_within_every_limit(machine: vp.Machine, limits: Limits,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """Short re-orientations: the S-curve along the path (rounds.Planner._scurve_plans) is kept
    where it is faster than the filtered plan, and holds every limit at 1 ms."""
    rng = np.random.default_rng(7)
    moves = [_reorientation(machine, rng) for _ in range(24)]
    feeds = [np.full(len(joints) - 1, 50.0) for joints, _ in moves]
    plans = plan_feeds([(j, t, f) for (j, t), f in zip(moves, feeds, strict=True)], limits, angular_feed=1.0)
    monkeypatch.setattr(rounds.Planner, "_scurve_plans", lambda self, seqs, planned: {})
    filtered = plan_feeds([(j, t, f) for (j, t), f in zip(moves, feeds, strict=True)], limits, angular_feed=1.0)
    scurves = 0
    for (joints, tip), feed, plan, other in zip(moves, feeds, plans, filtered, strict=True):
        assert isinstance(plan, FeedPlan) and isinstance(other, FeedPlan)
        assert plan.total <= other.total
        scurves += plan.gridpoints == 0  # no TOPP2 grid: an S-curve
        worst = check_feed_plan(machine, plan, joints, tip, feed, limits)
        assert max(worst["acc"], worst["jerk"]) >= 0.9  # it does use the limits
        # finer than 1 ms finite differences can tell: the plan's own derivatives, densely
        _, qd, qdd, qddd = plan.sample_all(np.linspace(0.0, plan.total, 20001))
        for value, limit in ((qd, limits.velocity), (qdd, limits.acceleration), (qddd, limits.jerk)):
            assert np.max(np.abs(value) / limit) <= 1.0 + 1e-6
    assert scurves >= 20
    assert sum(p.total for p in plans) <= 0.995 * sum(p.total for p in filtered)  # 0.8 % when written


def _row_through_the_pole(machine: vp.Machine, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A finishing row over a dome (radius 70 mm) with the tool axis along its normal, passing
    1.5 to 4 mm beside the pole: the table turns half a turn in the middle of the row, theta2 at
    its velocity limit, as on the example job's dome: (joints, tips) over 150 to 220 blocks."""
    while True:
        n = int(rng.integers(150, 221))
        radius, offset = 70.0, rng.uniform(1.5, 4.0)
        x = np.linspace(-0.5, 0.5, n) * rng.uniform(40.0, 70.0) + rng.uniform(-3.0, 3.0)
        normal = np.stack([x, np.full(n, offset), np.sqrt(radius ** 2 - x ** 2 - offset ** 2)], axis=1) / radius
        tip = np.array([0.0, 0.0, 20.0]) + radius * normal
        try:
            return joints_along(machine, tip, normal), tip
        except ValueError:
            continue


def test_rows_through_the_pole_take_a_faster_third_order_plan_within_every_limit(machine: vp.Machine,
                                                                                 limits: Limits) -> None:
    """optimize=True: the third-order programme's plan (verne_post.planning.third_order) is kept where
    it is faster than the filtered plan, and holds every limit at 1 ms and at its own analytic
    derivatives."""
    rng = np.random.default_rng(11)
    rows = [_row_through_the_pole(machine, rng) for _ in range(6)]
    sequences = [(joints, tip, np.full(len(joints) - 1, 41.7)) for joints, tip in rows]
    filtered = plan_feeds(sequences, limits, angular_feed=1.0)
    optimized = plan_feeds(sequences, limits, angular_feed=1.0, optimize=True)
    programmed = 0
    for (joints, tip, feed), plan, other in zip(sequences, optimized, filtered, strict=True):
        assert isinstance(plan, FeedPlan) and isinstance(other, FeedPlan)
        assert plan.total <= other.total
        programmed += plan.gridpoints > other.gridpoints  # the programme's grid is twice as fine
        worst = check_feed_plan(machine, plan, joints, tip, feed, limits)
        assert worst["vel"] >= 0.95  # theta2 at its limit in the middle
        _, qd, qdd, qddd = plan.sample_all(np.linspace(0.0, plan.total, 20001))
        for value, limit in ((qd, limits.velocity), (qdd, limits.acceleration), (qddd, limits.jerk)):
            assert np.max(np.abs(value) / limit) <= 1.0 + 1e-6
    assert programmed == len(rows)
    # 2.0 % shorter when written; 1.3 % with the filtered jerk modelled at half its value (tried)
    assert sum(p.total for p in optimized) <= 0.983 * sum(p.total for p in filtered)


def test_s_curve_reaches_the_end_at_rest_within_each_phase_limits() -> None:
    """scurve._scurve: from rest to rest over s in [0, 1] with its own limits per phase; with
    the same limits in every phase, ruckig's time-optimal move."""
    rng = np.random.default_rng(3)
    count = 400
    cap = 10.0 ** rng.uniform(-1, 2, count)
    cap[::7] = 1e9  # no speed limit in reach
    acc = 10.0 ** rng.uniform(0, 3, (count, 2))
    jerk = 10.0 ** rng.uniform(1, 5, (count, 4))
    same = np.arange(count) < 100
    acc[same] = acc[same, :1]
    jerk[same] = jerk[same, :1]
    durations, jerks, _ = scurve._scurve(cap, acc, jerk)
    profiles = scurve.scurve_profiles(np.arange(count), durations, jerks)
    for r in range(count):
        b0, b1 = profiles.bfirst[r], profiles.bfirst[r + 1]
        law = feed_planner.Cubics(profiles.breaks[b0:b1], profiles.coef[:, b0 - r:b1 - r - 1])
        total = durations[r].sum()
        t = np.linspace(0.0, total, 2001)
        assert law(np.array([total]))[0] == pytest.approx(1.0, abs=1e-9)
        assert np.abs([law(np.array([x]), nu)[0] for x in (0.0, total) for nu in (1, 2)]).max() <= 1e-9 * cap[r]
        speed, acceleration = law(t, 1), law(t, 2)
        assert speed.min() >= -1e-9 * cap[r] and speed.max() <= cap[r] * (1 + 1e-9)
        middle = np.searchsorted(t, durations[r, :4].sum())
        assert acceleration[:middle].max() <= acc[r, 0] * (1 + 1e-9)
        assert -acceleration[middle:].min() <= acc[r, 1] * (1 + 1e-9)
        assert np.array_equal(np.abs(jerks[r, [0, 2, 4, 6]]), jerk[r])
        if same[r]:
            assert total == pytest.approx(ruckig_time(1.0, cap[r], acc[r, 0], jerk[r, 0]), rel=1e-7)


def test_bad_input_is_a_value_error(limits: Limits, helix_path: tuple[np.ndarray, np.ndarray]) -> None:
    joints, tip = helix_path
    feed = np.full(10, 50.0)
    with pytest.raises(ValueError, match="feed"):
        plan_feed(joints[:11], tip[:11], feed[:9], limits, angular_feed=1.0)
    with pytest.raises(ValueError, match="positive"):
        plan_feed(joints[:11], tip[:11], np.r_[feed[:9], 0.0], limits, angular_feed=1.0)
    bad = joints[:11].copy()
    bad[3, 2] = np.nan
    with pytest.raises(ValueError, match="index 3"):
        plan_feed(bad, tip[:11], feed, limits, angular_feed=1.0)
    with pytest.raises(ValueError, match="angular_feed"):
        plan_feed(joints[:11], tip[:11], feed, limits, angular_feed=0.0)


# ---------------------------------------------------------------------------------------------
# Lower bound and baseline
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("engine", ["copp", "toppra"])
def test_both_engines_plan_the_zigzag_alike(machine: vp.Machine, limits: Limits,
                                            zigzag_path: tuple[np.ndarray, np.ndarray], engine: str) -> None:
    """copp-py and toppra solve the same TOPP2 problems: each plan holds every limit, same duration."""
    joints, tip = zigzag_path
    feed = np.full(len(joints) - 1, 100.0)
    plan = plan_feed(joints, tip, feed, limits, angular_feed=1.0, engine=engine)
    check_feed_plan(machine, plan, joints, tip, feed, limits)
    other = plan_feed(joints, tip, feed, limits, angular_feed=1.0, engine="toppra" if engine == "copp" else "copp")
    assert plan.total == pytest.approx(other.total, rel=2e-3)


def test_sequences_planned_together_are_planned_as_alone(machine: vp.Machine, limits: Limits,
                                                         helix_path: tuple[np.ndarray, np.ndarray],
                                                         zigzag_path: tuple[np.ndarray, np.ndarray]) -> None:
    """One batch of different sequences (one refused) gives each exactly the plan it gets on its own."""
    (hj, ht), (zj, zt) = helix_path, zigzag_path
    repeated = np.insert(hj[:10], 4, hj[4], axis=0), np.insert(ht[:10], 4, ht[4], axis=0)
    sequences = [(hj[:300], ht[:300], np.full(299, 40.0)), (zj, zt, np.full(len(zj) - 1, 100.0)),
                 (repeated[0], repeated[1], np.full(10, 50.0)), (hj[500:503], ht[500:503], np.full(2, 30.0)),
                 (hj[600:602], ht[600:602], np.full(1, 30.0))]
    together = plan_feeds(sequences, limits, angular_feed=1.0)
    assert isinstance(together[2], PlanningError) and together[2].index == 4
    for (joints, tip, feed), plan in zip(sequences, together, strict=True):
        if isinstance(plan, PlanningError):
            continue
        alone = plan_feed(joints, tip, feed, limits, angular_feed=1.0)
        # to the last bit: a program posted whole or in parts, on any number of processes, gets
        # the same G-code
        np.testing.assert_array_equal(plan.durations, alone.durations)
        check_feed_plan(machine, plan, joints, tip, feed, limits)
    # and many of random lengths and feeds: 14 of these 112 differed while a waypoint time, once
    # its Newton iteration had converged, still moved on with the batch's others
    pieces = [piece for seed in range(4) for piece in feed_pieces(machine, seed, longest=150)]
    for (joints, tip, feed), plan in zip(pieces, plan_feeds(pieces, limits, angular_feed=1.0), strict=True):
        alone = plan_feed(joints, tip, feed, limits, angular_feed=1.0)
        assert isinstance(plan, FeedPlan)
        np.testing.assert_array_equal(plan.durations, alone.durations)
        np.testing.assert_array_equal(plan.block_times, alone.block_times)


def test_a_program_split_by_work_over_processes_is_planned_as_in_one(monkeypatch: pytest.MonkeyPatch, limits: Limits,
                                                                     helix_path: tuple[np.ndarray, np.ndarray]) -> None:
    """plan_program cuts the feed sequences into contiguous runs of about equal work, this
    process's the larger by a helper's cost, and gets the same schedule to the last bit on one
    process as on two or three."""
    rapid = np.zeros(546, bool)
    rapid[np.cumsum([1] + [121] * 4 + [2] * 30)] = True  # 4 sequences of 120 blocks, then 30 of one
    joints, tip = (a[:len(rapid)] for a in helix_path)
    feed = np.random.default_rng(5).uniform(20.0, 60.0, len(joints))
    group = np.zeros(len(joints), int)
    args = (joints, tip, rapid, feed, group, limits)
    kwargs = {"rotary_feed": 1.0, "corner": math.radians(30.0)}
    monkeypatch.setattr(schedule, "_PROCESS_WORK", 100)  # this small program is then worth 3 processes
    ranges = schedule.feed_sequences(joints, rapid, group, limits, kwargs["corner"])
    work = np.array([schedule._ONE_BLOCK_WORK if a == b else b - a + 1 + schedule._SEQUENCE_WORK
                     for a, b in ranges])
    for parts in (2, 3):
        runs = schedule._split(list(range(len(ranges))), work, parts)
        assert len(runs) == parts and [i for run in runs for i in run] == list(range(len(ranges)))
        done = [work[run].sum() for run in runs]
        for other in done[1:]:
            assert abs(done[0] - other - schedule._PROCESS_WORK) <= work.max()
    one = schedule.plan_program(*args, **kwargs, workers=1)
    for workers in (2, 3):
        many = schedule.plan_program(*args, **kwargs, workers=workers)
        np.testing.assert_array_equal(many.duration, one.duration)
        assert [(s.first, s.last, s.rapid) for s in many.segments] == [(s.first, s.last, s.rapid) for s in one.segments]
    # The third-order programme too (HiGHS gives the same answer in any process), never slower.
    optimized = schedule.plan_program(*args, **kwargs, workers=1, optimize=True)
    np.testing.assert_array_equal(schedule.plan_program(*args, **kwargs, workers=2, optimize=True).duration,
                                  optimized.duration)
    assert optimized.duration.sum() <= one.duration.sum()


def test_batched_splines_are_scipys_not_a_knot_splines() -> None:
    """The one tridiagonal solve for many sequences (cyclic reduction, no pivoting) gives each
    scipy's CubicSpline (LAPACK's banded solve with pivoting): 2 to 12 points, and up to 600 with
    neighbouring intervals up to 1e4 apart in length."""
    rng = np.random.default_rng(7)
    for sizes, spread in ((rng.integers(2, 13, size=300), 0.0), (rng.integers(2, 600, size=60), 4.0)):
        x = np.concatenate([np.cumsum(rng.uniform(0.5, 1.5, n) * 10.0 ** rng.uniform(-spread, 0.0, n)) for n in sizes])
        y = rng.normal(size=(len(x), 4))
        first = np.r_[0, np.cumsum(sizes)]
        coef = not_a_knot(x, y, first)
        for r, n in enumerate(sizes):
            a = first[r]
            reference = CubicSpline(x[a:a + n], y[a:a + n], axis=0, bc_type="not-a-knot")
            # each term's reach over its interval, c_k h^(3 - k), in units of y
            reach = np.diff(x[a:a + n])[None, :, None] ** np.arange(3, -1, -1)[:, None, None]
            np.testing.assert_allclose(coef[:, a - r:a - r + n - 1] * reach, reference.c * reach, rtol=1e-11,
                                       atol=1e-10 * np.max(np.abs(y)))


def test_piece_search_is_the_exact_search_within_each_sequence() -> None:
    """_Pieces.search (one real search over the sequences laid end to end, then corrected) finds
    what searching each sequence's own starts finds, with queries on, and within a few ulps of,
    the starts, outside the sequences and in empty ones, at scales from 1e-3 to 1e4."""
    rng = np.random.default_rng(11)
    for _ in range(200):
        scale = 10.0 ** rng.uniform(-3.0, 4.0)
        starts = []
        for count in rng.integers(0, 9, size=int(rng.integers(1, 30))):
            if rng.random() < 0.5:  # starts packed a few ulps of the shift apart
                starts.append(scale * (rng.random() + np.cumsum(rng.uniform(1e-15, 1e-11, count))))
            else:
                starts.append(np.unique(rng.uniform(0.0, scale, count)))
        first = np.r_[0, np.cumsum([len(v) for v in starts])]
        if first[-1] == 0:
            continue
        pieces = segments.Pieces(np.concatenate(starts), first)
        seq = rng.integers(0, len(starts), size=600)
        x = rng.uniform(-scale, 2.0 * scale, size=600)
        near = rng.random(600) < 0.8
        pick = rng.integers(0, first[-1], size=600)
        seq[near] = pieces.owner[pick[near]]
        x[near] = pieces.start[pick[near]] * (1.0 + rng.choice([-1.0, 1.0], near.sum())
                                              * rng.choice([0.0, 1e-16, 3e-16, 1e-15, 1e-13], near.sum()))
        for side in ("left", "right"):
            expected = [first[r] + np.searchsorted(starts[r], v, side=side) for r, v in zip(seq, x, strict=True)]
            np.testing.assert_array_equal(pieces.search(seq, x, side), expected)


@pytest.mark.parametrize("speed", [50.0, 300.0, 800.0])
def test_straight_move_is_near_the_time_optimal_jerk_limited_one(limits: Limits, speed: float) -> None:
    """One slider along a straight line at a feed it can reach: the exact time-optimal
    jerk-limited rest-to-rest move (analytic S-curve) bounds the plan from below, and the
    per-sequence filter width keeps it close (the filter is exact where full acceleration is
    not needed; where it is, at most the 3 % acceleration margin and a 25 % wider window)."""
    length = 400.0
    rho = 600.0 + np.linspace(0.0, length, 201)
    joints = np.column_stack([rho, np.full_like(rho, 600.0), np.full_like(rho, 600.0), np.full_like(rho, 0.2),
                              np.full_like(rho, 0.5)])
    tip = np.column_stack([rho, np.zeros_like(rho), np.zeros_like(rho)])
    a, j = limits.acceleration[0], limits.jerk[0]
    ramp = 2.0 * math.sqrt(speed / j) if speed <= a * a / j else speed / a + a / j  # 0 -> speed
    optimal = length / speed + ramp
    plan = plan_feed(joints, tip, np.full(200, speed), limits, angular_feed=1.0)
    assert optimal * (1 - 1e-6) <= plan.total <= optimal * (1.005 if speed <= a * a / j else 1.03)


@pytest.mark.parametrize("jerk", [True, False])
def test_one_block_is_the_time_optimal_move_along_its_line(machine: vp.Machine, limits: Limits, jerk: bool) -> None:
    """A one-block sequence is a line in joint space with the same caps all along: its plan is
    the time-optimal rest-to-rest move in the path parameter, ruckig's (or, without jerk
    limits, the trapezoid's) under the path speed, acceleration and jerk the joints and the feed
    allow, on 300 random moves of all five joints (1 um to 300 mm, up to about 0.06 rad of the
    table); the certified peaks are the time law's own, and every limit holds."""
    rng = np.random.default_rng(17)
    start = np.array([600.0, 650.0, 700.0, 0.2, 0.5])
    for k in range(300):
        dq = rng.normal(size=5) * 10.0 ** rng.uniform(-3.0, 2.5) * np.r_[1.0, 1.0, 1.0, 1e-4, 2e-4]  # mm, rad
        joints = np.stack([start, start + dq])
        tip = vp.forward_kinematics(machine, joints, tool_length=TOOL).tip
        feed = np.array([10.0 ** rng.uniform(0.0, 3.0)])  # 1 to 1000 mm/s
        plan = plan_feed(joints, tip, feed, limits, angular_feed=1.0, jerk=jerk)
        chord = np.linalg.norm(tip[1] - tip[0])
        speed = min(np.min(limits.velocity / np.abs(dq)), feed[0] / chord, 1.0 / 1e-4)
        acc = np.min(limits.acceleration / np.abs(dq))
        if jerk:
            best = ruckig_time(1.0, speed, acc, np.min(limits.jerk / np.abs(dq)))
        else:
            best = 2.0 / math.sqrt(acc) if speed ** 2 >= acc else 1.0 / speed + speed / acc
        assert plan.total == pytest.approx(best, rel=1e-9), (k, plan.total / best)
        # the certified peaks are the time law's own (sampled, at its breaks too)
        _, *rates = plan.sample_all(np.r_[np.linspace(0.0, plan.total, 2001), plan.profile.breaks])
        sampled = [np.abs(r).max(axis=0) / limit for r, limit in
                   zip(rates, (limits.velocity, limits.acceleration, limits.jerk), strict=True)]
        np.testing.assert_allclose(plan.peak_ratios, sampled if jerk else [*sampled[:2], np.zeros(5)], rtol=1e-6,
                                   atol=1e-12)
        if k % 30 == 0:  # every limit, at 1 ms, the feed by the forward kinematics
            check_feed_plan(machine, plan, joints, tip, feed, limits, jerk=jerk)


@pytest.mark.parametrize("jerk", [True, False])
def test_long_slow_block_ramps_as_fast_as_the_limits_allow(limits: Limits, jerk: bool) -> None:
    """A plunge: a long move of one slider at a slow feed, written as two blocks (so planned by
    TOPP2 and the filter, not in closed form as one block is). TOPP2 holds the path
    acceleration over a grid interval, so a ramp from rest lasts the whole first interval
    unless the ends are refined: the plan took 6 % over the optimum before they were. The
    optimum is the analytic rest-to-rest move (a trapezoid without jerk limits, the S-curve with
    them); the plan within 0.5 % of it, and within every limit."""
    rng = np.random.default_rng(5)
    a, j = limits.acceleration[0], limits.jerk[0]
    for length, speed in zip(rng.uniform(5.0, 40.0, 6), rng.uniform(2.0, 12.0, 6), strict=True):  # mm, mm/s
        joints = np.tile([600.0, 650.0, 700.0, 0.2, 0.5], (3, 1))
        joints[1:, 0] += [1.0, length]  # a 1 mm block, then the long one
        tip = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, -length]])
        best = (ruckig_time(length, speed, a, j) if jerk else length / speed + speed / a)
        plan = plan_feed(joints, tip, np.array([speed, speed]), limits, angular_feed=1.0, jerk=jerk)
        assert best * (1 - 1e-6) <= plan.total <= 1.005 * best, (length, speed, plan.total / best)
        t, dt = _uniform(plan.total)
        vel, acc, jerks = _finite_difference_ratios(plan.sample(t)[0], dt, limits)
        assert max(vel.max(), acc.max(), *([jerks.max()] if jerk else [])) <= SLACK


@pytest.mark.parametrize("jerk", [True, False])
def test_feed_is_held_where_the_tip_speed_per_unit_of_path_changes(limits: Limits, jerk: bool) -> None:
    """The tip runs straight at the feed while the table turns at a rate that swings fourfold
    along the row, so the path-speed cap the feed sets (its tip speed per unit of the joint-space
    parameter) changes all along the sequence; every joint stays far below its limits. The plan
    must ride the feed: within 1 % (plus the ramps at the ends) of the row's length over the
    feed, the velocity-only lower bound; 4 % with jerk limits, whose filter has each cap hold a
    little way either side of its point. Taking each gridpoint's cap as the lowest over its two
    intervals took 3.7 % (5.3 % with jerk limits)."""
    blocks, step, feed = 400, 0.5, 40.0  # mm, mm, mm/s
    k = np.arange(blocks + 1)
    turn = np.r_[0.0, np.cumsum(0.01 * (1.0 + 3.0 * np.sin(np.pi * k[1:] / blocks * 3.0) ** 2))]  # rad
    joints = np.column_stack([np.full(blocks + 1, 600.0), np.full(blocks + 1, 650.0), np.full(blocks + 1, 700.0),
                              np.full(blocks + 1, 0.2), 0.5 + turn])
    tip = np.column_stack([step * k, np.zeros(blocks + 1), np.zeros(blocks + 1)])
    bound = lower_bound_time(joints, tip, np.full(blocks, feed), limits)
    assert bound == pytest.approx(blocks * step / feed)
    plan = plan_feed(joints, tip, np.full(blocks, feed), limits, angular_feed=1.0, jerk=jerk)
    assert bound <= plan.total <= (1.04 if jerk else 1.01) * bound + 0.05, plan.total / bound


def test_short_moves_that_turn_without_cruise_are_near_the_time_optimal_ones(limits: Limits) -> None:
    """A move too short to reach its feed accelerates then slows down at once (a re-orientation
    in place, a short link): the filter would double the jerk at that turn, so the plan gets a
    plateau of one filter width instead of a lower acceleration, and a window as narrow as the
    ramp to its peak speed needs. Straight moves of one slider or of the tilt, with and without
    full acceleration: within 8 % of the time-optimal S-curve (lowering the acceleration, as
    before, took 12 to 23 % more), and within every limit."""
    rng = np.random.default_rng(11)
    sequences, optimal, moving = [], [], []
    for joint, low, high in ((0, 8.0, 45.0), (0, 55.0, 100.0), (2, 55.0, 100.0), (3, 0.03, 0.15),
                             (3, 0.16, 1.0)):  # mm, mm, mm, rad, rad
        for distance in rng.uniform(low, high, 4):
            joints = np.tile([600.0, 650.0, 700.0, 0.2, 0.5], (41, 1))
            joints[:, joint] += np.linspace(0.0, distance, 41)
            tip = np.zeros((41, 3))
            tip[:, 0] = np.linspace(0.0, 1.0, 41)  # a tip motion of 1 mm: the feed does not bind
            sequences.append((joints, tip, np.full(40, 1e4)))
            optimal.append(ruckig_time(distance, limits.velocity[joint], limits.acceleration[joint],
                                                      limits.jerk[joint]))
            moving.append(joint)
    plans = plan_feeds(sequences, limits, angular_feed=100.0)
    for plan, best, joint in zip(plans, optimal, moving, strict=True):
        assert isinstance(plan, FeedPlan)
        assert best * (1 - 1e-6) <= plan.total <= 1.08 * best, (joint, plan.total / best)
        t, dt = _uniform(plan.total)
        vel, acc, jerk = _finite_difference_ratios(plan.sample(t)[0], dt, limits)
        assert max(vel.max(), acc.max(), jerk.max()) <= SLACK


def test_baseline_of_a_straight_line_is_a_trapezoid(limits: Limits) -> None:
    joints = np.tile([500.0, 600.0, 700.0, 0.1, 0.2], (2, 1))
    joints[1, 0] += 100.0  # rho1 alone moves 100 mm, the tip 100 mm
    tip = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]])
    for feed, speed in ((50.0, 50.0), (5000.0, limits.velocity[0])):
        expected = 100.0 / speed + speed / limits.acceleration[0]
        assert baseline_time(joints, tip, np.array([feed]), limits) == pytest.approx(expected, rel=1e-12)
        assert lower_bound_time(joints, tip, np.array([feed]), limits) == pytest.approx(100.0 / speed)


def test_baseline_decelerates_for_a_slower_block(limits: Limits) -> None:
    joints = np.tile([500.0, 600.0, 700.0, 0.1, 0.2], (4, 1))
    joints[:, 0] += [0.0, 100.0, 101.0, 201.0]
    tip = np.zeros((4, 3))
    tip[:, 0] = joints[:, 0]
    slow = baseline_time(joints, tip, np.array([500.0, 1.0, 500.0]), limits)
    fast = baseline_time(joints, tip, np.array([500.0, 500.0, 500.0]), limits)
    a = limits.acceleration[0]
    # two 100 mm trapezoids at 500 mm/s (down to 1 mm/s, not to rest) and 1 mm at 1 mm/s
    assert slow == pytest.approx(2 * (100.0 / 500.0 + 500.0 / a) + 1.0, rel=1e-3)
    assert fast < slow


# ---------------------------------------------------------------------------------------------
# Rapids
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("delta", "scale"), [
    ([300.0, -120.0, 40.0, 0.4, 2.5], 1.0),  # long: cruises at the velocity limit
    ([3.0, 1.0, -2.0, 0.001, 0.01], 1.0),  # short: never reaches it
    ([0.0, 0.0, 0.0, -0.8, 0.0], 0.5),  # one rotary joint, slower rapid limits
])
def test_rapid_is_jerk_limited_and_straight(limits: Limits, delta: list[float], scale: float) -> None:
    rapid_limits = limits.scaled(scale, scale, scale)
    start = np.array([600.0, 650.0, 700.0, 0.2, -1.0])
    end = start + delta
    rapid = plan_rapid(start, end, rapid_limits)
    assert rapid.duration > 0
    assert rapid.duration >= np.max(np.abs(end - start) / rapid_limits.velocity)
    t, dt = _uniform(rapid.duration)
    q, qd, qdd = rapid.sample(t)
    vel, acc, jerk = _finite_difference_ratios(q, dt, rapid_limits)
    assert max(vel.max(), acc.max(), jerk.max()) <= SLACK
    assert np.abs(q[0] - start).max() <= 1e-9 and np.abs(q[-1] - end).max() <= 1e-9
    assert np.abs(qd[[0, -1]]).max() <= 1e-9 and np.abs(qdd[[0, -1]]).max() <= 1e-9
    # Every sample on the segment start..end, moving forward along it.
    d = end - start
    along = (q - start) @ d / (d @ d)
    off = q - start - along[:, None] * d
    assert np.abs(off).max() <= 1e-9 * max(1.0, np.abs(d).max())
    assert along.min() >= -1e-12 and along.max() <= 1 + 1e-12
    assert np.all(np.diff(along) >= -1e-12)


def test_rapid_of_zero_length(limits: Limits) -> None:
    start = np.array([600.0, 650.0, 700.0, 0.2, -1.0])
    rapid = plan_rapid(start, start.copy(), limits)
    assert rapid.duration == 0.0
    q, qd, _ = rapid.sample(np.array([0.0, 1.0]))
    assert np.all(q == start) and np.all(qd == 0.0)


def test_rapid_beyond_ruckigs_duration_limit_is_a_planning_error(limits: Limits) -> None:
    """ruckig refuses trajectories longer than its duration limit (a corrupt turn of the table by
    millions of degrees asks for one): a planning error, not a crash."""
    start = np.array([600.0, 600.0, 600.0, 0.0, 0.0])
    with pytest.raises(PlanningError, match="ruckig could not plan the rapid"):
        plan_rapid(start, start + np.array([0.0, 0.0, 0.0, 0.0, 1.7e5]), limits)


def test_a_sequence_the_tight_plan_cannot_certify_gets_the_safe_plan(
        monkeypatch: pytest.MonkeyPatch, machine: vp.Machine, limits: Limits,
        zigzag_path: tuple[np.ndarray, np.ndarray]) -> None:
    """A sequence whose tight plan (own filter width, short cap reach) cannot be brought within
    the limits is planned again the safe way (widest filter, long reach), not refused (found on
    a 3M-point job)."""
    joints, tip = zigzag_path
    feed = np.full(len(joints) - 1, 100.0)
    real = rounds.Planner.plan

    def tight_fails(self: rounds.Planner) -> list:
        plans = real(self)
        return [PlanningError("tight plan failed", 0) for _ in plans] if self.erode < 0.5 else plans

    monkeypatch.setattr(rounds.Planner, "plan", tight_fails)
    plan = plan_feed(joints, tip, feed, limits, angular_feed=1.0)
    assert plan.filter_width == pytest.approx(1.25 * np.max(limits.acceleration / limits.jerk))
    check_feed_plan(machine, plan, joints, tip, feed, limits)
