"""Time laws of feed sequences, planned for all the sequences of a program at once.

Units: joints (N, 5) are rho1..3 in mm and theta1, theta2 in rad; tool tips in mm relative to
the part; times in s; limits per second (mm/s, rad/s, mm/s^2, ...). Nothing here reads files.

The controller moves linearly in joint space between the waypoints of a feed sequence; the
polyline is smooth (small turning angles), so the planner sees a C2 cubic spline through the
waypoints (not-a-knot, as scipy's ``CubicSpline``), parametrised by the normalised cumulative
joint-space arc length s in [0, 1] (each joint weighted by 1 / its velocity limit, so mm and
rad mix sensibly). The spline passes through every waypoint at its s value; between them it
stays within the chordal tolerance of the polyline. Each sequence runs from rest to rest and is
planned in four steps:

1. Velocity caps on the path speed sdot(s) (1/s): per block the programmed feed as a limit on
   the tool-tip speed, ``|d tip/ds| * sdot <= F``, with ``|d tip/ds|`` both the block's tip
   chord over its s length and, pointwise, the derivative of a spline through the tips with
   the same parameter (rotary-only blocks: ``|d(theta1, theta2)/ds| * sdot <= angular_feed``);
   a minimum block duration; pointwise the joint velocity limits ``|q_j'(s)| sdot <= v_j`` and
   a centripetal-jerk cap ``|q_j'''(s)| sdot^3 <= 0.7 J_j``, evaluated at every waypoint, block
   middle and gridpoint, so the feed holds on every block even where the grid is coarser (the
   squared path speed being linear in s between gridpoints, the gridpoints of an interval are
   lowered until its line meets every cap inside it: a cap that changes along the path, as the
   tip's speed per unit of s does, is followed, not its lowest value over two intervals).
2. TOPP2 (:mod:`verne_post.planning.topp`: copp-py by default, toppra as the reference) with those caps
   and the joint accelerations ``|q_j' sddot + q_j'' sdot^2| <= 0.97 a_j``, time-scaled so the
   squared path speeds are O(1). A grid interval every ``w / 4`` of travel at the capped speed
   (long blocks subdivided, runs of short blocks merged), at least 32, at most about one per
   block: the cost follows the path's duration, not its waypoint count; the intervals at either
   end halved until they take at most ``w / 4`` (the ramp from rest lasts one interval).
3. Jerk: the constant-acceleration profile sigma(t) is filtered by a moving average of width w
   (an FIR filter along the path, as CNC controllers limit jerk, so the motion stays on the
   path): ``s(t) = 1/w * integral_{t-w}^{t} sigma``, a piecewise cubic whose path jerk is
   ``(sigma''(t) - sigma''(t - w)) / w``. A rest-to-rest ramp to a joint speed V by such a
   filter takes ``V / u + w``, with the path acceleration u bounded so that ``u / w`` meets the
   jerk limit J: the least is ``2 sqrt(V / J)`` at ``w = sqrt(V / J)``, ``u = J w``, which is
   exactly the time-optimal jerk-limited ramp. So each sequence gets its own width: the
   largest ``sqrt(|qdot_j| / J_j)`` over its capped joint speeds, at most
   ``1.1 max_j(a_j / J_j)`` (where full acceleration pays), and toppra's path acceleration
   bound is ``min(a_j, w J_j) / max |q_j'|`` over the window. The filtered speed mixes the speeds
   within a window of travel, so each cap is imposed over ``0.1 w * (its own speed)`` of travel
   on either side (a step down of the feed is reached that much early; the verification and its
   local slow-downs take care of the rest).
4. Verification of the exact trajectory (joint velocity, acceleration, jerk, tip feed, angular
   feed, analytic derivatives) at several samples of every polynomial piece of the time law and
   both sides of every waypoint. Where a limit is exceeded, the speed caps (excess due to speed
   and curvature) or the acceleration bound (excess due to path acceleration and jerk) are
   lowered around it in proportion and that sequence is planned again. A sequence that still
   exceeds a limit after ``max_refinements`` rounds is planned once more the safe way (the
   widest filter, caps imposed over ``w / 2 * speed``); if that fails too it gets a
   :class:`PlanningError`: nothing is returned unchecked.

   One excess gets another remedy: a speed peak with no cruise, where the path acceleration
   turns from +u to -u within one filter window, so the filter sees a step of 2u and doubles
   the jerk (ratio 1.5 to 1.6 on the re-orientations of the 105k job). Lowering u there costs
   time where it is most expensive; instead the sequence's speed is capped just below its peak,
   at the level where the profile cruises for one filter width: the two steps of u then fall
   in different windows. For a straight move this filter of an accelerate-cruise-decelerate
   profile is exactly the time-optimal jerk-limited (7-segment) S-curve, the cruise of the
   unfiltered profile becoming the jerk-free stretch where the acceleration changes sign, once
   the window is the one the ramp to the peak speed needs: a peak too slow for full
   acceleration first gets the narrower ``sqrt(V / J)``, then its plateau.

A one-block sequence needs none of this: a line in joint space with the same caps all along,
its time-optimal move is the 7-segment S-curve in s (the trapezoid without jerk limits), in
closed form, its peaks the limits it meets (:func:`straight_plans`). A short multi-block
sequence (a re-orientation) is also tried as an S-curve in s, each ramp and jerk phase with the
limits of the stretch it covers (:func:`scurve_laws`); verified as in step 4, it replaces the
filtered plan where it is faster. With ``optimize``, each sequence of more than 40 blocks is also
planned by a linear programme (:mod:`verne_post.planning.third_order`) whose squared path speeds,
filtered by a window two of its longest grid intervals wide, meet the jerk limits as that filter
produces them; verified the same way, the plan replaces the filtered one where it is faster
(:func:`.feed.lp.third_order_plans`).

Every step is vectorised over all the sequences together (arrays concatenated, each element
knowing its sequence); only the TOPP2 solve (and the programme) runs once per sequence.
Positions within a sequence are kept local (s in [0, 1], t from 0), so precision does not
depend on the program's length.

Block durations are the times between the path parameter values of the waypoints, so sampling
at the cumulative durations gives back the waypoints.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .feed.batch import Batch, concatenate, refusals, select
from .feed.lp import third_order_plans
from .feed.plan import Cubics, FeedPlan
from .feed.rounds import Planner
from .feed.scurve import straight_plans
from .timing import Limits, PlanningError
from .topp import Engine, solver

__all__ = ["Cubics", "FeedPlan", "plan_feed", "plan_feeds"]

# Tries in turn (a sequence goes to the next only if the last could not be brought within every
# limit): (erode, widest): a cap holds over erode * w * (its own speed) of travel on either side
# of its point; widest: the filter is SAFE_FIR_FACTOR max(a / J) wide instead of the sequence's
# own width.
# The last is the safe setting of the planner before per-sequence widths.
_TRIES = ((0.1, False), (0.5, True))
# The third-order programme (optimize=True, verne_post.planning.third_order): on sequences of more blocks
# than this (shorter ones gained nothing on the 105k job: their S-curves are as good), on a grid
# this much finer, with these shares of the acceleration and jerk limits (the programme sees them
# at the gridpoints only; 1.0 gives the same plans, after more rounds), in at most this many rounds.
LP_MIN_BLOCKS = 40
_LP_GRID = 2.0


def plan_feed(joints: np.ndarray, tip: np.ndarray, feed: np.ndarray, limits: Limits, *, angular_feed: float,
              min_duration: float = 1e-4, jerk: bool = True, max_turn: float = math.radians(30.0),
              max_refinements: int = 12, engine: Engine = "copp", optimize: bool = False) -> FeedPlan:
    """Plan the time law of one continuous feed sequence (see :func:`plan_feeds`); raises its
    :class:`PlanningError`."""
    (plan,) = plan_feeds([(joints, tip, feed)], limits, angular_feed=angular_feed, min_duration=min_duration,
                         jerk=jerk, max_turn=max_turn, max_refinements=max_refinements, engine=engine,
                         optimize=optimize)
    if isinstance(plan, PlanningError):
        raise plan
    return plan


def plan_feeds(sequences: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]], limits: Limits, *,
               angular_feed: float, min_duration: float = 1e-4, jerk: bool = True,
               max_turn: float = math.radians(30.0), max_refinements: int = 12, engine: Engine = "copp",
               optimize: bool = False) -> list[FeedPlan | PlanningError]:
    """Plan the time laws of independent feed sequences, each from rest to rest.

    Parameters
    ----------
    sequences : per sequence ``(joints, tip, feed)``: joints (K + 1, 5) waypoints (block end
        positions) in mm and rad, the controller moving linearly between them; tip (K + 1, 3)
        tool tip at the waypoints, mm, relative to the part; feed (K,) programmed feed of each
        block, mm/s, the maximum tip speed relative to the part.
    limits : joint velocity, acceleration and jerk limits.
    angular_feed : rad/s, the speed limit of the rotary joints (theta1, theta2 together) on
        rotary-only blocks (tip still).
    min_duration : s, no block is shorter than this.
    jerk : limit joint jerk too (otherwise the constant-acceleration TOPP2 profile is used).
    max_turn : rad, the largest angle between consecutive blocks (in joint space weighted by
        1 / velocity limit) that is accepted; sharper corners must be split by the caller.
    max_refinements : rounds of local slow-down allowed to meet every limit.
    engine : the TOPP2 engine, ``"copp"`` (copp-py) or ``"toppra"`` (the reference).
    optimize : also plan each sequence of more than 40 blocks by the third-order linear
        programme (:mod:`verne_post.planning.third_order`) and keep that plan where it is verified and
        faster: about 1 % off long rows whose speed climbs from one limit to another, for
        planning several times slower.

    Returns, per sequence, its plan or the :class:`PlanningError` that names the waypoint
    where a corner is too sharp, a block has no motion, the engine failed, or no plan within
    the limits was found. Raises ValueError for malformed input.
    """
    if not isinstance(limits, Limits):
        raise TypeError("limits must be a verne_post.planning.timing.Limits")
    if not (math.isfinite(angular_feed) and angular_feed > 0):
        raise ValueError(f"angular_feed must be positive (rad/s), got {angular_feed}")
    if not (math.isfinite(min_duration) and min_duration >= 0):
        raise ValueError(f"min_duration must be >= 0 (s), got {min_duration}")
    solver(engine)  # an unknown engine is refused before any work
    if not sequences:
        return []
    joints, tip, feed, first = concatenate(sequences)
    results: list[FeedPlan | PlanningError | None] = [None] * (len(first) - 1)
    refused = refusals(joints, first, limits, max_turn)
    for r, error in refused.items():
        results[r] = error
    blocks = np.diff(first) - 1
    straight = np.array([r for r in range(len(results)) if r not in refused and blocks[r] == 1], dtype=int)
    if len(straight):
        batch = Batch.of(*select(joints, tip, feed, first, straight), limits, angular_feed, min_duration, jerk)
        for r, plan in zip(straight, straight_plans(batch), strict=True):
            results[r] = plan
    again = np.array([r for r in range(len(results)) if r not in refused and blocks[r] > 1], dtype=int)
    for erode, widest in _TRIES:
        if not len(again):
            break
        batch = Batch.of(*select(joints, tip, feed, first, again), limits, angular_feed, min_duration, jerk)
        for r, plan in zip(again, Planner(batch, engine, max_refinements, erode, widest).plan(), strict=True):
            results[r] = plan
        again = np.array([r for r in again if isinstance(results[r], PlanningError)], dtype=int)
    longer = np.array([r for r, plan in enumerate(results)
                       if optimize and jerk and isinstance(plan, FeedPlan) and blocks[r] > LP_MIN_BLOCKS], dtype=int)
    if len(longer):
        batch = Batch.of(*select(joints, tip, feed, first, longer), limits, angular_feed, min_duration, jerk)
        planner = Planner(batch, engine, max_refinements, 0.0, False, _LP_GRID)
        for k, plan in third_order_plans(planner).items():
            if plan.total < results[longer[k]].total:  # type: ignore[union-attr]
                results[longer[k]] = plan
    return results  # type: ignore[return-value]


