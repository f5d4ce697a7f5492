"""The plan of one feed sequence: its time law as cubics in time, and how it was found."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The factors of a cubic's coefficients (highest first) in its derivative of each order.
DERIVATIVE_WEIGHTS = {0: (1.0, 1.0, 1.0, 1.0), 1: (3.0, 2.0, 1.0), 2: (6.0, 2.0), 3: (6.0,)}


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
        weights = DERIVATIVE_WEIGHTS[nu]
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
