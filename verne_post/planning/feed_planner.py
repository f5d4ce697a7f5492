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
closed form, its peaks the limits it meets (:func:`_straight_plans`). A short multi-block
sequence (a re-orientation) is also tried as an S-curve in s, each ramp and jerk phase with the
limits of the stretch it covers (:func:`_scurve_laws`); verified as in step 4, it replaces the
filtered plan where it is faster. With ``optimize``, each sequence of more than 40 blocks is also
planned by a linear programme (:mod:`verne_post.planning.third_order`) whose squared path speeds,
filtered by a window two of its longest grid intervals wide, meet the jerk limits as that filter
produces them; verified the same way, the plan replaces the filtered one where it is faster
(:meth:`_Planner.third_order_plans`).

Every step is vectorised over all the sequences together (arrays concatenated, each element
knowing its sequence); only the TOPP2 solve (and the programme) runs once per sequence.
Positions within a sequence are kept local (s in [0, 1], t from 0), so precision does not
depend on the program's length.

Block durations are the times between the path parameter values of the waypoints, so sampling
at the cumulative durations gives back the waypoints.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Literal

import numpy as np

from . import third_order
from .timing import DOF, TIP_EPS, Limits, PlanningError, checked_sequence, rest_to_rest
from .topp import Engine, ToppError, solver

__all__ = ["Cubics", "FeedPlan", "plan_feed", "plan_feeds"]

logger = logging.getLogger(__name__)

_ACC_MARGIN = 0.97  # share of the acceleration limits given to TOPP2 (the filter mixes neighbours)
_JERK_CAP_MARGIN = 0.7  # share of the jerk limits for the centripetal-jerk velocity cap
# Widest filter: w = factor * max_j(a_j / J_j), where full acceleration is used. The safe try
# (below) keeps 1.25, room for a path acceleration swinging past its limit within one window; the
# tight try has 1.1, since a turn without cruise now gets a plateau instead (step 4): on the 105k
# job 1.1 saves 4.8 s of 1966 (1.05 and 1.0 about 1 s more, planning 30 to 50 % more sequences
# twice). With the S-curves (_scurve_plans), 1.0 saves 1.5 s of 1941 for 15 to 20 % more
# planning time, and tighter margins (erosion 0.05, _ACC_MARGIN and _SHRINK 0.99) 2.2 s more for
# 45 % more in all: kept as they are.
_FIR_FACTOR = 1.1
_SAFE_FIR_FACTOR = 1.25
# Tries in turn (a sequence goes to the next only if the last could not be brought within every
# limit): (erode, widest): a cap holds over erode * w * (its own speed) of travel on either side
# of its point; widest: the filter is _SAFE_FIR_FACTOR max(a / J) wide instead of the sequence's
# own width.
# The last is the safe setting of the planner before per-sequence widths.
_TRIES = ((0.1, False), (0.5, True))
_GRID_PER_WINDOW = 4  # target grid intervals per filter width, at the capped speed
_MIN_INTERVALS = 32
_END_HALVINGS, _MAX_END_HALVINGS = 4, 16  # halvings of each end's interval, at least and at most
_MAX_INTERVALS_PER_BLOCK = 1.0  # grid intervals per block, on average at most (plus a constant)
# (acceleration factor, time-scale factor) tried in turn when the TOPP2 engine fails numerically
_RETRIES = ((1.0, 1.0), (0.999, 0.1), (0.99, 0.43), (0.98, 2.3), (0.97, 10.0))
_MAX_PIECE_SAMPLES = 64  # verification samples per piece of the time law (see _verify)
_VERIFY_CHUNK = 1 << 16  # samples evaluated together (bounded memory)
_VERIFY_TOL = 1e-6  # relative excess tolerated by the verification (rounding)
_SHRINK = 0.97  # extra factor applied when lowering caps after a violation
# A jerk excess at least this large is taken for a turn without cruise (module docstring, step 4):
# the filter doubles the jerk there, while other excesses are a few per cent.
_TURN_JERK = 1.3
_NARROWER = 0.9  # a turn's window is narrowed to its own ramp's if that is this much narrower
# The third-order programme (optimize=True, verne_post.planning.third_order): on sequences of more blocks
# than this (shorter ones gained nothing on the 105k job: their S-curves are as good), on a grid
# this much finer, with these shares of the acceleration and jerk limits (the programme sees them
# at the gridpoints only; 1.0 gives the same plans, after more rounds), in at most this many rounds.
LP_MIN_BLOCKS = 40
_LP_GRID = 2.0
_LP_ACC_MARGIN, _LP_JERK_MARGIN = 0.995, 0.99
_LP_ROUNDS = 6
# The filter width, in longest grid intervals of the law: a wider window costs its lag but lets
# the profile under it step more (the limit is exact either way). On the 105k job 1 gave 1935.47 s,
# 2 1935.24 s (the rows that climb into a rotary limit gain, the slow rows lose a little); the
# better of both per sequence 1934.80 s, for twice the planning.
_LP_WINDOW = 2.0


@dataclass(frozen=True, eq=False)
class Cubics:
    """A piecewise cubic in one variable x: ``sum_k coef[k, i] (x - breaks[i])^(3 - k)`` on
    [breaks[i], breaks[i + 1]), the end pieces extended beyond the ends (as scipy's ``PPoly``
    with ``extrapolate=True``; numpy only, so that posting does not import scipy.interpolate).

    ``breaks`` (P + 1,) increasing; ``coef`` (4, P) scalar values or (4, P, D) vector values.
    """

    breaks: np.ndarray
    coef: np.ndarray

    def __call__(self, x: np.ndarray, nu: int = 0) -> np.ndarray:
        """Derivative ``nu`` (0..3) at ``x`` (n,): (n,) or (n, D)."""
        x = np.asarray(x, dtype=float)
        piece = np.clip(np.searchsorted(self.breaks, x, side="right") - 1, 0, len(self.breaks) - 2)
        tau = x - self.breaks[piece]
        if self.coef.ndim == 3:
            tau = tau[:, None]
        c = np.take(self.coef, piece, axis=1)
        weights = _DERIVATIVE_WEIGHTS[nu]
        value = weights[0] * c[0]
        for k, weight in enumerate(weights[1:], start=1):
            value = value * tau + weight * c[k]
        return value


