"""A third-order reference for the feed plans: copp-py's TOPP3-LP on a sequence, apart from the planner.

The planner gets jerk limits by filtering a second-order (TOPP2) profile. How far is that from
what an exact third-order method reaches? copp-py (https://copp.pro, MIT) solves TOPP3 as a
linear programme with the joint jerk constraints linearised around a reference profile
(``copp.solver.topp3_lp``; Wang et al., the copp-py documentation): here linearised around the
TOPP2 solution, then twice more around its own result.

The path model is built here, not taken from the planner: a scipy ``CubicSpline``
(not-a-knot) of the joints through the waypoints, parametrised by the normalised joint-space
chord length weighted by 1 / velocity limit; caps pointwise at the stations: the joint
velocity, acceleration and jerk limits (copp-py's ``Robot`` rows) and the programmed feed as a
cap on the tip speed, with the tip a spline over the same parameter. Stations: 500 per second of
estimated motion, at least 200. The planner's own extras (the minimum block duration, chord caps
between stations) are left out, so the TOPP2 time here, T2, is a little below the planner's T0;
the ratio T3 / T2 is the jerk limits' cost by this method, to set beside the planner's T / T0.

Units: joints (K + 1, 5) mm and rad, tips (K + 1, 3) mm, feeds (K,) mm/s, times s.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from verne_post.planning.timing import TIP_EPS, Limits

STATIONS_PER_SECOND = 500
MIN_STATIONS = 200
LINEARISATIONS = 3


def topp3_reference(joints: np.ndarray, tip: np.ndarray, feed: np.ndarray, limits: Limits
                    ) -> tuple[float, float] | None:
    """(T2, T3) in s of one feed sequence from rest to rest: copp-py's TOPP2 and TOPP3-LP on the
    same stations and caps (T3 of the last linearisation the LP solved within its constraints);
    None for a sequence with a rotary-only block (no tip motion to cap) or where the LP failed."""
    import copp_py as copp

    chords = np.linalg.norm(np.diff(tip, axis=0), axis=1)
    if np.any(chords < TIP_EPS):
        return None
    weighted = np.linalg.norm(np.diff(joints, axis=0) / limits.velocity, axis=1)
    knots = np.r_[0.0, np.cumsum(weighted)] / np.sum(weighted)
    q, p = CubicSpline(knots, joints), CubicSpline(knots, tip)
    n = int(max(MIN_STATIONS, STATIONS_PER_SECOND * np.sum(chords / feed)))
    s = np.linspace(0.0, 1.0, n)
    block = np.clip(np.searchsorted(knots, s, side="right") - 1, 0, len(feed) - 1)
    feed_cap = (feed[block] / np.maximum(np.linalg.norm(p(s, 1), axis=1), 1e-12)) ** 2  # on (ds/dt)^2
    robot = copp.Robot(joints.shape[1], capacity=n)
    robot.append_s(s)
    robot.set_q(q(s), q(s, 1), q(s, 2), 0, dddq=q(s, 3))
    robot.add_velocity_limits(limits.velocity, -limits.velocity, start_idx_s=0)
    robot.add_acceleration_limits(limits.acceleration, -limits.acceleration, start_idx_s=0)
    robot.add_jerk_limits(limits.jerk, -limits.jerk, start_idx_s=0)
    robot.constraints.add_constraint_1st(feed_cap.reshape(n, 1), 0)
    problem = copp.solver.topp2_ra.Problem(robot.constraints, (0, n - 1), (0.0, 0.0))
    a2 = np.maximum(np.asarray(copp.solver.topp2_ra.solve(problem)), 0.0)
    t2, _ = copp.interpolation.s_to_t_topp2(s, a2)
    reference, b, t3 = np.maximum(a2, 1e-6 * a2.max()), None, None
    for _ in range(LINEARISATIONS):
        try:
            profile = copp.solver.topp3_lp.solve(
                copp.solver.topp3_lp.Problem(robot.constraints, reference, b_linearization=b))
        except copp.CoppError:  # Clarabel's "InsufficientProgress": keep the last profile it solved
            break
        profile.force_positive_a(s)
        if max(robot.constraints.exceed_topp3(profile)) > 1e-6:
            break
        reference, b = np.maximum(profile.a, 1e-9), profile.b
        t3, _ = copp.interpolation.s_to_t_topp3(s, profile)
    return None if t3 is None else (float(t2), float(t3))
