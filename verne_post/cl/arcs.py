"""Circular arcs and helices as points: pure geometry, no reader state.

Lengths are in whatever unit the caller uses (the reader passes file units); angles in radians.
An arc is given by its centre ``c``, unit axis ``n``, start and end points and a direction
about ``n`` (``"ccw"``: right-hand rule, ``"cw"``: the other way). Start and end may differ in
height along ``n`` and in radius: the height and radius change linearly with the swept angle
(a helix, or a spiral that absorbs the CAM's rounding of the radius).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["MAX_ARC_POINTS", "arc_points", "arc_sweep", "tangent_votes"]

MAX_ARC_POINTS = 1_000_000  # one arc may expand into at most this many points
_COS_TANGENT = 0.9  # a move within ~25 degrees of the arc tangent counts as tangent


def _frame(c: np.ndarray, n: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, float, float]:
    """(in-plane offset of ``p`` from the axis, its radius, its height along ``n``)."""
    d = p - c
    h = float(d @ n)
    v = d - h * n
    return v, float(np.linalg.norm(v)), h


def arc_sweep(c: np.ndarray, n: np.ndarray, start: np.ndarray, end: np.ndarray, direction: str,
              turns: int = 1, full_circle_tol: float = 0.0) -> float:
    """Angle (radians, > 0) swept from ``start`` to ``end`` going ``direction`` about ``n``.

    ``turns`` > 1 adds ``turns - 1`` full turns (NX ``CIRCLE/...,TIMES,n``: the partial arc plus
    n - 1 turns). Coincident start and end (within ``full_circle_tol``) make one full turn.
    """
    v0, r0, _ = _frame(c, n, start)
    v1, _, _ = _frame(c, n, end)
    if float(np.linalg.norm(v1 - v0)) <= full_circle_tol:
        theta = 2.0 * math.pi
    else:
        u = v0 / r0
        w = np.cross(n, u)
        theta = math.atan2(float(v1 @ w), float(v1 @ u))  # counter-clockwise angle in (-pi, pi]
        if direction == "cw":
            theta = -theta
        if theta <= 0.0:
            theta += 2.0 * math.pi
    return theta + 2.0 * math.pi * (turns - 1)


def arc_points(c: np.ndarray, n: np.ndarray, start: np.ndarray, end: np.ndarray, sweep: float, direction: str,
               chordal_tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Points after ``start`` up to ``end`` (exactly) and their fraction t in (0, 1] of the sweep.

    Segments span at most 90 degrees and deviate from the arc by at most ``chordal_tolerance``
    (sagitta r (1 - cos(dphi / 2))). Raises ValueError when that needs more than
    :data:`MAX_ARC_POINTS` points.
    """
    v0, r0, h0 = _frame(c, n, start)
    _, r1, h1 = _frame(c, n, end)
    rr = max(r0, r1)
    dmax = 2.0 * math.acos(1.0 - chordal_tolerance / rr) if chordal_tolerance < rr else math.pi / 2
    dmax = min(dmax, math.pi / 2)
    k = max(2, math.ceil(sweep / dmax - 1e-9))
    if k > MAX_ARC_POINTS:
        raise ValueError(f"arc needs {k} points at the chordal tolerance (more than {MAX_ARC_POINTS})")
    t = np.arange(1, k + 1, dtype=float) / k
    phi = t * sweep * (1.0 if direction == "ccw" else -1.0)
    u = v0 / r0
    w = np.cross(n, u)
    radius = (r0 + t * (r1 - r0))[:, None]
    height = (h0 + t * (h1 - h0))[:, None]
    points = c + radius * (np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * w) + height * n
    points[-1] = end
    return points, t


def tangent_votes(before: np.ndarray, start: np.ndarray, end: np.ndarray, after: np.ndarray, c: np.ndarray,
                  n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per arc, how many of its two neighbouring moves are tangent to it read ccw and read cw.

    Arrays of shape (A, 3): the point before the arc's start (NaN where there is none), start,
    end, the point after the end (NaN where none), centre and unit axis. The move into the start
    is compared with the counter-clockwise tangent n x (start - c) there, the move out of the end
    with n x (end - c); a move within ~25 degrees of that tangent votes ccw, within ~25 degrees of
    its opposite votes cw. Returns (ccw_votes, cw_votes), each 0..2 per arc.
    """

    def cosines(move: np.ndarray, at: np.ndarray) -> np.ndarray:
        tangent = np.cross(n, at - c)
        norms = np.linalg.norm(move, axis=1) * np.linalg.norm(tangent, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            cos = np.einsum("ij,ij->i", move, tangent) / norms
        return np.where(norms > 1e-12, cos, np.nan)

    cos_in = cosines(start - before, start)
    cos_out = cosines(after - end, end)
    ccw = (np.nan_to_num(cos_in) > _COS_TANGENT).astype(int) + (np.nan_to_num(cos_out) > _COS_TANGENT)
    cw = (np.nan_to_num(cos_in) < -_COS_TANGENT).astype(int) + (np.nan_to_num(cos_out) < -_COS_TANGENT)
    return ccw, cw