@dataclass(frozen=True, eq=False)
class FeedPlan:
    """Time law of one feed sequence.

    ``durations[k]`` (s) is the time from waypoint k to k + 1; ``block_times`` (K + 1,) their
    cumulative sum from 0. ``path`` is the joint-space spline q(s) through the waypoints
    (at ``waypoint_s``), ``profile`` the path parameter s(t) (piecewise polynomial in t, C2
    when planned with jerk limits).
    """

    durations: np.ndarray  # (K,) s
    block_times: np.ndarray  # (K + 1,) s, block_times[0] = 0, block_times[-1] = total
    waypoint_s: np.ndarray  # (K + 1,) path parameter of the waypoints, 0 .. 1
    path: Cubics  # q(s): (5,) mm/rad, a cubic per block
    profile: Cubics  # s(t)
    filter_width: float  # s, width of the jerk filter (0 without jerk limiting; an S-curve: its first jerk time)
    gridpoints: int  # TOPP2 gridpoints used (0: an S-curve, no TOPP2)
    refinements: int  # local cap reductions needed to meet every limit
    # (3, 5): largest |velocity|, |acceleration|, |jerk| of each joint over its limit, found by
    # the planner's verification of this exact time law (at every piece and both sides of
    # every waypoint); the certified figures the report shows
    peak_ratios: np.ndarray

    @property
    def total(self) -> float:
        """Duration of the whole sequence (s)."""
        return float(self.block_times[-1])

    def sample_path(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Path parameter s and its first three time derivatives at times ``t`` (s, clipped to 0..total)."""
        t = np.clip(np.asarray(t, dtype=float).reshape(-1), 0.0, self.total)
        s = np.clip(self.profile(t), 0.0, 1.0)
        return s, self.profile(t, 1), self.profile(t, 2), self.profile(t, 3)

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Joint positions, velocities, accelerations (n, 5) each (mm, rad, per s) at times ``t`` (s)."""
        q, qd, qdd, _ = self.sample_all(t)
        return q, qd, qdd

    def sample_all(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Joint positions, velocities, accelerations and jerks (n, 5) each at times ``t`` (s)."""
        s, sd, sdd, sddd = self.sample_path(t)
        q = self.path(s)
        q1, q2, q3 = self.path(s, 1), self.path(s, 2), self.path(s, 3)
        sd_, sdd_, sddd_ = sd[:, None], sdd[:, None], sddd[:, None]
        return q, q1 * sd_, q1 * sdd_ + q2 * sd_ ** 2, q1 * sddd_ + 3.0 * q2 * sd_ * sdd_ + q3 * sd_ ** 3

    def block_index(self, t: np.ndarray) -> np.ndarray:
        """Index of the block (0..K-1) being run at times ``t`` (s)."""
        t = np.asarray(t, dtype=float)
        return np.clip(np.searchsorted(self.block_times, t, side="right") - 1, 0, len(self.durations) - 1)


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
    joints, tip, feed, first = _concatenate(sequences)
    results: list[FeedPlan | PlanningError | None] = [None] * (len(first) - 1)
    refused = _refusals(joints, first, limits, max_turn)
    for r, error in refused.items():
        results[r] = error
    blocks = np.diff(first) - 1
    straight = np.array([r for r in range(len(results)) if r not in refused and blocks[r] == 1], dtype=int)
    if len(straight):
        batch = _Batch.of(*_select(joints, tip, feed, first, straight), limits, angular_feed, min_duration, jerk)
        for r, plan in zip(straight, _straight_plans(batch), strict=True):
            results[r] = plan
    again = np.array([r for r in range(len(results)) if r not in refused and blocks[r] > 1], dtype=int)
    for erode, widest in _TRIES:
        if not len(again):
            break
        batch = _Batch.of(*_select(joints, tip, feed, first, again), limits, angular_feed, min_duration, jerk)
        for r, plan in zip(again, _Planner(batch, engine, max_refinements, erode, widest).plan(), strict=True):
            results[r] = plan
        again = np.array([r for r in again if isinstance(results[r], PlanningError)], dtype=int)
    longer = np.array([r for r, plan in enumerate(results)
                       if optimize and jerk and isinstance(plan, FeedPlan) and blocks[r] > LP_MIN_BLOCKS], dtype=int)
    if len(longer):
        batch = _Batch.of(*_select(joints, tip, feed, first, longer), limits, angular_feed, min_duration, jerk)
        planner = _Planner(batch, engine, max_refinements, 0.0, False, _LP_GRID)
        for k, plan in planner.third_order_plans().items():
            if plan.total < results[longer[k]].total:  # type: ignore[union-attr]
                results[longer[k]] = plan
    return results  # type: ignore[return-value]


# --------------------------------------------------------------------------------------------
# Segmented arrays: many sequences in one array, each element knowing its sequence
# --------------------------------------------------------------------------------------------


def _ranges(start: np.ndarray, stop: np.ndarray) -> np.ndarray:
    """Concatenation of arange(start[i], stop[i]) over i."""
    count = np.maximum(stop - start, 0)
    offset = np.repeat(start - np.r_[0, np.cumsum(count)[:-1]], count)
    return np.arange(int(count.sum())) + offset


def _segment_cumsum(values: np.ndarray, start: np.ndarray, dtype: type = float) -> np.ndarray:
    """Per segment, the running sum of ``values`` from 0 (segments begin at ``start``, with a
    last entry = len(values)), each summed on its own: a sequence's plan does not depend, even
    in its last bit, on what it is planned with (the same G-code whether a program is planned
    whole or in parts)."""
    out = np.empty(len(values), dtype=dtype)
    for a, b in zip(start[:-1].tolist(), start[1:].tolist(), strict=True):
        np.cumsum(values[a:b], dtype=dtype, out=out[a:b])
    return out


@dataclass(frozen=True, eq=False)
class _Pieces:
    """Piecewise cubics of many sequences: pieces grouped by sequence, in local coordinates.

    ``start`` (P,) local start of each piece; ``first`` (R + 1,) offsets of each sequence's
    pieces; ``coef`` (4, P) or (4, D, P) cubic coefficients (highest first) in (x - start), or
    None for a plain sorted grid. Vector values come out dimension-major, (D, n): each joint's
    row is contiguous.
    """

    start: np.ndarray
    first: np.ndarray
    coef: np.ndarray | None = None

    @cached_property
    def owner(self) -> np.ndarray:
        return np.repeat(np.arange(len(self.first) - 1), np.diff(self.first))

    @cached_property
    def _line(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The sequences laid end to end on one real line, 1 apart beyond their spans: the
        starts there, each sequence's shift, and the bounds (R,) its queries are clipped to."""
        count = np.diff(self.first)
        low, high = np.zeros(len(count)), np.zeros(len(count))
        some = count > 0
        low[some] = self.start[self.first[:-1][some]]
        high[some] = self.start[self.first[1:][some] - 1]
        shift = np.r_[0.0, np.cumsum(high - low + 2.0)[:-1]] - low
        return self.start + shift[self.owner], shift, low - 0.5, high + 0.5

    def search(self, seq: np.ndarray, x: np.ndarray, side: Literal["left", "right"] = "right") -> np.ndarray:
        """np.searchsorted of local positions x among the starts of sequence seq (global index)."""
        line, shift, low, high = self._line
        i = np.searchsorted(line, np.clip(x, low[seq], high[seq]) + shift[seq], side=side)
        # A real search is twice as fast as one of (sequence, position) pairs. Rounding x + shift
        # never reorders (rounding is monotonic), it can only tie a start with x: searching
        # right, i may then be past a start > x; searching left, short of a start < x. Corrected
        # exactly (rarely more than a pass that finds nothing):
        while True:
            if side == "right":
                wrong = np.flatnonzero((i > self.first[seq]) & (self.start[np.maximum(i - 1, 0)] > x))
                step = -1
            else:
                wrong = np.flatnonzero((i < self.first[seq + 1]) & (self.start[np.minimum(i, len(self.start) - 1)] < x))
                step = 1
            if not len(wrong):
                return i
            i[wrong] += step

    def clip(self, seq: np.ndarray, index: np.ndarray) -> np.ndarray:
        """Indices clipped into the pieces of their sequences."""
        return np.clip(index, self.first[seq], self.first[seq + 1] - 1)

    def locate(self, seq: np.ndarray, x: np.ndarray, side: Literal["left", "right"] = "right") -> np.ndarray:
        """Piece holding local position x of sequence seq (its first or last piece outside)."""
        return self.clip(seq, self.search(seq, x, side) - 1)

    def __call__(self, piece: np.ndarray, x: np.ndarray, order: int = 0) -> np.ndarray:
        """Derivative ``order`` (0..3) at local positions x, each in its ``piece``."""
        return self.derivatives(piece, x, (order,))[0]

    def derivatives(self, piece: np.ndarray, x: np.ndarray, orders: tuple[int, ...]) -> list[np.ndarray]:
        """Derivatives of the given orders (0..3) at local positions x, each in its ``piece``."""
        assert self.coef is not None
        tau = x - self.start[piece]
        # c0 is gathered only where the value is wanted; np.take keeps each row contiguous (fancy
        # indexing on the last axis would not, and every reduction over joints would crawl).
        c = np.take(self.coef[: 4 - min(orders)], piece, axis=-1)
        out = []
        for order in orders:
            weights = _DERIVATIVE_WEIGHTS[order]
            value = weights[0] * c[0]
            for k, weight in enumerate(weights[1:], start=1):
                value *= tau
                value += c[k] if weight == 1.0 else weight * c[k]
            out.append(value)
        return out


#: d^n/dx^n of c3 x^3 + c2 x^2 + c1 x + c0 as Horner weights on (c3, c2, ...).
_DERIVATIVE_WEIGHTS = {0: (1.0, 1.0, 1.0, 1.0), 1: (3.0, 2.0, 1.0), 2: (6.0, 2.0), 3: (6.0,)}


def _not_a_knot(x: np.ndarray, y: np.ndarray, first: np.ndarray) -> np.ndarray:
    """Cubic coefficients (4, N - R, D) of the not-a-knot splines through (x, y) per sequence.

    x (N,) strictly increasing within each sequence; y (N, D); ``first`` (R + 1,) offsets.
    The same splines as scipy's ``CubicSpline(x, y, bc_type="not-a-knot")`` (a straight line
    through 2 points, a parabola through 3), solved as one tridiagonal system for the slopes.
    """
    n = np.diff(first)
    owner = np.repeat(np.arange(len(n)), n)
    local = np.arange(len(x)) - first[:-1][owner]
    size = n[owner]
    last = local == size - 1
    dx = np.diff(x)
    slope = np.diff(y, axis=0) / dx[:, None]
    # Row i couples slopes i - 1, i, i + 1: dx[i] m[i-1] + 2 (dx[i-1] + dx[i]) m[i] + dx[i-1] m[i+1].
    diag = np.ones(len(x))
    upper = np.zeros(len(x))  # element (i, i + 1)
    lower = np.zeros(len(x))  # element (i, i - 1)
    rhs = np.zeros_like(y, dtype=float)
    inner = np.flatnonzero((local > 0) & ~last & (size >= 4))
    diag[inner] = 2.0 * (dx[inner - 1] + dx[inner])
    upper[inner] = dx[inner - 1]
    lower[inner] = dx[inner]
    rhs[inner] = 3.0 * (dx[inner, None] * slope[inner - 1] + dx[inner - 1, None] * slope[inner])
    # The not-a-knot end rows are not diagonally dominant (dx[1] m[0] + (dx[0] + dx[1]) m[1]).
    # Row 1 minus row 0 (both hold dx[1] m[0]) no longer holds m[0], likewise the row before the
    # last minus the last; m[0] and m[-1] come after from their own rows. What is left is
    # strictly diagonally dominant (dx[0] + dx[1] on the diagonal of row 1 against dx[0]), which
    # a solve without pivoting keeps stable.
    head = np.flatnonzero((local == 0) & (size >= 4))
    d = x[head + 2] - x[head]
    head_rows = dx[head + 1], d, (((dx[head] + 2.0 * d) * dx[head + 1])[:, None] * slope[head]
                                  + (dx[head] ** 2)[:, None] * slope[head + 1]) / d[:, None]
    tail = np.flatnonzero(last & (size >= 4))
    d = x[tail] - x[tail - 2]
    tail_rows = dx[tail - 2], d, ((dx[tail - 1] ** 2)[:, None] * slope[tail - 2]
                                  + ((2.0 * d + dx[tail - 1]) * dx[tail - 2])[:, None] * slope[tail - 1]) / d[:, None]
    lower[head + 1] = upper[tail - 1] = 0.0
    for (_, coupling, value), row in ((head_rows, head + 1), (tail_rows, tail - 1)):
        diag[row] -= coupling
        rhs[row] -= value
    # Two points: the chord. Three: the parabola through them (its slopes at the three nodes).
    two = np.flatnonzero(size == 2)
    rhs[two] = slope[np.where(local[two] == 0, two, two - 1)]
    three = np.flatnonzero((size == 3) & (local == 0))
    for k in range(3):
        node = three + k
        h0, h1 = dx[three], dx[three + 1]
        curvature = (slope[three + 1] - slope[three]) / (h0 + h1)[:, None]
        offset = (-h0, h0, h0 + 2.0 * h1)[k]
        rhs[node] = slope[three] + curvature * offset[:, None]
    m = _tridiagonal(lower, diag, upper, rhs, local)
    for end, (own, coupling, value), row in ((head, head_rows, head + 1), (tail, tail_rows, tail - 1)):
        m[end] = (value - coupling[:, None] * m[row]) / own[:, None]
    block = np.flatnonzero(~last)  # block b starts at node b (global node index)
    h = dx[block][:, None]
    m0, m1, chord = m[block], m[block + 1], slope[block]
    return np.stack([(m0 + m1 - 2.0 * chord) / h ** 2, (3.0 * chord - 2.0 * m0 - m1) / h, m0, y[block]])


def _tridiagonal(lower: np.ndarray, diag: np.ndarray, upper: np.ndarray, rhs: np.ndarray, local: np.ndarray
                 ) -> np.ndarray:
    """x (N, D) with ``lower[i] x[i - 1] + diag[i] x[i] + upper[i] x[i + 1] = rhs[i]`` (N,), for
    a strictly diagonally dominant matrix made of independent systems, one after the other:
    ``local`` (N,) each row's index within its own, whose first row has ``lower`` 0 and last row
    ``upper`` 0.

    Cyclic reduction (Hockney 1965; stable without pivoting for such matrices, Heller 1976): each
    level eliminates each system's odd rows from its even ones, in log2(longest) vectorised
    levels; then the odd unknowns are found back from their rows, level by level. The parity is
    each system's own, so a system gets the same bits whatever comes before it (a zero coupling
    adds exactly nothing). numpy only: scipy's banded solver cost the planning's process 0.3 s
    to import.
    """
    a, b, c, d = lower, diag, upper, rhs
    levels = []
    while np.any(local):
        n = len(b)
        odd = local % 2 == 1
        keep = np.flatnonzero(~odd)
        before, after = np.maximum(keep - 1, 0), np.minimum(keep + 1, n - 1)
        alpha, gamma = -a[keep] / b[before], -c[keep] / b[after]  # 0 at a system's first, last row
        levels.append((a, b, c, d, keep, np.flatnonzero(odd)))
        a, b, c, d = (alpha * a[before], b[keep] + alpha * c[before] + gamma * a[after], gamma * c[after],
                      d[keep] + alpha[:, None] * d[before] + gamma[:, None] * d[after])
        local = local[keep] // 2
    x = d / b[:, None]
    for a, b, c, d, keep, odd in reversed(levels):  # odd: never a system's first row
        n = len(b)
        full = np.zeros((n + 1, d.shape[1]))  # a row of 0 after the last (no coupling to it)
        full[keep] = x
        full[odd] = (d[odd] - a[odd, None] * full[odd - 1] - c[odd, None] * full[odd + 1]) / b[odd, None]
        x = full[:n]
    return x


def _range_chmin(n: int, lo: np.ndarray, hi: np.ndarray, values: np.ndarray) -> np.ndarray:
    """out[i] = min(values[m] for every m with lo[m] <= i <= hi[m]) (inf where none), vectorised.

    Each update is written to the two power-of-two blocks covering its range, then the blocks
    are pushed down level by level (a sparse table used in reverse).
    """
    length = hi - lo + 1
    level = np.floor(np.log2(np.maximum(length, 1))).astype(int)
    top = int(level.max()) if len(level) else 0
    table = np.full((top + 1, n), np.inf)
    np.minimum.at(table, (level, lo), values)
    np.minimum.at(table, (level, hi - (1 << level) + 1), values)
    for k in range(top, 0, -1):
        half = 1 << (k - 1)
        np.minimum(table[k - 1], table[k], out=table[k - 1])
        table[k - 1, half:] = np.minimum(table[k - 1, half:], table[k, : n - half])
    return table[0]


def _range_max(values: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """max(values[lo..hi]) for inclusive index arrays lo <= hi (sparse table)."""
    n = len(values)
    levels = [values]
    step = 1
    while 2 * step <= n:
        prev = levels[-1]
        nxt = np.full_like(values, -np.inf)
        nxt[: n - 2 * step + 1] = np.maximum(prev[: n - 2 * step + 1], prev[step: n - step + 1])
        levels.append(nxt)
        step *= 2
    table = np.stack(levels)
    level = np.floor(np.log2(hi - lo + 1)).astype(int)
    return np.maximum(table[level, lo], table[level, hi - (1 << level) + 1])


# --------------------------------------------------------------------------------------------
# The sequences' geometry and caps
# --------------------------------------------------------------------------------------------


def _concatenate(sequences: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]]
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Checked (:func:`timing.checked_sequence`), concatenated (joints, tip, feed) and the
    waypoint offsets (R + 1,)."""
    checked = []
    for r, sequence in enumerate(sequences):
        try:
            checked.append(checked_sequence(*sequence))
        except ValueError as error:
            raise ValueError(f"{error} (sequence {r})" if len(sequences) > 1 else str(error)) from None
    joints, tips, feeds = zip(*checked, strict=True)
    first = np.r_[0, np.cumsum([len(q) for q in joints])]
    return np.concatenate(joints), np.concatenate(tips), np.concatenate(feeds), first


def _select(joints: np.ndarray, tip: np.ndarray, feed: np.ndarray, first: np.ndarray, which: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The sequences ``which`` of concatenated (joints, tip, feed) with waypoint offsets ``first``."""
    rows = _ranges(first[which], first[which + 1])
    blocks = _ranges(first[which] - which, first[which + 1] - which - 1)
    return joints[rows], tip[rows], feed[blocks], np.r_[0, np.cumsum(np.diff(first)[which])]


def _refusals(joints: np.ndarray, first: np.ndarray, limits: Limits, max_turn: float) -> dict[int, PlanningError]:
    """Sequences that cannot be planned at all: a block without joint motion, a sharp corner."""
    bfirst = first - np.arange(len(first))
    bseq = np.repeat(np.arange(len(first) - 1), np.diff(bfirst))
    left = np.arange(len(bseq)) + bseq
    step = (joints[left + 1] - joints[left]) / limits.velocity
    weighted = np.linalg.norm(step, axis=1)
    total = np.add.reduceat(weighted, bfirst[:-1])
    errors: dict[int, PlanningError] = {}
    for b in np.flatnonzero(weighted <= 1e-12 * np.maximum(total[bseq], 1e-300)):
        r, k = int(bseq[b]), int(b - bfirst[bseq[b]])
        errors.setdefault(r, PlanningError(f"feed block {k} (waypoints {k} to {k + 1}) has no joint motion: drop "
                                           f"repeated waypoints", k))
    direction = step / np.maximum(weighted, 1e-300)[:, None]
    turn = np.arccos(np.clip(np.sum(direction[:-1] * direction[1:], axis=1), -1.0, 1.0))
    for b in np.flatnonzero((turn > max_turn) & (bseq[:-1] == bseq[1:])):
        r, i = int(bseq[b]), int(b - bfirst[bseq[b]]) + 1
        errors.setdefault(r, PlanningError(f"corner of {math.degrees(turn[b]):.1f} deg at waypoint {i} is sharper "
                                           f"than {math.degrees(max_turn):.1f} deg: split the feed sequence there", i))
    return errors


@dataclass(frozen=True, eq=False)
class _Batch:
    """Sequences to plan, concatenated: R sequences, W waypoints, B = W - R blocks."""

    limits: Limits
    jerk: bool
    wfirst: np.ndarray  # (R + 1,) waypoint offsets
    bfirst: np.ndarray  # (R + 1,) block offsets
    s: np.ndarray  # (W,) local path parameter of the waypoints
    path: _Pieces  # q(s), a cubic per block, (4, 5, B)
    tip: _Pieces  # tip(s), the same parameter, (4, 3, B)
    tip_feed: np.ndarray  # (B,) mm/s, inf on rotary-only blocks
    block_cap: np.ndarray  # (B,) sdot cap of each block (feed, angular feed, minimum duration)

    @property
    def count(self) -> int:
        return len(self.wfirst) - 1

    @classmethod
    def of(cls, joints: np.ndarray, tip: np.ndarray, feed: np.ndarray, first: np.ndarray, limits: Limits,
           angular_feed: float, min_duration: float, jerk: bool) -> _Batch:
        count = len(first) - 1
        bfirst = first - np.arange(count + 1)
        bseq = np.repeat(np.arange(count), np.diff(bfirst))
        left = np.arange(len(bseq)) + bseq
        dq = joints[left + 1] - joints[left]
        weighted = np.linalg.norm(dq / limits.velocity, axis=1)
        s = np.zeros(len(joints))
        running = _segment_cumsum(weighted, bfirst)
        s[left + 1] = running / running[bfirst[1:] - 1][bseq]
        s[first[1:] - 1] = 1.0
        ds = s[left + 1] - s[left]
        coef = np.ascontiguousarray(_not_a_knot(s, np.hstack([joints, tip]), first).transpose(0, 2, 1))
        length = np.linalg.norm(tip[left + 1] - tip[left], axis=1)
        rotary_only = length < TIP_EPS
        rotary = np.linalg.norm(dq[:, 3:], axis=1)
        with np.errstate(divide="ignore", over="ignore"):  # a rapid's cap (1e9 mm/s) over a tiny length
            tip_cap = np.where(rotary_only, np.inf, feed * ds / np.maximum(length, 1e-300))
            rot_cap = np.where(rotary_only & (rotary > 0), angular_feed * ds / np.maximum(rotary, 1e-300), np.inf)
            dur_cap = ds / min_duration if min_duration > 0 else np.full(len(ds), np.inf)
        return cls(limits, jerk, first, bfirst, s, _Pieces(s[left], bfirst, coef[:, :DOF]),
                   _Pieces(s[left], bfirst, coef[:, DOF:]), np.where(rotary_only, np.inf, feed),
                   np.minimum(np.minimum(tip_cap, rot_cap), dur_cap))

    def point_cap(self, seq: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Squared path-speed caps at local path parameters c: joint velocity, tip feed,
        centripetal jerk, and the caps of the block(s) c lies in; and |q'(c)| (5, n)."""
        lim = self.limits
        right = self.path.locate(seq, c, "right")
        # c on a waypoint lies in both its blocks: the one before is the one searching left finds
        left = right - ((self.path.start[right] == c) & (right > self.path.first[seq]))
        q = self.path.derivatives(right, c, (1, 3) if self.jerk else (1,))
        q1 = np.abs(q[0])
        feed = np.minimum(self.tip_feed[left], self.tip_feed[right])
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.min((lim.velocity[:, None] / q1) ** 2, axis=0)
            x = np.minimum(x, np.nan_to_num((feed / np.linalg.norm(self.tip(right, c, 1), axis=0)) ** 2, nan=np.inf))
            if self.jerk:
                x = np.minimum(x, np.min((_JERK_CAP_MARGIN * lim.jerk[:, None] / np.abs(q[1])) ** (2.0 / 3.0), axis=0))
        return np.minimum(np.minimum(x, np.minimum(self.block_cap[left], self.block_cap[right]) ** 2), 1e300), q1

    def sequence_path(self, r: int) -> tuple[np.ndarray, Cubics]:
        """Sequence r's waypoint parameters (K + 1,) and its spline q(s), standalone copies."""
        w = slice(self.wfirst[r], self.wfirst[r + 1])
        blocks = self.path.coef[..., self.bfirst[r]:self.bfirst[r + 1]]
        return self.s[w].copy(), Cubics(self.s[w].copy(), np.ascontiguousarray(blocks.transpose(0, 2, 1)))

    def waypoint_at(self, seq: int, c: float) -> int:
        """Index (within its sequence) of the first waypoint at or after local path parameter c."""
        s = self.s[self.wfirst[seq]:self.wfirst[seq + 1]]
        return int(np.clip(np.searchsorted(s, c - 1e-12, side="left"), 0, len(s) - 1))


def _sorted_points(seq: np.ndarray, x: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points (seq, local x) sorted by sequence then x, exact repeats dropped; with offsets (R + 1,)."""
    # x + 2 seq orders the points as (seq, x) does for x in [0, 1], but for ties by rounding:
    # sorted so (3x faster than a lexsort of the pair, the points being runs already sorted),
    # then checked exactly.
    order = np.argsort(x + 2.0 * seq, kind="stable")
    seq, x = seq[order], x[order]
    if np.any((seq[1:] < seq[:-1]) | ((seq[1:] == seq[:-1]) & (x[1:] < x[:-1]))):
        order = np.lexsort((x, seq))
        seq, x = seq[order], x[order]
    keep = np.r_[True, (seq[1:] != seq[:-1]) | (x[1:] != x[:-1])]
    seq, x = seq[keep], x[keep]
    return seq, x, np.searchsorted(seq, np.arange(count + 1))


# --------------------------------------------------------------------------------------------
# One-block sequences: in closed form
# --------------------------------------------------------------------------------------------


def _straight_plans(batch: _Batch) -> list[FeedPlan]:
    """Plans of one-block sequences (the batch holds only those).

    A block is a line in joint space, q(s) = q0 + s dq for s in [0, 1], and the tip's spline
    through two points the chord: every cap is the same all along it. The time-optimal move
    from rest to rest is then known exactly: the 7-segment S-curve in s (the trapezoid without
    jerk limits) under the path speed of :meth:`_Batch.point_cap`, the path acceleration
    ``min_j a_j / |dq_j|`` and the path jerk ``min_j J_j / |dq_j|``, at the limits themselves.
    Its peaks are those limits, exactly (the peak ratios are computed, not sampled).
    """
    count = batch.count
    lim = batch.limits
    x, slope = batch.point_cap(np.arange(count), np.full(count, 0.5))  # slope (5, M): |dq| (s spans 1)
    with np.errstate(divide="ignore"):
        acc = np.min(lim.acceleration[:, None] / slope, axis=0)
        jerk = np.min(lim.jerk[:, None] / slope, axis=0) if batch.jerk else np.full(count, np.inf)
    move = rest_to_rest(np.ones(count), np.sqrt(x), acc, jerk)
    top, peak_acc, tj, ta = move.peak_speed, move.peak_acceleration, move.jerk_time, move.acceleration_time
    # Segments: jerk up, hold, jerk down, cruise, then the mirror; acceleration at each start.
    durations = np.stack([tj, ta, tj, move.cruise_time, tj, ta, tj], axis=1)
    zero = np.zeros(count)
    start_acc = np.stack([zero, peak_acc, peak_acc, zero, zero, -peak_acc, -peak_acc], axis=1)
    j = np.where(np.isfinite(jerk), jerk, 0.0)
    seg_jerk = np.stack([j, zero, -j, zero, -j, zero, j], axis=1)
    start_s, start_v, _ = _phase_starts(durations, seg_jerk, start_acc)
    ratios = np.stack([top * slope / lim.velocity[:, None], peak_acc * slope / lim.acceleration[:, None],
                       (jerk * slope / lim.jerk[:, None]) if batch.jerk else np.zeros_like(slope)], axis=1)
    plans = []
    for r in range(count):
        keep = durations[r] > 0
        breaks = np.r_[0.0, np.cumsum(durations[r, keep])]
        coef = np.stack([seg_jerk[r, keep] / 6.0, start_acc[r, keep] / 2.0, start_v[r, keep], start_s[r, keep]])
        total = breaks[-1]
        plans.append(FeedPlan(np.array([total]), np.array([0.0, total]), *batch.sequence_path(r), Cubics(breaks, coef),
                              float(tj[r]), 0, 0, ratios[:, :, r].T.copy()))
    return plans


# --------------------------------------------------------------------------------------------
# The planner
# --------------------------------------------------------------------------------------------


def _peaks(grid: _Pieces, x: np.ndarray, seqs: np.ndarray) -> np.ndarray:
    """Per sequence of ``seqs``, the gridpoint (global index) where x is largest, the first if tied."""
    counts = grid.first[seqs + 1] - grid.first[seqs]
    gi = _ranges(grid.first[seqs], grid.first[seqs + 1])
    owner = np.repeat(np.arange(len(seqs)), counts)
    top = np.maximum.reduceat(x[gi], np.r_[0, np.cumsum(counts)[:-1]])
    at_top = np.flatnonzero(x[gi] == top[owner])
    return gi[at_top[np.searchsorted(owner[at_top], np.arange(len(seqs)))]]


def _plateau_levels(grid: _Pieces, x: np.ndarray, seqs: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Per sequence of ``seqs``, the squared path speed L (1/s^2) below its peak at which the
    profile x (squared path speeds at the gridpoints, zero at both ends), capped at L, cruises
    for w (s); NaN where it already cruises that long at its peak.

    The cruise is the run of gridpoints around the peak where x >= L, at sqrt(L) once capped
    (where x crosses L within an interval, the capped profile still ramps there, only less
    steeply): its duration falls as L rises, so L is found by bisection, all the sequences at
    once.
    """
    gi = _ranges(grid.first[seqs], grid.first[seqs + 1])
    owner = np.repeat(np.arange(len(seqs)), grid.first[seqs + 1] - grid.first[seqs])
    s, xs = grid.start[gi], np.maximum(x[gi], 0.0)
    peak = np.searchsorted(gi, _peaks(grid, x, seqs))  # local to gi
    top = xs[peak]
    index = np.arange(len(xs))

    def cruise(level: np.ndarray) -> np.ndarray:
        below = xs < level[owner]  # true at each sequence's ends, where x = 0 < level
        i = np.maximum.accumulate(np.where(below, index, -1))[peak]  # last node below, left of the peak
        j = np.minimum.accumulate(np.where(below, index, len(xs))[::-1])[::-1][peak]  # first, right
        return (s[j - 1] - s[i + 1]) / np.sqrt(level)

    hi = np.where(top > 0, top * (1.0 - 1e-9), 1.0)
    lo = np.zeros_like(hi)
    short = (top > 0) & (cruise(hi) < w)
    for _ in range(50):
        mid = np.where(short, 0.5 * (lo + hi), hi)
        long_enough = cruise(mid) >= w
        lo, hi = np.where(long_enough, mid, lo), np.where(long_enough, hi, mid)
    return np.where(short & (lo > 0), lo, np.nan)


@dataclass(frozen=True, eq=False)
class _Profiles:
    """s(t) of some sequences: cubic pieces in local time, breaks per sequence (with the end)."""

    seqs: np.ndarray  # (S,) sequence numbers, in order
    breaks: np.ndarray  # (P + S,) local times
    bfirst: np.ndarray  # (S + 1,) offsets into breaks
    coef: np.ndarray  # (4, P), highest first

    @cached_property
    def pieces(self) -> _Pieces:
        pfirst = self.bfirst - np.arange(len(self.bfirst))
        ends = self.bfirst[1:] - 1
        starts = np.delete(self.breaks, ends)
        return _Pieces(starts, pfirst, self.coef)

    @property
    def total(self) -> np.ndarray:
        return self.breaks[self.bfirst[1:] - 1]


# --------------------------------------------------------------------------------------------
# S-curves along a path: short moves such as re-orientations
# --------------------------------------------------------------------------------------------
#
# A short sequence (a re-orientation of the table over a few blocks) has no cruise worth the
# name: the filtered TOPP2 profile spends a filter width on each of its few corners, and a turn
# without cruise costs a plateau (module docstring, step 4). Its time-optimal third-order law is
# close to an S-curve in s whose phases each have their own limits: the ramp up at the
# acceleration the stretch it covers allows, the ramp down at its own, and each of the four jerk
# phases at the jerk left where the path's curvature takes part of the joint jerk (the terms
# 3 q'' sdot sddot + q''' sdot^3). Each phase's limits are the tangential ones over the path
# parameters it covers (min over joints of a_j / |q_j'|, J_j / |q_j'|) times a factor of that
# phase, lowered by every excess found at its samples, until no sample exceeds a limit; the
# plan is then verified as every other plan (_Planner._verify) and kept only if it is faster.
# The 105k job's 342 re-orientations take 96.7 s instead of 100.2 s (the filtered plans), 2.3 %
# above their jerk-limited lower bound (benchmarks/jerk_bound.py) in all; on one of them copp-py's
# TOPP3-LP (benchmarks/topp3.py) gets 0.2707 s, this 0.2743 s, the filter 0.2948 s.

_SCURVE_ROUNDS = 8
_SCURVE_SAMPLES = 9  # per phase, both ends included
_SCURVE_MARGIN = 1.001  # a limit is lowered a little past the excess found at the samples
_SCURVE_START_SAMPLES = 64  # uniform path samples for the first limits


def _ramp(speed: np.ndarray, acc: np.ndarray, rise: np.ndarray, fall: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """From rest to ``speed`` with the acceleration at most ``acc``, its jerk ``rise`` while the
    acceleration grows and ``fall`` while it returns to 0 (any unit of length; all per s^k):
    the durations (s) of the three phases, the middle one at constant acceleration, and the
    distance covered."""
    bend = 0.5 / rise + 0.5 / fall  # speed gained over the two jerk phases, per acceleration^2
    full = speed >= acc ** 2 * bend
    peak = np.where(full, acc, np.sqrt(speed / bend))
    t1, t3 = peak / rise, peak / fall
    t2 = np.where(full, (speed - peak ** 2 * bend) / peak, 0.0)
    v1 = rise * t1 ** 2 / 2.0
    v2 = v1 + peak * t2
    distance = (rise * t1 ** 3 / 6.0 + v1 * t2 + peak * t2 ** 2 / 2.0
                + v2 * t3 + peak * t3 ** 2 / 2.0 - fall * t3 ** 3 / 6.0)
    return t1, t2, t3, distance


def _scurve(cap: np.ndarray, acc: np.ndarray, jerk: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rest to rest over s in [0, 1], row by row: the ramp up under acc[:, 0] with the jerks
    jerk[:, 0] (rising) and jerk[:, 1], a cruise at the peak speed (at most ``cap``, 1/s), the
    ramp down under acc[:, 1] with the jerks jerk[:, 2] and jerk[:, 3] (the last, back to rest).
    Returns the 7 phase durations (S, 7) in s, their path jerks (S, 7) and the peak speed (S,)."""
    def covered(v: np.ndarray) -> np.ndarray:
        return _ramp(v, acc[:, 0], jerk[:, 0], jerk[:, 1])[3] + _ramp(v, acc[:, 1], jerk[:, 3], jerk[:, 2])[3]

    # Two ramps to v cover at least v^2 / (2 acc) each: the peak is below the speed where those make 1.
    low, high = np.zeros_like(cap), np.minimum(cap, np.sqrt(2.0 / (1.0 / acc[:, 0] + 1.0 / acc[:, 1])))
    short = covered(cap) > 1.0
    for _ in range(32):  # the peak whose two ramps cover the whole distance (covered grows with it)
        mid = 0.5 * (low + high)
        over = covered(mid) > 1.0
        low, high = np.where(over, low, mid), np.where(over, mid, high)
    speed = np.where(short, low, cap)
    a1, a2, a3, up = _ramp(speed, acc[:, 0], jerk[:, 0], jerk[:, 1])
    d1, d2, d3, down = _ramp(speed, acc[:, 1], jerk[:, 3], jerk[:, 2])
    cruise = np.maximum(1.0 - up - down, 0.0) / speed
    zero = np.zeros_like(speed)
    durations = np.stack([a1, a2, a3, cruise, d3, d2, d1], axis=1)
    jerks = np.stack([jerk[:, 0], zero, -jerk[:, 1], zero, -jerk[:, 2], zero, jerk[:, 3]], axis=1)
    return durations, jerks, speed


def _phase_starts(durations: np.ndarray, jerks: np.ndarray, acc: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """s, sdot, sddot at the start of each phase (S, P), from rest at s = 0: the acceleration
    integrated from the jerks, or ``acc`` where it is given (a trapezoid's steps)."""
    s, v = np.zeros(durations.shape), np.zeros(durations.shape)
    a = np.zeros(durations.shape) if acc is None else acc
    for k in range(durations.shape[1] - 1):
        h, j = durations[:, k], jerks[:, k]
        s[:, k + 1] = s[:, k] + v[:, k] * h + a[:, k] * h ** 2 / 2.0 + j * h ** 3 / 6.0
        v[:, k + 1] = v[:, k] + a[:, k] * h + j * h ** 2 / 2.0
        if acc is None:
            a[:, k + 1] = a[:, k] + j * h
    return s, v, a


def _scurve_laws(batch: _Batch, seqs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per sequence of ``seqs``, the fastest S-curve (:func:`_scurve`) found within every limit
    at its samples: phase durations (S, 7), s, and path jerks (S, 7); durations inf where none."""
    lim = batch.limits
    count = len(seqs)
    uniform = np.linspace(0.0, 1.0, _SCURVE_START_SAMPLES)
    x, tangent = batch.point_cap(np.repeat(seqs, len(uniform)), np.tile(uniform, count))
    cap = np.sqrt(np.min(x.reshape(count, -1), axis=1))
    with np.errstate(divide="ignore"):  # a joint that does not move limits nothing
        acc = np.min(lim.acceleration[:, None] / tangent, axis=0).reshape(count, -1).min(axis=1)
        jerk = np.min(lim.jerk[:, None] / tangent, axis=0).reshape(count, -1).min(axis=1)
    acc, jerk = np.repeat(acc[:, None], 2, axis=1), np.repeat(jerk[:, None], 4, axis=1)
    acc_factor, jerk_factor = np.ones((count, 2)), np.ones((count, 4))
    best_durations, best_jerks = np.full((count, 7), np.inf), np.zeros((count, 7))
    fraction = np.linspace(0.0, 1.0, _SCURVE_SAMPLES)
    sample_seq = np.repeat(seqs, 7 * _SCURVE_SAMPLES)
    shape = (count, 7, _SCURVE_SAMPLES)
    for _ in range(_SCURVE_ROUNDS):
        durations, jerks, peak = _scurve(cap, acc, jerk)
        s0, v0, a0 = (state[:, :, None] for state in _phase_starts(durations, jerks))
        tau, j = durations[:, :, None] * fraction, jerks[:, :, None]
        s = np.clip(s0 + v0 * tau + a0 * tau ** 2 / 2.0 + j * tau ** 3 / 6.0, 0.0, 1.0).ravel()
        sd = (v0 + a0 * tau + j * tau ** 2 / 2.0).ravel()
        sdd = (a0 + j * tau).ravel()
        sddd = np.broadcast_to(j, shape).ravel()
        q1, q2, q3 = batch.path.derivatives(batch.path.locate(sample_seq, s), s, (1, 2, 3))
        speed_ratio = (sd / np.sqrt(batch.point_cap(sample_seq, s)[0])).reshape(shape)
        acc_ratio = np.max(np.abs(q1 * sdd + q2 * sd ** 2) / lim.acceleration[:, None], axis=0).reshape(shape)
        jerk_ratio = np.max(np.abs(q1 * sddd + 3.0 * q2 * sd * sdd + q3 * sd ** 3) / lim.jerk[:, None],
                            axis=0).reshape(shape)
        worst = np.maximum(np.maximum(speed_ratio, acc_ratio), jerk_ratio).max(axis=(1, 2))
        better = (worst <= 1.0) & (durations.sum(axis=1) < best_durations.sum(axis=1))
        best_durations[better], best_jerks[better] = durations[better], jerks[better]
        # Next: the speed capped below any excess; each phase's limits the tangential ones over
        # the stretch it now covers, times its factor, lowered past any excess it had.
        with np.errstate(divide="ignore"):
            tangent_acc = np.min(lim.acceleration[:, None] / np.abs(q1), axis=0).reshape(shape)
            tangent_jerk = np.min(lim.jerk[:, None] / np.abs(q1), axis=0).reshape(shape)
        excess = speed_ratio.max(axis=(1, 2))
        cap = np.where(excess > 1.0, np.minimum(cap, peak) / (excess * _SCURVE_MARGIN), cap)
        for k, half in enumerate((slice(0, 3), slice(4, 7))):
            excess = acc_ratio[:, half].max(axis=(1, 2))
            acc_factor[:, k] /= np.where(excess > 1.0, excess * _SCURVE_MARGIN, 1.0)
            acc[:, k] = acc_factor[:, k] * tangent_acc[:, half].min(axis=(1, 2))
        for k, phase in enumerate((0, 2, 4, 6)):
            excess = jerk_ratio[:, phase].max(axis=1)
            jerk_factor[:, k] /= np.where(excess > 1.0, excess * _SCURVE_MARGIN, 1.0)
            jerk[:, k] = jerk_factor[:, k] * tangent_jerk[:, phase].min(axis=1)
    return best_durations, best_jerks


def _scurve_profiles(seqs: np.ndarray, durations: np.ndarray, jerks: np.ndarray) -> _Profiles:
    """The S-curves (:func:`_scurve`) of the sequences ``seqs`` as profiles (phases of no duration left out)."""
    s0, v0, a0 = _phase_starts(durations, jerks)
    keep = durations > 0
    bfirst = np.r_[0, np.cumsum(keep.sum(axis=1) + 1)]
    breaks = np.empty(bfirst[-1])
    ends = bfirst[1:] - 1
    breaks[np.delete(np.arange(len(breaks)), ends)] = (np.cumsum(durations, axis=1) - durations)[keep]
    breaks[ends] = durations.sum(axis=1)
    return _Profiles(seqs, breaks, bfirst, np.stack([jerks[keep] / 6.0, a0[keep] / 2.0, v0[keep], s0[keep]]))


def _longest_interval(s: np.ndarray, x: np.ndarray) -> float:
    """Duration (s) of the longest grid interval but the two at the ends (those halved toward rest)."""
    return float(np.max(third_order.interval_times(s, x)[1:-1], initial=0.0))


class _Planner:
    """All the sequences of a batch: grid and caps once, then TOPP2, filter and verification in
    rounds, each round over the sequences not yet within every limit."""

    def __init__(self, batch: _Batch, engine: Engine, max_refinements: int, erode: float, widest: bool,
                 grid_factor: float = 1.0) -> None:
        self.batch, self.engine, self.solve, self.max_refinements = batch, engine, solver(engine), max_refinements
        self.erode = erode
        lim = batch.limits
        count = batch.count
        path, s, bfirst = batch.path, batch.s, batch.bfirst
        bseq = path.owner
        ds = np.diff(s)[np.arange(len(bseq)) + bseq]
        mids = path.start + 0.5 * ds
        x_mid, tangent_mid = batch.point_cap(bseq, mids)
        tau = ds / np.sqrt(x_mid)  # s per block at its cap
        t_est = np.add.reduceat(tau, bfirst[:-1])
        self.t_scale = np.maximum(t_est, 1e-6)
        # Filter width per sequence (module docstring, step 3): long enough to ramp the fastest
        # joint to its capped speed with its jerk limit, at most where full acceleration pays.
        self.widest = (_SAFE_FIR_FACTOR if widest else _FIR_FACTOR) * float(np.max(lim.acceleration / lim.jerk))
        if not batch.jerk:
            self.w = np.zeros(count)
        elif widest:
            self.w = np.full(count, self.widest)
        else:
            speed = tangent_mid * np.sqrt(x_mid)  # joints at the block caps
            ramp = np.sqrt(np.max(speed / lim.jerk[:, None], axis=0))
            self.w = np.minimum(np.maximum.reduceat(ramp, bfirst[:-1]), self.widest)
        blocks = np.diff(bfirst)
        window = (self.w if batch.jerk else np.full(count, 0.05)) / (grid_factor * _GRID_PER_WINDOW)
        per_block = grid_factor * _MAX_INTERVALS_PER_BLOCK
        delta = np.maximum(np.minimum(window, t_est / _MIN_INTERVALS), t_est / (per_block * blocks + _MIN_INTERVALS))
        # Gridpoints: waypoints where the travel time at the caps crosses a multiple of delta,
        # long blocks subdivided, and a geometrically refined start and end (from and to rest).
        wseq = np.repeat(np.arange(count), np.diff(batch.wfirst))
        cum = np.zeros(len(s))
        cum[np.arange(len(bseq)) + bseq + 1] = _segment_cumsum(tau, bfirst)
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
            at = _ranges(np.zeros(count, int), halvings) + 1
            point = np.repeat(gap, halvings) * 0.5 ** at
            ends.append(1.0 - point if mirror else point)
            end_seq.append(np.repeat(np.arange(count), halvings))
        gseq, grid, gfirst = _sorted_points(np.concatenate([wseq[kept], bseq[long][owner], *end_seq]),
                                            np.concatenate([s[kept], interior, *ends]), count)
        self.grid = _Pieces(grid, gfirst)
        n = len(grid)
        # Check points: the gridpoints, the middles of their intervals, the waypoints, the block middles.
        inner_grid = np.flatnonzero(np.diff(gseq) == 0)
        cseq, check, cfirst = _sorted_points(
            np.concatenate([gseq, gseq[inner_grid], wseq, bseq]),
            np.concatenate([grid, 0.5 * (grid[inner_grid] + grid[inner_grid + 1]), s, mids]), count)
        checks = _Pieces(check, cfirst)
        raw, tangent = batch.point_cap(cseq, check)
        # No S-curve along a sequence (_scurve_plans) is faster than the whole path at its lowest cap.
        self.scurve_floor = 1.0 / np.sqrt(np.minimum.reduceat(raw, cfirst[:-1]))
        # With the filter, the speed at a point mixes the speeds within half a filter width of
        # travel around it: each check point imposes its cap over erode * w * (its own capped
        # speed) on either side. The squared speed is linear in s between gridpoints, so the
        # gridpoints within that range take the cap, and the two intervals it ends in are
        # lowered at both ends until their line meets it at the range's ends.
        reach = erode * self.w[cseq] * np.sqrt(raw)
        lo = self.grid.search(cseq, check - reach, "left")
        hi = self.grid.search(cseq, check + reach, "right") - 1
        inside = lo <= hi
        xcap = _range_chmin(n, lo[inside], hi[inside], raw[inside])
        scale = np.ones(n)  # per interval, by its left gridpoint
        # The gridpoint at or before each end of the range: the one before the first inside it,
        # the last inside it (an end on a gridpoint gives a weight of 1 or 0: the same line).
        for end, left in ((np.clip(check - reach, 0.0, 1.0), lo - 1), (np.clip(check + reach, 0.0, 1.0), hi)):
            left = self.grid.clip(cseq, left)
            right = np.minimum(left + 1, gfirst[cseq + 1] - 1)
            span = grid[right] - grid[left]
            weight = np.divide(end - grid[left], span, out=np.zeros_like(span), where=span > 0)
            line = xcap[left] + weight * (xcap[right] - xcap[left])
            np.minimum.at(scale, left, np.minimum(raw / line, 1.0))
        before = np.r_[1.0, scale[:-1]]
        before[gfirst[:-1]] = 1.0
        self.xcap = xcap * np.minimum(scale, before)
        index = np.arange(n)
        lo0 = grid[np.maximum(index - 1, gfirst[gseq])]
        hi0 = grid[np.minimum(index + 1, gfirst[gseq + 1] - 1)]
        r = erode * self.w[gseq] * np.sqrt(self.xcap)
        self.radius = np.maximum(r, np.maximum(grid - lo0, hi0 - grid))
        # Path acceleration bound: the filter spreads a path acceleration over its window, where
        # |q_j'| may be larger than at the gridpoint; |sddot| <= a_j / max over the window |q_j'|,
        # and u / w within the jerk limit: |sddot| <= w J_j / max |q_j'|.
        a = checks.clip(gseq, checks.search(gseq, np.minimum(grid - r, lo0), "left"))
        b = np.maximum(a, checks.clip(gseq, checks.search(gseq, np.maximum(grid + r, hi0), "right") - 1))
        # 1 / bound = max(max_j |q_j'| / a_j, max_j |q_j'| / J_j / w): both kept, for a new w.
        self.need_acc = _range_max(np.max(tangent / lim.acceleration[:, None], axis=0), a, b)
        self.need_jerk = _range_max(np.max(tangent / lim.jerk[:, None], axis=0), a, b) if batch.jerk else None
        self._acceleration_bound()
        piece = batch.path.locate(gseq, grid)
        self.q1, self.q2 = (d.T for d in batch.path.derivatives(piece, grid, (1, 2)))  # (G, 5)

    def _acceleration_bound(self) -> None:
        """The path acceleration bound umax (1/s^2) at the gridpoints for the current widths."""
        need = self.need_acc
        if self.need_jerk is not None:
            need = np.maximum(need, self.need_jerk / self.w[self.grid.owner])
        with np.errstate(divide="ignore"):
            self.umax = np.minimum(1.0 / need, 1e300)

    # -- rounds ---------------------------------------------------------------------------------

    def plan(self) -> list[FeedPlan | PlanningError]:
        count = self.batch.count
        results: list[FeedPlan | PlanningError | None] = [None] * count
        n = len(self.grid.start)
        cap = np.full(n, np.inf)
        acc_scale = np.full(n, _ACC_MARGIN if self.batch.jerk else 1.0)
        # The engines may exceed their bounds by rounding, and the filter mixes neighbouring speeds:
        # keep clear. 4e-5 left one sequence in six of the 105k job 2e-5 to 4e-5 over a cap,
        # each then planned again with its caps 3 % lower there (slower, and a round of planning more).
        base = self.xcap * (1.0 - 3e-4)
        x = np.zeros(n)
        active = np.arange(count)
        worst: dict[int, tuple[float, float, float, float]] = {}
        narrowed, plateaued = np.zeros(count, bool), np.zeros(count, bool)
        scurves: dict[int, FeedPlan] = {}
        for attempt in range(self.max_refinements + 1):
            solved = []
            xmax = np.minimum(base, cap)
            for r in active:
                outcome = self._topp(int(r), xmax, acc_scale)
                if isinstance(outcome, PlanningError):
                    results[r] = outcome
                else:
                    x[self.grid.first[r]:self.grid.first[r + 1]] = outcome
                    solved.append(r)
            if not solved:
                break
            profiles, stuck = self._profiles(np.array(solved), x)
            for r, error in stuck.items():
                results[r] = error
            times, broken = self._block_times(profiles)
            for r, error in broken.items():
                results[r] = error
            good = ~np.isin(profiles.seqs, list(broken))
            where, fx, fa, seq, ratios, peaks = self._verify(profiles, times, good)
            failing = np.unique(seq)
            for k in np.flatnonzero(good & ~np.isin(profiles.seqs, failing)):
                results[profiles.seqs[k]] = self._feed_plan(int(profiles.seqs[k]), profiles, int(k), times, attempt,
                                                            peaks[k])
            if attempt == 0 and self.batch.jerk:
                # A sequence within every limit has its plan; one still over a limit only slows
                # down in later rounds: its S-curve, if faster than this round, ends its rounds, or
                # else may still win at the end (tried where it may beat 1.25 times this round:
                # the later rounds cost the 105k job's re-orientations 2 to 8 %).
                over = np.isin(profiles.seqs, failing)
                scurves = self._scurve_plans(profiles.seqs[good], (np.where(over, 1.25, 1.0) * profiles.total)[good])
                first = dict(zip(profiles.seqs.tolist(), profiles.total.tolist(), strict=True))
                done = [r for r in failing.tolist() if r in scurves and scurves[r].total <= first[r]]
                for r in done:
                    results[r] = scurves.pop(r)
                failing = np.setdiff1d(failing, done)
            if not len(failing):
                break
            for r in failing:
                mine = seq == r
                top = int(np.argmax(np.max(ratios[mine], axis=1)))
                worst[int(r)] = (*ratios[mine][top], float(where[mine][top]))
            # Lower the caps and the acceleration bound around each violation, in proportion, over
            # the stretch the filter window there can span (twice the erosion radius, and the
            # neighbouring gridpoints).
            grid = self.grid
            nearest = np.clip(grid.search(seq, where), grid.first[seq] + 1, grid.first[seq + 1] - 1)
            reach = 2.0 * np.maximum(self.radius[nearest], self.radius[nearest - 1])
            lo = grid.clip(seq, grid.search(seq, where - reach, "left") - 1)
            hi = grid.clip(seq, grid.search(seq, where + reach, "right"))
            fx_grid = np.minimum(_range_chmin(n, lo, hi, fx), 1.0)
            fa_grid = np.minimum(_range_chmin(n, lo, hi, fa), 1.0)
            cap = np.minimum(cap, np.where(fx_grid < 1.0, fx_grid * np.maximum(x, 0.0), np.inf))
            # A turn without cruise (module docstring, step 4): a plateau, not a lower acceleration.
            turns = np.array([r for r in failing if worst[int(r)][2] >= _TURN_JERK and not plateaued[r]], dtype=int)
            if len(turns):
                # A peak too slow to need full acceleration wants a narrower window first (the
                # time-optimal ramp to V has w = sqrt(V / J)); its plateau comes the round after.
                peak = _peaks(grid, x, turns)
                ramp = np.sqrt(np.max(np.abs(self.q1[peak]) * np.sqrt(np.maximum(x[peak], 0.0))[:, None]
                                      / self.batch.limits.jerk, axis=1))
                narrower = (ramp < _NARROWER * self.w[turns]) & ~narrowed[turns]
                if np.any(narrower):
                    self.w[turns[narrower]] = ramp[narrower]
                    narrowed[turns[narrower]] = True
                    self._acceleration_bound()
                    fa_grid[np.isin(grid.owner, turns[narrower])] = 1.0
                    turns = turns[~narrower]
            if len(turns):
                level = np.full(count, np.nan)
                level[turns] = _plateau_levels(grid, x, turns, self.w[turns])
                plateaued[turns] = True
                on_plateau = np.isfinite(level)[grid.owner]
                cap[on_plateau] = np.minimum(cap[on_plateau], level[grid.owner[on_plateau]])
                fa_grid[on_plateau] = 1.0
            acc_scale = acc_scale * fa_grid
            logger.debug("feed plan round %d: %d sequences over the limits", attempt, len(failing))
            active = failing
        kinds = ("velocity or feed", "acceleration", "jerk")
        for r, (*ratio, at) in worst.items():
            if results[r] is None:
                kind = kinds[int(np.argmax(ratio))]
                index = self.batch.waypoint_at(r, at)
                results[r] = PlanningError(
                    f"no time law within the joint {kind} limits found near waypoint {index} after "
                    f"{self.max_refinements} refinements (worst ratio {max(ratio):.3f}): the jerk/acceleration "
                    f"limits cannot be met along this path", index)
        for r, plan in scurves.items():  # verified too: also where the filtered plan found none
            if not isinstance(results[r], FeedPlan) or plan.total < results[r].total:  # type: ignore[union-attr]
                results[r] = plan
        assert all(result is not None for result in results)
        return results  # type: ignore[return-value]

    def _scurve_plans(self, seqs: np.ndarray, planned: np.ndarray) -> dict[int, FeedPlan]:
        """Verified S-curves along the paths of the sequences ``seqs`` (:func:`_scurve_laws`) that
        are faster than ``planned`` (s, each); only sequences whose lowest cap allows that are tried."""
        hopeful = self.scurve_floor[seqs] < planned
        seqs, planned = seqs[hopeful], planned[hopeful]
        if not len(seqs):
            return {}
        durations, jerks = _scurve_laws(self.batch, seqs)
        faster = np.flatnonzero(np.sum(durations, axis=1) < planned)
        if not len(faster):
            return {}
        profiles = _scurve_profiles(seqs[faster], durations[faster], jerks[faster])
        times, broken = self._block_times(profiles)
        good = ~np.isin(profiles.seqs, list(broken))
        _, _, _, failing, _, peaks = self._verify(profiles, times, good)
        plans = {}
        for k in np.flatnonzero(good & ~np.isin(profiles.seqs, failing)):
            r = int(profiles.seqs[k])
            plans[r] = replace(self._feed_plan(r, profiles, int(k), times, 0, peaks[k]),
                               filter_width=float(durations[faster[k], 0]), gridpoints=0)
        return plans

    def _second_order_upper(self) -> tuple[np.ndarray, list[int]]:
        """The second-order optimum at the gridpoints (1/s^2), within the caps as they are: it
        bounds every third-order law from above, and is the programme's first reference; and
        the sequences where TOPP2 found it."""
        n = len(self.grid.start)
        caps = self.xcap * (1.0 - 3e-4)
        upper = np.zeros(n)
        active = []
        for r in range(self.batch.count):
            outcome = self._topp(r, caps, np.ones(n), filtered=False)
            if not isinstance(outcome, PlanningError):
                upper[self.grid.first[r]:self.grid.first[r + 1]] = outcome
                active.append(r)
        return np.minimum(upper, caps), active

    def _third_order_problem(self, r: int, upper: np.ndarray, q3: np.ndarray, margin: np.ndarray
                             ) -> third_order.ThirdOrderProblem:
        """Sequence r's programme under the caps ``upper`` with the (acceleration, jerk) margins;
        q3 the path's third derivatives at every gridpoint."""
        g = slice(self.grid.first[r], self.grid.first[r + 1])
        lim = self.batch.limits
        return third_order.ThirdOrderProblem(self.grid.start[g], upper[g], self.q1[g], self.q2[g], q3[g],
                                             margin[0] * lim.acceleration, margin[1] * lim.jerk)

    def third_order_plans(self) -> dict[int, FeedPlan]:
        """Verified plans of this batch's sequences by the third-order linear programme
        (:mod:`verne_post.planning.third_order`), for a planner built with ``erode=0``: the caps as they
        are, the programme keeping the filtered law within them. Rounds as in :meth:`plan`: a
        law over a cap has the caps of the gridpoints around the excess lowered by it, one over
        an acceleration or jerk limit its sequence's margins; a sequence that finds no law
        within every limit is left out (its filtered plan stays). The planner's filter widths
        become the programme's windows."""
        grid, count, n = self.grid, self.batch.count, len(self.grid.start)
        upper, active = self._second_order_upper()
        path = self.batch.path
        q3 = path.derivatives(path.locate(grid.owner, grid.start), grid.start, (3,))[0].T  # (G, 5), once
        margin = np.tile([_LP_ACC_MARGIN, _LP_JERK_MARGIN], (count, 1))
        x = np.zeros(n)
        plans: dict[int, FeedPlan] = {}
        for attempt in range(_LP_ROUNDS):
            solved = []
            for r in active:
                g = slice(grid.first[r], grid.first[r + 1])
                problem = self._third_order_problem(r, upper, q3, margin[r])
                if attempt == 0:
                    # The window: _LP_WINDOW longest inner intervals of a first law (found with the
                    # second-order law's longest): an interval longer than the window bounds its
                    # steps by J w, stricter than its duration needs.
                    self.w[r] = _longest_interval(problem.s, upper[g])
                    first = third_order.solve_filtered(problem, upper[g], self.w[r])
                    if first is None:
                        continue
                    self.w[r] = _LP_WINDOW * max(self.w[r], _longest_interval(problem.s, first))
                # Later rounds start from the last law (its pairs, its linearisation).
                found = third_order.solve_filtered(problem, upper[g] if attempt == 0 else x[g], self.w[r])
                if found is not None:
                    x[g] = found
                    solved.append(r)
            if not solved:
                break
            profiles, _ = self._profiles(np.array(solved), x)
            times, broken = self._block_times(profiles)
            good = ~np.isin(profiles.seqs, list(broken))
            where, _, _, seq, ratios, peaks = self._verify(profiles, times, good)
            failing = np.unique(seq)
            for k in np.flatnonzero(good & ~np.isin(profiles.seqs, failing)):
                r = int(profiles.seqs[k])
                plans[r] = self._feed_plan(r, profiles, int(k), times, attempt, peaks[k])
            # Over a cap: the gridpoints either side of the excess lowered by it (squared).
            over = ratios[:, 0] > 1.0 + _VERIFY_TOL
            nearest = np.clip(grid.search(seq[over], where[over]), grid.first[seq[over]] + 1,
                              grid.first[seq[over] + 1] - 1)
            for side in (nearest - 1, nearest):
                np.minimum.at(upper, side, x[side] / (ratios[over, 0] * _SCURVE_MARGIN) ** 2)
            for column in (1, 2):  # over an acceleration or jerk limit: that margin, by the largest excess
                excess = np.ones(count)
                np.maximum.at(excess, seq, ratios[:, column])
                margin[:, column - 1] /= np.where(excess > 1.0 + _VERIFY_TOL, excess * _SCURVE_MARGIN, 1.0)
            active = [int(r) for r in failing if r not in broken]
            if not active:
                break
        return plans

    def _topp(self, r: int, xmax: np.ndarray, acc_scale: np.ndarray, filtered: bool = True
              ) -> np.ndarray | PlanningError:
        """Squared path speeds (1/s^2) at the gridpoints of sequence r, time-optimal under xmax
        and the accelerations (and, to be ``filtered``, the path acceleration bound umax).

        An engine may lose a reachable set to rounding; the same problem is then solved again at
        another time scale, with the acceleration limits 0.1 to 2 % lower (stricter, never looser).
        """
        g = slice(self.grid.first[r], self.grid.first[r + 1])
        failure = None
        for tighten, rescale in _RETRIES:
            t0 = self.t_scale[r] * rescale
            scale = acc_scale[g] * tighten
            inverse = 1.0 / (scale[:, None] * self.batch.limits.acceleration[None, :] * t0 ** 2)
            umax = scale * self.umax[g] * t0 ** 2 if self.batch.jerk and filtered else None
            try:
                x = self.solve(self.grid.start[g], np.maximum(xmax[g], 0.0) * t0 ** 2, umax, self.q1[g] * inverse,
                               self.q2[g] * inverse) / t0 ** 2
            except ToppError as error:
                failure = error
                logger.debug("%s failed (accelerations x %s, time scale x %s): %s", self.engine, tighten, rescale,
                             error)
                continue
            x[0] = x[-1] = 0.0
            return x
        where = 0 if failure is None or failure.index is None else self.batch.waypoint_at(
            r, float(self.grid.start[g][min(failure.index, g.stop - g.start - 1)]))
        return PlanningError(f"{self.engine} found no feasible time law near waypoint {where} (instance not "
                             f"controllable or numerically ill-conditioned)", where)

    # -- the time law ---------------------------------------------------------------------------

    def _profiles(self, seqs: np.ndarray, x: np.ndarray) -> tuple[_Profiles, dict[int, PlanningError]]:
        """s(t) of the sequences ``seqs`` from their squared path speeds x at the gridpoints: the
        constant-acceleration profile, filtered when jerk is limited."""
        grid = self.grid
        stuck: dict[int, PlanningError] = {}
        v_all = np.sqrt(np.maximum(x, 0.0))
        zero = np.flatnonzero((v_all[:-1] + v_all[1:] <= 0) & (grid.owner[:-1] == grid.owner[1:]))
        for i in zero[np.isin(grid.owner[zero], seqs)]:
            r = int(grid.owner[i])
            if r not in stuck:
                where = self.batch.waypoint_at(r, float(grid.start[i]))
                stuck[r] = PlanningError(f"the planned path speed drops to zero near waypoint {where}", where)
        seqs = np.array([r for r in seqs if r not in stuck], dtype=int)
        counts = grid.first[seqs + 1] - grid.first[seqs]
        gi = _ranges(grid.first[seqs], grid.first[seqs + 1])
        nfirst = np.r_[0, np.cumsum(counts)]
        owner = np.repeat(np.arange(len(seqs)), counts)
        s_nodes, v = grid.start[gi], v_all[gi]
        inner = np.flatnonzero(owner[1:] == owner[:-1])
        dgrid = s_nodes[inner + 1] - s_nodes[inner]
        dt = 2.0 * dgrid / (v[inner] + v[inner + 1])
        u = (x[gi][inner + 1] - x[gi][inner]) / (2.0 * dgrid)
        ifirst = nfirst - np.arange(len(nfirst))
        t_nodes = np.zeros(len(gi))
        t_nodes[inner + 1] = _segment_cumsum(dt, ifirst)
        if not self.batch.jerk:
            coef = np.stack([np.zeros_like(u), 0.5 * u, v[inner], s_nodes[inner]])
            return _Profiles(seqs, t_nodes, nfirst, coef), stuck
        total = t_nodes[nfirst[1:] - 1]
        w = self.w[seqs]
        sigma = _Pieces(t_nodes[inner], ifirst)
        s0, v0 = s_nodes[inner], v[inner]
        area = s0 * dt + v0 * dt ** 2 / 2.0 + u * dt ** 3 / 6.0
        # Integrals of sigma in long double, restarting at each sequence: ~1e-16 precision in s.
        running = _segment_cumsum(area, ifirst, np.longdouble)  # through each piece
        total_area = running[ifirst[1:] - 1]
        prefix = np.concatenate([[np.longdouble(0.0)], running[:-1]])  # before each piece
        prefix[ifirst[:-1]] = 0.0

        def derivatives(k: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            i = sigma.locate(k, t)
            tau = t - sigma.start[i]
            before, after = t < 0.0, t >= total[k]
            value = np.where(before, 0.0, np.where(after, 1.0, s0[i] + v0[i] * tau + u[i] * tau ** 2 / 2.0))
            rest = before | after
            return value, np.where(rest, 0.0, v0[i] + u[i] * tau), np.where(rest, 0.0, u[i])

        def integral(k: np.ndarray, t: np.ndarray) -> np.ndarray:
            i = sigma.locate(k, t)
            tau = t - sigma.start[i]
            local = (s0[i] * tau + v0[i] * tau ** 2 / 2.0 + u[i] * tau ** 3 / 6.0).astype(np.longdouble)
            out = np.where(t <= 0.0, np.longdouble(0.0), prefix[i] + local)
            return np.where(t >= total[k], total_area[k] + (t - total[k]).astype(np.longdouble),
                            out)

        bseq, breaks, bfirst = _sorted_points(np.concatenate([owner, owner]),
                                              np.concatenate([t_nodes, t_nodes + w[owner]]), len(seqs))
        # Breakpoints t[i] and t[j] + w can nearly coincide: a sliver piece between them would get
        # its third derivative from the wrong side by rounding. Pieces under a nanosecond are merged.
        last = np.zeros(len(breaks), bool)
        last[bfirst[1:] - 1] = True
        keep = last.copy()
        keep[bfirst[:-1]] = True
        keep[:-1] |= (breaks[1:] - breaks[:-1] > 1e-9) & ~last[:-1]
        bseq, breaks = bseq[keep], breaks[keep]
        bfirst = np.searchsorted(bseq, np.arange(len(seqs) + 1))
        ends = bfirst[1:] - 1
        k = np.delete(bseq, ends)
        left = np.delete(breaks, ends)
        mid = left + 0.5 * (np.delete(breaks, bfirst[:-1]) - left)
        wk = w[k]
        value = ((integral(k, left) - integral(k, left - wk)) / wk.astype(np.longdouble)).astype(float)
        a1, b1, _ = derivatives(k, left)
        a0, b0, _ = derivatives(k, left - wk)
        third = (derivatives(k, mid)[2] - derivatives(k, mid - wk)[2]) / wk
        coef = np.stack([third / 6.0, (b1 - b0) / (2.0 * wk), (a1 - a0) / wk, value])
        return _Profiles(seqs, breaks, bfirst, coef), stuck

    def _block_times(self, profiles: _Profiles) -> tuple[tuple[np.ndarray, np.ndarray], dict[int, PlanningError]]:
        """Times at which each sequence's s(t) reaches its waypoints: (times, offsets per sequence)."""
        batch, pieces = self.batch, profiles.pieces
        count = len(profiles.seqs)
        # s at every break (the end: the last piece at its end), made nondecreasing per sequence.
        at = np.empty(len(profiles.breaks))
        starts = np.delete(np.arange(len(at)), profiles.bfirst[1:] - 1)
        at[starts] = pieces.coef[3]
        ends = profiles.bfirst[1:] - 1
        last_piece = pieces.first[1:] - 1
        at[ends] = pieces(last_piece, profiles.breaks[ends])
        owner = np.repeat(np.arange(count), np.diff(profiles.bfirst))
        at = np.maximum.accumulate(owner + 1j * at).imag  # per sequence (complex order: lexicographic)
        levels = _Pieces(at, profiles.bfirst)
        seqs = profiles.seqs
        wcount = batch.wfirst[seqs + 1] - batch.wfirst[seqs]
        tfirst = np.r_[0, np.cumsum(wcount)]
        targets_index = _ranges(batch.wfirst[seqs] + 1, batch.wfirst[seqs + 1] - 1)
        k = np.repeat(np.arange(count), wcount - 2)
        targets = batch.s[targets_index]
        m = np.clip(levels.search(k, targets, "right") - 1, profiles.bfirst[k], profiles.bfirst[k + 1] - 2)
        piece = m - k
        h = profiles.breaks[m + 1] - profiles.breaks[m]
        c3, c2, c1, c0 = (pieces.coef[j, piece] for j in range(4))
        lo = np.zeros_like(targets)
        hi = h.copy()
        span = at[m + 1] - at[m]
        with np.errstate(divide="ignore", invalid="ignore"):
            tau = np.clip(np.where(span > 0, h * (targets - at[m]) / span, 0.5 * h), lo, hi)
        for _ in range(60):
            f = ((c3 * tau + c2) * tau + c1) * tau + c0 - targets
            df = (3.0 * c3 * tau + 2.0 * c2) * tau + c1
            lo = np.where(f < 0, tau, lo)
            hi = np.where(f > 0, tau, hi)
            with np.errstate(divide="ignore", invalid="ignore"):
                newton = tau - f / df
            ok = (df > 0) & (newton > lo) & (newton < hi)
            new = np.where(ok, newton, 0.5 * (lo + hi))
            done = (f == 0) | (np.abs(new - tau) <= 1e-15 * np.maximum(h, 1.0))
            tau = np.where(f == 0, tau, new)
            if np.all(done):
                break
        times = np.zeros(tfirst[-1])
        inner = np.delete(np.arange(tfirst[-1]), np.r_[tfirst[:-1], tfirst[1:] - 1])
        times[inner] = profiles.breaks[m] + tau
        times[tfirst[1:] - 1] = profiles.total
        broken: dict[int, PlanningError] = {}
        towner = np.repeat(np.arange(count), wcount)
        for i in np.flatnonzero((np.diff(times) <= 0) & (towner[1:] == towner[:-1])):
            r = int(seqs[towner[i]])
            if r not in broken:
                block = int(i - tfirst[towner[i]])
                broken[r] = PlanningError(f"block {block} got a non-positive duration (numerical failure)", block)
        return (times, tfirst), broken

    def _verify(self, profiles: _Profiles, times: tuple[np.ndarray, np.ndarray], good: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Worst excess over the limits at samples of the time laws of the good sequences.

        Returns, for the samples that exceed a limit: their path parameter s, the factor on the
        squared speed cap, the factor on the acceleration bound, their sequence, and their
        (velocity, acceleration, jerk) ratios (n, 3); and per profile the largest |velocity|,
        |acceleration|, |jerk| of each joint over its limit at the samples (S, 3, 5).
        """
        batch, pieces = self.batch, profiles.pieces
        times, tfirst = times
        pk = pieces.owner
        h = np.diff(profiles.breaks)[np.delete(np.arange(len(profiles.breaks) - 1), profiles.bfirst[1:-1] - 1)]
        fill_dt = max(self.widest / 8.0, 1e-3) if batch.jerk else 5e-3
        # A piece lies within one grid interval, where the path and the cubic s(t) are smooth: a
        # bounded number of samples resolves it however long it lasts (a very slow feed gives
        # pieces of hours, which at fill_dt would not fit in memory).
        chosen = np.flatnonzero(good[pk])
        gaps = np.clip(np.ceil(h[chosen] / fill_dt), 2, _MAX_PIECE_SAMPLES).astype(int)
        piece = np.repeat(chosen, gaps)
        step = np.arange(int(gaps.sum())) - np.repeat(np.cumsum(gaps) - gaps, gaps)
        t = pieces.start[piece] + h[piece] * step / np.repeat(gaps, gaps)
        # s(t) is C2: at a break only the path jerk sddd changes, so the first sample of a piece
        # also carries the previous piece's sddd (the left side of the break), 6 c3 of that piece.
        left = np.full(len(t), np.nan)
        after = (step == 0) & (piece > pieces.first[pk[piece]])
        left[after] = 6.0 * pieces.coef[0, piece[after] - 1]
        towner = np.repeat(np.arange(len(profiles.seqs)), np.diff(tfirst))
        interior = np.flatnonzero((towner[1:] == towner[:-1]) & good[towner[1:]])
        interior = interior[np.isin(interior + 1, tfirst[1:] - 1, invert=True)]  # waypoints 1 .. K - 1
        dt = np.diff(times)
        around_t = np.concatenate([times[interior + 1] - 1e-7 * dt[interior],
                                   times[interior + 1] + 1e-7 * dt[interior + 1]])
        around_k = np.concatenate([towner[interior + 1]] * 2)
        final_k = np.flatnonzero(good)  # the end of the last piece: the end of the motion
        t = np.concatenate([t, around_t, profiles.total[final_k]])
        piece = np.concatenate([piece, pieces.locate(around_k, around_t), pieces.first[final_k + 1] - 1])
        left = np.concatenate([left, np.full(len(around_t) + len(final_k), np.nan)])
        order = np.argsort(pieces.owner[piece], kind="stable")  # by profile, for the peaks per profile
        piece, t, left = piece[order], t[order], left[order]
        peaks = np.zeros((len(profiles.seqs), 3 * DOF))
        found = []
        for chunk in np.array_split(np.arange(len(t)), max(1, -(-len(t) // _VERIFY_CHUNK))):
            *excess, (k, peak) = self._excess(profiles, piece[chunk], t[chunk], left[chunk])
            np.maximum.at(peaks, k, peak)
            found.append(excess)
        bad = tuple(np.concatenate(parts) for parts in zip(*found, strict=True))
        return (*bad, peaks.reshape(-1, 3, DOF))  # type: ignore[return-value]

    def _excess(self, profiles: _Profiles, piece: np.ndarray, t: np.ndarray, left: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
        """_verify's findings at samples t, each in its profile piece, sorted by profile (see
        there); ``left`` the path jerk just before a sample at a break (NaN elsewhere). The
        peaks as (profiles present, their (3 * 5) peaks)."""
        batch, pieces, lim = self.batch, profiles.pieces, self.batch.limits
        k = pieces.owner[piece]
        t = np.clip(t, 0.0, profiles.total[k])
        s, sd, sdd, sddd = pieces.derivatives(piece, t, (0, 1, 2, 3))
        s = np.clip(s, 0.0, 1.0)
        r = profiles.seqs[k]
        blk = batch.path.locate(r, s, "right")
        q1, q2, q3 = batch.path.derivatives(blk, s, (1, 2, 3))  # (5, n)
        v, a, j = lim.velocity[:, None], lim.acceleration[:, None], lim.jerk[:, None]
        joint_vel = np.abs(q1) / v * sd
        r_vel = np.max(joint_vel, axis=0)
        r_vel = np.maximum(r_vel, sd / batch.block_cap[blk])
        r_vel = np.maximum(r_vel, np.linalg.norm(batch.tip(blk, s, 1), axis=0) * sd / batch.tip_feed[blk])
        # Acceleration and jerk split into the tangential part (from the path acceleration and
        # jerk: lowered through the acceleration bound) and the rest (from the path's curvature:
        # lowered through the speed).
        acc_c = q2 * sd ** 2
        joint_acc = np.abs(q1 * sdd + acc_c) / a
        r_acc = np.max(joint_acc, axis=0)
        share_acc = np.max(np.abs(acc_c) / a, axis=0) / np.maximum(r_acc, 1e-300)
        if batch.jerk:
            jerk_c = 3.0 * q2 * (sd * sdd) + q3 * sd ** 3
            joint_jerk = np.abs(q1 * sddd + jerk_c) / j
            at_break = np.flatnonzero(~np.isnan(left))
            joint_jerk[:, at_break] = np.maximum(joint_jerk[:, at_break],
                                                 np.abs(q1[:, at_break] * left[at_break] + jerk_c[:, at_break]) / j)
            r_jerk = np.max(joint_jerk, axis=0)
            share_jerk = np.max(np.abs(jerk_c) / j, axis=0) / np.maximum(r_jerk, 1e-300)
        else:
            joint_jerk = np.zeros_like(joint_acc)
            r_jerk = share_jerk = np.zeros_like(r_acc)
        starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
        peaks = (k[starts], np.maximum.reduceat(np.vstack([joint_vel, joint_acc, joint_jerk]), starts, axis=1).T)
        bad = (r_vel > 1 + _VERIFY_TOL) | (r_acc > 1 + _VERIFY_TOL) | (r_jerk > 1 + _VERIFY_TOL)
        r_vel, r_acc, r_jerk = (np.maximum(ratio[bad], 1.0) for ratio in (r_vel, r_acc, r_jerk))
        curv_acc = share_acc[bad] > 0.5
        curv_jerk = share_jerk[bad] > 0.5
        fx = np.minimum(r_vel ** -2.0, np.where(curv_acc, r_acc ** -1.0, 1.0))
        fx = np.minimum(fx, np.where(curv_jerk, r_jerk ** (-2.0 / 3.0), 1.0))
        fa = np.minimum(np.where(curv_acc, 1.0, r_acc ** -1.0), np.where(curv_jerk, 1.0, r_jerk ** -1.0))
        fx = np.where(fx < 1.0, fx * _SHRINK, 1.0)
        fa = np.where(fa < 1.0, fa * _SHRINK, 1.0)
        return s[bad], fx, fa, r[bad], np.stack([r_vel, r_acc, r_jerk], axis=1), peaks

    def _feed_plan(self, r: int, profiles: _Profiles, k: int, times: tuple[np.ndarray, np.ndarray],
                   attempt: int, peaks: np.ndarray) -> FeedPlan:
        batch = self.batch
        block_times = times[0][times[1][k]:times[1][k + 1]].copy()
        b0, b1 = profiles.bfirst[k], profiles.bfirst[k + 1]
        profile = Cubics(profiles.breaks[b0:b1].copy(), np.ascontiguousarray(profiles.coef[:, b0 - k:b1 - k - 1]))
        return FeedPlan(np.diff(block_times), block_times, *batch.sequence_path(r), profile, float(self.w[r]),
                        int(self.grid.first[r + 1] - self.grid.first[r]), attempt, peaks)
