"""NX CLSF splines (``NURBS/``, ``KNOT/``, ``CNTRL/``) as polylines within a chordal tolerance.

Pure functions: numpy and scipy only, no reader state. Every coordinate is in the CL file's
own units and frame (the CL/MCS frame of the surrounding ``GOTO`` records); the reader scales
and transforms the result like any other motion point.

What NX writes
--------------
::

    NURBS/
    KNOT/0.0416667,0.3750000,0.6250000,0.9583333,1.0000000
    CNTRL/-254.9774,466.2698,206.9401
    ... (7 CNTRL records in all)
    GOTO/...

In a real NX file (70 splines, /work/shared/CL-DIALECTS.md) every spline has exactly
``n - 2`` knot values for ``n`` ``CNTRL`` records, the first knot is never 0 and the last is
always 1. No Siemens document describing these three records was found (searches of the
documentation, web-page, issue and code corpora for the record names and NX's post-processor
variables found none), so the reading below rests on NX's own post-processor code and on the
counts:

* NX's post-processor (the MOM layer that turns the same tool path into G-code) hands a spline
  to the post as ``mom_nurbs_order``, ``mom_nurbs_knots`` (a full, clamped knot vector,
  ``knot_count = point_count + order``) and ``mom_nurbs_points``, and point 0 is where the
  tool already is: the Sinumerik 840D post suppresses it when a spline follows a spline
  ("suppress first contrl point") and moves there with ``G1`` otherwise, and the Fanuc 30i post
  moves there with an ``anchor_point`` block (``G1 X[mom_nurbs_points(0,0)]...``) before
  ``G06.2``. Sources: github.com/Unigraphics/PostBuilder (branch PB1980s),
  POSTBUILD/pblib/controller/mill/SIEMENS/Sinumerik_840D/sinumerik_840D.tcl
  (``PB_CMD_nurbs_spline``) and .def (``nurbs_bspline``, ``nurbs_bspline_start``),
  POSTBUILD/pblib/controller/mill/FANUC/Fanuc_30i/fanuc_30i.def (``anchor_point``, ``nurbs``),
  POSTBUILD/app/mom_vars_csv.txt (``mom_nurbs_order``: "Defines the order of the nurbs.
  Output as Pn").
* The controllers NX targets default to cubics: Fanuc ``G06.2`` rank 4 unless ``P`` is given,
  and "If a control point command is omitted in the first block, the current position ... is
  the first control point" (Fanuc Series 15i/150i-MA operator's manual, NURBS interpolation,
  cncmanuals.com pages 143-144, 158); NX's polynomial spline outputs for Heidenhain and
  Sinumerik carry cubic coefficients (``mom_nurbs_coefficients``: k3, k2, k1 per axis).
* A clamped B-spline of degree p on N control points has N - p spans. The ``KNOT`` list is one
  value per span (the parameter where each span ends, the last being 1) if the curve is a
  **cubic whose first control point is the tool's current position and whose other control
  points are the CNTRL records** (N = n + 1, n + 1 - 3 = n - 2 spans). The other reading that
  fits the count, a quadratic whose first CNTRL record is the curve start (N = n), would make
  NX write the current position again as a control point, which no GOTO-style CL record does.

So by default (``degree=3``) the full knot vector is ``[0, 0, 0, 0, k_1 ... k_{n-3}, 1, 1, 1,
1]`` (the listed knots after the four implied zeros, three more ones appended) and the control
polygon is ``[start, CNTRL_1 ... CNTRL_n]``: the curve starts exactly at the tool's position and
ends exactly at the last CNTRL point. ``degree=2`` gives the other reading (knot vector
``[0, 0, 0, k_1 ... 1, 1, 1]``, control polygon ``[CNTRL_1 ... CNTRL_n]``) and then checks that
CNTRL_1 is where the tool is. How to decide on a real file: measure ``|CNTRL_1 - previous
position|`` over its splines; if it is zero for every spline, the quadratic reading is the one
NX means; if it is generally not zero, only the cubic reading keeps the path continuous.

NX's MOM order is not always 4 (the same Sinumerik post turns order-2 splines into linear
moves), but the CLSF records carry no order, so the count fixes it; a file whose counts differ
from ``n - 2`` is refused rather than guessed at. No ``NURBS/`` arguments (order, knot count)
and no weights were seen in real files. ``weights``
is accepted for a ``CNTRL/x,y,z,w`` form should one appear (the start point then has weight 1);
the reader decides whether to pass it.

Sampling: for a polynomial curve, the distance between a curve piece over a parameter interval
of length h and its chord is at most h^2/8 * max|C''| on that interval (the linear-interpolation
error bound, valid for vector functions). Each knot span is cut into equal parameter steps so
that this bound, with max|C''| bounded by the largest second-derivative control point of the
span (convex-hull property), is within the chordal tolerance. For rational curves (weights) the
bound on |C''| is estimated by sampling each span densely with a 1.25 safety factor, since the
convex-hull bound does not apply to the quotient.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import BSpline

__all__ = ["MAX_POINTS", "NurbsCurve", "nurbs_points", "nx_nurbs_curve", "sample_nurbs"]

MAX_POINTS = 1_000_000  # a spline needing more points than this at the tolerance is refused
_RATIONAL_SAMPLES = 16  # per span, to estimate max|C''| of a rational curve
_RATIONAL_MARGIN = 1.25  # safety factor on that estimate
_KNOT_TOL = 1e-6  # NX prints knots with 7 decimals; the last one is 1.0000000


@dataclass(frozen=True)
class NurbsCurve:
    """A clamped NURBS curve: degree, full knot vector, control points (N, 3), weights (N,) or None.

    Coordinates are in the caller's units and frame. The curve runs from ``control[0]`` (at
    ``knots[0]``) to ``control[-1]`` (at ``knots[-1]``).
    """

    degree: int
    knots: np.ndarray
    control: np.ndarray
    weights: np.ndarray | None = None


def _check_curve(curve: NurbsCurve) -> None:
    """Raise ValueError (one line) unless ``curve`` is a valid clamped NURBS curve."""
    p, t, c = curve.degree, curve.knots, curve.control
    n = len(c)
    if p < 1:
        raise ValueError(f"spline degree must be at least 1, got {p}")
    if c.ndim != 2 or c.shape[1] != 3 or n < p + 1:
        raise ValueError(f"a degree-{p} spline needs at least {p + 1} control points (x,y,z), got {n}")
    if t.ndim != 1 or len(t) != n + p + 1:
        raise ValueError(f"a degree-{p} spline with {n} control points needs {n + p + 1} knots, got {len(t)}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(c))):
        raise ValueError("spline knots and control points must be finite numbers")
    if np.any(np.diff(t) < 0):
        raise ValueError("spline knots must not decrease")
    if t[p] >= t[n]:
        raise ValueError("spline knots span an empty parameter range")
    if np.any(t[: p + 1] != t[0]) or np.any(t[n:] != t[-1]):
        raise ValueError("spline knot vector must be clamped (end knots repeated degree + 1 times)")
    interior = t[p + 1 : n]
    if len(interior):
        _, counts = np.unique(interior, return_counts=True)
        if counts.max() > p:
            raise ValueError(f"a spline knot repeats {counts.max()} times; a degree-{p} spline allows {p}")
    if curve.weights is not None:
        w = curve.weights
        if w.shape != (n,):
            raise ValueError(f"spline has {len(w)} weights for {n} control points")
        if not np.all(np.isfinite(w)) or np.any(w <= 0):
            raise ValueError("spline weights must be positive finite numbers")


def nx_nurbs_curve(
    start: np.ndarray,
    knots: Sequence[float],
    control: np.ndarray,
    weights: np.ndarray | None = None,
    *,
    degree: int = 3,
    start_tolerance: float = 0.0,
) -> NurbsCurve:
    """Build the curve an NX ``NURBS/`` record means (see the module docstring for the reading).

    ``start`` (3,) is the tool's position before the record, ``knots`` every value of the
    ``KNOT/`` records in order, ``control`` (n, 3) the ``CNTRL/`` points, ``weights`` (n,) or
    None; all in CL file units and frame. ``degree=3`` (default): the curve starts at ``start``
    (the first control point) by construction. ``degree=2``: the curve starts at ``control[0]``,
    which must lie within ``start_tolerance`` of ``start``.
    Raises ValueError with a one-line reason for anything else, e.g.
    "NURBS has 4 knots for 7 control points: expected 5".
    """
    if degree not in (2, 3):
        raise ValueError(f"NX NURBS reading is defined for degree 2 or 3, got {degree}")
    start = np.asarray(start, dtype=float).reshape(-1)
    control = np.asarray(control, dtype=float)
    k = np.asarray(knots, dtype=float).reshape(-1)
    if start.shape != (3,) or not np.all(np.isfinite(start)):
        raise ValueError("NURBS start point must be 3 finite numbers")
    if control.ndim != 2 or control.shape[1] != 3:
        raise ValueError("NURBS control points must be x,y,z")
    n = len(control)
    if n < 3:
        raise ValueError(f"NURBS needs at least 3 control points, got {n}")
    if len(k) != n - 2:
        raise ValueError(f"NURBS has {len(k)} knots for {n} control points: expected {n - 2}")
    if not np.all(np.isfinite(k)):
        raise ValueError("NURBS knots must be finite numbers")
    if abs(k[-1] - 1.0) > _KNOT_TOL:
        raise ValueError(f"NURBS last knot must be 1, got {k[-1]:g}")
    if k[0] <= 0.0:
        raise ValueError(f"NURBS first knot must be after the implied 0, got {k[0]:g}")
    if len(k) > 1 and k[-2] >= 1.0:
        raise ValueError(f"NURBS knots before the last must be below 1, got {k[-2]:g}")
    w = None if weights is None else np.asarray(weights, dtype=float).reshape(-1)
    if w is not None and len(w) != n:
        raise ValueError(f"NURBS has {len(w)} weights for {n} control points")
    interior = k[:-1]
    if degree == 3:
        full_knots = np.concatenate([np.zeros(4), interior, np.ones(4)])
        full_control = np.vstack([start, control])
        full_weights = None if w is None else np.concatenate([[1.0], w])
    else:
        gap = float(np.linalg.norm(control[0] - start))
        if gap > start_tolerance:
            raise ValueError(f"NURBS first control point is {gap:g} away from the tool position")
        full_knots = np.concatenate([np.zeros(3), interior, np.ones(3)])
        full_control = control
        full_weights = w
    curve = NurbsCurve(degree, full_knots, full_control, full_weights)
    _check_curve(curve)
    return curve


def _second_derivative_bound(spl: BSpline, curve: NurbsCurve, span: np.ndarray) -> np.ndarray:
    """Upper bound (polynomial) or estimate (rational) of max|C''| on each knot span index."""
    p, t = curve.degree, curve.knots
    if curve.weights is None:
        if p < 2:
            return np.zeros(len(span))
        # C'' is a degree p-2 B-spline; on span j its value is a convex combination of its
        # control points j-p .. j-2, so their largest norm bounds |C''| there.
        r = np.linalg.norm(spl.derivative(2).c, axis=1)
        return r[span[:, None] - p + np.arange(p - 1)[None, :]].max(axis=1)
    s = np.linspace(0.0, 1.0, _RATIONAL_SAMPLES + 1)
    u = (t[span, None] + (t[span + 1] - t[span])[:, None] * s[None, :]).ravel()
    a0, a1, a2 = spl(u), spl(u, nu=1), spl(u, nu=2)
    w0, w1, w2 = a0[:, 3:], a1[:, 3:], a2[:, 3:]
    c0 = a0[:, :3] / w0
    c1 = (a1[:, :3] - w1 * c0) / w0
    c2 = (a2[:, :3] - 2.0 * w1 * c1 - w2 * c0) / w0
    return _RATIONAL_MARGIN * np.linalg.norm(c2, axis=1).reshape(len(span), -1).max(axis=1)


def sample_nurbs(curve: NurbsCurve, chordal_tolerance: float, max_points: int = MAX_POINTS) -> np.ndarray:
    """Points (m, 3) of ``curve`` after its start up to and including its end, so that every
    chord between consecutive points (the first chord starting at ``control[0]``) stays within
    ``chordal_tolerance`` of the curve. Units and frame are those of ``curve.control``.

    Raises ValueError for an invalid curve, a non-positive tolerance, or when more than
    ``max_points`` points would be needed ("spline needs more than N points at tolerance t").
    """
    tol = float(chordal_tolerance)
    if not (np.isfinite(tol) and tol > 0.0):
        raise ValueError(f"chordal tolerance must be a positive number, got {chordal_tolerance!r}")
    _check_curve(curve)
    p, t = curve.degree, curve.knots
    n = len(curve.control)
    if curve.weights is None:
        coeffs = curve.control
    else:
        w = curve.weights[:, None]
        coeffs = np.hstack([curve.control * w, w])
    spl = BSpline(t, coeffs, p)
    span = np.arange(p, n)
    span = span[t[span + 1] > t[span]]
    h = t[span + 1] - t[span]
    with np.errstate(over="ignore", invalid="ignore"):
        steps = np.ceil(h * np.sqrt(_second_derivative_bound(spl, curve, span) / (8.0 * tol)))
    steps = np.maximum(steps, 1.0)
    if not np.all(np.isfinite(steps)) or steps.sum() > max_points:
        raise ValueError(f"spline needs more than {max_points} points at tolerance {tol:g}")
    steps = steps.astype(np.int64)
    total = int(steps.sum())
    # Parameters a + h * i / s for i = 1..s on every span, in span order.
    first = np.cumsum(steps) - steps
    i = np.arange(1, total + 1) - np.repeat(first, steps)
    u = np.repeat(t[span], steps) + np.repeat(h, steps) * i / np.repeat(steps, steps)
    u = np.clip(u, t[p], t[n])
    values = spl(u)
    points = values if curve.weights is None else values[:, :3] / values[:, 3:]
    points[-1] = curve.control[-1]  # clamped end: exactly the last control point
    return points


def nurbs_points(
    start: np.ndarray,
    knots: Sequence[float],
    control: np.ndarray,
    weights: np.ndarray | None,
    chordal_tolerance: float,
    *,
    degree: int = 3,
    max_points: int = MAX_POINTS,
) -> np.ndarray:
    """Polyline (m, 3) of an NX ``NURBS/`` spline, in CL file units and frame.

    ``start`` (3,) is the tool position before the ``NURBS/`` record, ``knots`` the ``KNOT/``
    values in order, ``control`` (n, 3) the ``CNTRL/`` points, ``weights`` (n,) or None. The
    result holds the points after ``start`` up to and including the curve's end (the last
    ``CNTRL`` point), spaced so that each chord, the first one from ``start``, deviates at most
    ``chordal_tolerance`` from the curve.

    With the default ``degree=3`` the curve starts at ``start`` by construction (it is the first
    control point), so nothing is checked there; ``degree=2`` selects the other reading of the
    knot count and requires the first CNTRL point within ``chordal_tolerance`` of ``start``.
    Tool axes are not interpolated here: the reader keeps the current axis.
    Raises ValueError with a one-line reason (bad counts, bad knots, too many points).
    """
    curve = nx_nurbs_curve(start, knots, control, weights, degree=degree, start_tolerance=chordal_tolerance)
    return sample_nurbs(curve, chordal_tolerance, max_points)
