"""Plans by the third-order linear programme (:mod:`verne_post.planning.third_order`, ``optimize``):
the caps as they are, in rounds as the filtered plans."""

from __future__ import annotations

import numpy as np

from .. import third_order
from ..timing import PlanningError
from .plan import FeedPlan
from .profiles import time_laws
from .rounds import Planner
from .scurve import SCURVE_MARGIN
from .verification import VERIFY_TOL, block_times, verify

_LP_ACC_MARGIN, _LP_JERK_MARGIN = 0.995, 0.99
_LP_ROUNDS = 6
# The filter width, in longest grid intervals of the law: a wider window costs its lag but lets
# the profile under it step more (the limit is exact either way). On the 105k job 1 gave 1935.47 s,
# 2 1935.24 s (the rows that climb into a rotary limit gain, the slow rows lose a little); the
# better of both per sequence 1934.80 s, for twice the planning.
_LP_WINDOW = 2.0


def _longest_interval(s: np.ndarray, x: np.ndarray) -> float:
    """Duration (s) of the longest grid interval but the two at the ends (those halved toward rest)."""
    return float(np.max(third_order.interval_times(s, x)[1:-1], initial=0.0))


def _second_order_upper(planner: Planner) -> tuple[np.ndarray, list[int]]:
    """The second-order optimum at the gridpoints (1/s^2), within the caps as they are: it
    bounds every third-order law from above, and is the programme's first reference; and
    the sequences where TOPP2 found it."""
    n = len(planner.grid.start)
    caps = planner.xcap * (1.0 - 3e-4)
    upper = np.zeros(n)
    active = []
    for r in range(planner.batch.count):
        outcome = planner.topp(r, caps, np.ones(n), filtered=False)
        if not isinstance(outcome, PlanningError):
            upper[planner.grid.first[r]:planner.grid.first[r + 1]] = outcome
            active.append(r)
    return np.minimum(upper, caps), active

def _third_order_problem(planner: Planner, r: int, upper: np.ndarray, q3: np.ndarray, margin: np.ndarray
                         ) -> third_order.ThirdOrderProblem:
    """Sequence r's programme under the caps ``upper`` with the (acceleration, jerk) margins;
    q3 the path's third derivatives at every gridpoint."""
    g = slice(planner.grid.first[r], planner.grid.first[r + 1])
    lim = planner.batch.limits
    return third_order.ThirdOrderProblem(planner.grid.start[g], upper[g], planner.q1[g], planner.q2[g], q3[g],
                                         margin[0] * lim.acceleration, margin[1] * lim.jerk)

def third_order_plans(planner: Planner) -> dict[int, FeedPlan]:
    """Verified plans of this batch's sequences by the third-order linear programme
    (:mod:`verne_post.planning.third_order`), for a planner built with ``erode=0``: the caps as they
    are, the programme keeping the filtered law within them. Rounds as in :meth:`Planner.plan`: a
    law over a cap has the caps of the gridpoints around the excess lowered by it, one over
    an acceleration or jerk limit its sequence's margins; a sequence that finds no law
    within every limit is left out (its filtered plan stays). The planner's filter widths
    become the programme's windows."""
    grid, count, n = planner.grid, planner.batch.count, len(planner.grid.start)
    upper, active = _second_order_upper(planner)
    path = planner.batch.path
    q3 = path.derivatives(path.locate(grid.owner, grid.start), grid.start, (3,))[0].T  # (G, 5), once
    margin = np.tile([_LP_ACC_MARGIN, _LP_JERK_MARGIN], (count, 1))
    x = np.zeros(n)
    plans: dict[int, FeedPlan] = {}
    for attempt in range(_LP_ROUNDS):
        solved = []
        for r in active:
            g = slice(grid.first[r], grid.first[r + 1])
            problem = _third_order_problem(planner, r, upper, q3, margin[r])
            if attempt == 0:
                # The window: _LP_WINDOW longest inner intervals of a first law (found with the
                # second-order law's longest): an interval longer than the window bounds its
                # steps by J w, stricter than its duration needs.
                planner.w[r] = _longest_interval(problem.s, upper[g])
                first = third_order.solve_filtered(problem, upper[g], planner.w[r])
                if first is None:
                    continue
                planner.w[r] = _LP_WINDOW * max(planner.w[r], _longest_interval(problem.s, first))
            # Later rounds start from the last law (its pairs, its linearisation).
            found = third_order.solve_filtered(problem, upper[g] if attempt == 0 else x[g], planner.w[r])
            if found is not None:
                x[g] = found
                solved.append(r)
        if not solved:
            break
        profiles, _ = time_laws(planner.grid, planner.batch, planner.w, np.array(solved), x)
        times, broken = block_times(planner.batch, profiles)
        good = ~np.isin(profiles.seqs, list(broken))
        where, _, _, seq, ratios, peaks = verify(planner.batch, planner.widest, profiles, times, good)
        failing = np.unique(seq)
        for k in np.flatnonzero(good & ~np.isin(profiles.seqs, failing)):
            r = int(profiles.seqs[k])
            plans[r] = planner.feed_plan(r, profiles, int(k), times, attempt, peaks[k])
        # Over a cap: the gridpoints either side of the excess lowered by it (squared).
        over = ratios[:, 0] > 1.0 + VERIFY_TOL
        nearest = np.clip(grid.search(seq[over], where[over]), grid.first[seq[over]] + 1,
                          grid.first[seq[over] + 1] - 1)
        for side in (nearest - 1, nearest):
            np.minimum.at(upper, side, x[side] / (ratios[over, 0] * SCURVE_MARGIN) ** 2)
        for column in (1, 2):  # over an acceleration or jerk limit: that margin, by the largest excess
            excess = np.ones(count)
            np.maximum.at(excess, seq, ratios[:, column])
            margin[:, column - 1] /= np.where(excess > 1.0 + VERIFY_TOL, excess * SCURVE_MARGIN, 1.0)
        active = [int(r) for r in failing if r not in broken]
        if not active:
            break
    return plans
