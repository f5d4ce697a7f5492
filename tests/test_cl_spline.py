"""NX CLSF splines (verne_post.cl.spline) against an independent Cox-de Boor evaluator.

The reference curve is evaluated here with the Cox-de Boor recursion written out (no scipy),
from the knot vector and control polygon that the reading in the module docstring defines.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy.spatial import cKDTree

from verne_post.cl.spline import MAX_POINTS, NurbsCurve, nurbs_points, nx_nurbs_curve, sample_nurbs


def basis(knots: np.ndarray, degree: int, u: np.ndarray) -> np.ndarray:
    """B-spline basis values (len(u), len(knots) - degree - 1) by the Cox-de Boor recursion."""
    t = np.asarray(knots, dtype=float)
    b = ((t[:-1] <= u[:, None]) & (u[:, None] < t[1:])).astype(float)
    last = max(i for i in range(len(t) - 1) if t[i] < t[i + 1])
    b[u >= t[-1], last] = 1.0  # the closed right end belongs to the last non-empty interval
    for k in range(1, degree + 1):
        nxt = np.zeros((len(u), len(t) - 1 - k))
        for i in range(len(t) - 1 - k):
            if t[i + k] > t[i]:
                nxt[:, i] += (u - t[i]) / (t[i + k] - t[i]) * b[:, i]
            if t[i + k + 1] > t[i + 1]:
                nxt[:, i] += (t[i + k + 1] - u) / (t[i + k + 1] - t[i + 1]) * b[:, i + 1]
        b = nxt
    return b


def curve_at(knots, degree, control, weights, u):
    b = basis(np.asarray(knots, float), degree, np.asarray(u, float))
    if weights is None:
        return b @ control
    bw = b * weights
    return (bw @ control) / bw.sum(axis=1, keepdims=True)


def dense(knots, degree, control, weights, n=200_001):
    u = np.linspace(knots[0], knots[-1], n)
    return curve_at(knots, degree, control, weights, u)


def distance_to_polyline(points: np.ndarray, poly: np.ndarray, near: int = 6) -> np.ndarray:
    """Upper bound of each point's distance to the polyline: the segments around the point's
    nearest vertices (a subset of all segments, so the true distance is never larger)."""
    _, idx = cKDTree(poly).query(points, k=min(near, len(poly)))
    idx = np.atleast_2d(idx.T).T
    best = np.full(len(points), np.inf)
    for col in range(idx.shape[1]):
        for off in (-1, 0):
            i0 = np.clip(idx[:, col] + off, 0, len(poly) - 2)
            a, b = poly[i0], poly[i0 + 1]
            ab = b - a
            s = np.clip(np.einsum("ij,ij->i", points - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300), 0, 1)
            best = np.minimum(best, np.linalg.norm(points - (a + s[:, None] * ab), axis=1))
    return best


def assert_within_tolerance(poly: np.ndarray, true: np.ndarray, tol: float) -> None:
    """Both ways: every true-curve point near the polyline, every chord point near the curve."""
    spacing = np.linalg.norm(np.diff(true, axis=0), axis=1).max()
    assert distance_to_polyline(true, poly).max() <= tol * (1 + 1e-9) + 1e-12
    chords = np.concatenate([poly[:-1] + f * (poly[1:] - poly[:-1]) for f in (0.25, 0.5, 0.75)])
    d, _ = cKDTree(true).query(chords)
    assert d.max() <= tol + spacing / 2


def raises(message: str):
    return pytest.raises(ValueError, match=f"^{re.escape(message)}$")


def random_nx_spline(rng: np.random.Generator, n: int) -> tuple[np.ndarray, list[float], np.ndarray]:
    start = rng.uniform(-300, 300, 3)
    control = start + np.cumsum(rng.normal(0, 25, (n, 3)), axis=0)
    interior = np.sort(rng.uniform(0.02, 0.98, n - 3))
    return start, [*interior.tolist(), 1.0], control


@pytest.mark.parametrize("seed", range(12))
def test_cubic_reading_chordal_bound_and_ends(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 13))
    start, knots, control = random_nx_spline(rng, n)
    tol = float(10 ** rng.uniform(-2.5, -0.5))
    pts = nurbs_points(start, knots, control, None, tol)

    # The reading: cubic, clamped, current position first, CNTRL after it.
    full_knots = [0.0] * 4 + knots[:-1] + [1.0] * 4
    polygon = np.vstack([start, control])
    true = dense(full_knots, 3, polygon, None)
    np.testing.assert_allclose(true[0], start, atol=1e-9)  # the curve leaves from the tool position
    assert np.array_equal(pts[-1], control[-1])  # and ends exactly at the last CNTRL point
    assert not np.allclose(pts[0], start)  # the start itself is not repeated
    assert_within_tolerance(np.vstack([start, pts]), true, tol)


def test_nx_sample_from_the_dialect_notes() -> None:
    # Knots of a real NX spline (CL-DIALECTS.md); first and last control point as printed there,
    # the others made up. 7 CNTRL records, 5 knots.
    knots = [0.0416667, 0.3750000, 0.6250000, 0.9583333, 1.0000000]
    control = np.array(
        [
            [-254.9774, 466.2698, 206.9401],
            [-250.0, 470.0, 206.9401],
            [-240.0, 475.0, 206.0],
            [-230.0, 474.0, 205.0],
            [-220.0, 470.0, 205.0],
            [-215.0, 466.0, 205.0],
            [-214.0, 465.0, 205.0],
        ]
    )
    start = np.array([-255.5, 466.0, 207.0])
    pts = nurbs_points(start, knots, control, None, 0.01)
    true = dense([0.0] * 4 + knots[:-1] + [1.0] * 4, 3, np.vstack([start, control]), None)
    assert_within_tolerance(np.vstack([start, pts]), true, 0.01)


@pytest.mark.parametrize("seed", range(4))
def test_quadratic_reading(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(3, 10))
    start, knots, control = random_nx_spline(rng, n)
    control[0] = start
    tol = 0.02
    pts = nurbs_points(start, knots, control, None, tol, degree=2)
    true = dense([0.0] * 3 + knots[:-1] + [1.0] * 3, 2, control, None)
    assert np.array_equal(pts[-1], control[-1])
    assert_within_tolerance(np.vstack([start, pts]), true, tol)
    control[0] += [0.0, 0.5, 0.0]
    with raises("NURBS first control point is 0.5 away from the tool position"):
        nurbs_points(start, knots, control, None, tol, degree=2)


@pytest.mark.parametrize("seed", range(4))
def test_rational_cubic_reading(seed: int) -> None:
    rng = np.random.default_rng(200 + seed)
    start, knots, control = random_nx_spline(rng, 8)
    weights = rng.uniform(0.3, 3.0, 8)
    tol = 0.01
    pts = nurbs_points(start, knots, control, weights, tol)
    true = dense([0.0] * 4 + knots[:-1] + [1.0] * 4, 3, np.vstack([start, control]), np.r_[1.0, weights])
    np.testing.assert_allclose(pts[-1], control[-1])
    assert_within_tolerance(np.vstack([start, pts]), true, tol)


def test_exact_circle_from_rational_quadratics() -> None:
    # The standard 9-point rational quadratic circle: every curve point is at radius R.
    r, tol = 40.0, 0.005
    s = math.sqrt(0.5)
    ring = np.array([[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1], [1, -1], [1, 0]], float)
    control = np.c_[r * ring, np.full(9, 7.0)]
    weights = np.array([1, s, 1, s, 1, s, 1, s, 1])
    knots = np.array([0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1])
    pts = sample_nurbs(NurbsCurve(2, knots, control, weights), tol)
    poly = np.vstack([control[0], pts])
    np.testing.assert_allclose(np.linalg.norm(poly[:, :2], axis=1), r, rtol=1e-12)
    theta = np.unwrap(np.arctan2(poly[:, 1], poly[:, 0]))
    step = np.diff(theta)
    assert np.all(step > 0) and theta[-1] - theta[0] == pytest.approx(2 * math.pi)
    assert (r * (1 - np.cos(step / 2))).max() <= tol  # sagitta of every chord
    fewest = math.ceil(2 * math.pi / (2 * math.acos(1 - tol / r)))
    assert len(pts) <= 3 * fewest  # bounded, not wasteful


def test_degree_one_is_its_control_polygon() -> None:
    control = np.array([[0, 0, 0], [1, 2, 3], [4, 4, 4], [5, 0, -1]], float)
    knots = np.array([0, 0, 0.3, 0.5, 1, 1])
    pts = sample_nurbs(NurbsCurve(1, knots, control), 1e-6)
    np.testing.assert_allclose(pts, control[1:], atol=1e-12)


def test_straight_spline_stays_on_its_line() -> None:
    start = np.zeros(3)
    control = np.outer(np.arange(1, 6), [1.0, 2.0, -1.0])  # collinear control polygon
    pts = nurbs_points(start, [0.3, 0.6, 1.0], control, None, 1e-3)
    line = control[-1] / np.linalg.norm(control[-1])
    assert np.allclose(np.cross(pts, line), 0.0, atol=1e-9)
    assert np.all(np.diff(pts @ line) > 0)  # moves forward only
    assert np.array_equal(pts[-1], control[-1])


@pytest.mark.parametrize(
    ("knots", "n", "message"),
    [
        ([0.3, 0.6, 1.0], 7, "NURBS has 3 knots for 7 control points: expected 5"),
        ([0.1, 0.2, 0.3, 0.6, 0.8, 1.0], 7, "NURBS has 6 knots for 7 control points: expected 5"),
        ([], 2, "NURBS needs at least 3 control points, got 2"),
        ([0.0, 0.3, 0.5, 0.8, 1.0], 7, "NURBS first knot must be after the implied 0, got 0"),
        ([0.1, 0.3, 0.5, 0.8, 0.9], 7, "NURBS last knot must be 1, got 0.9"),
        ([0.1, 0.3, 0.5, 1.0, 1.0], 7, "NURBS knots before the last must be below 1, got 1"),
        ([0.1, 0.5, 0.3, 0.8, 1.0], 7, "spline knots must not decrease"),
        ([0.5, 0.5, 0.5, 0.5, 1.0], 7, "a spline knot repeats 4 times; a degree-3 spline allows 3"),
        ([0.1, float("nan"), 0.5, 0.8, 1.0], 7, "NURBS knots must be finite numbers"),
    ],
)
def test_rejects_inconsistent_records(knots: list[float], n: int, message: str) -> None:
    control = np.arange(3.0 * n).reshape(n, 3)
    with raises(message):
        nurbs_points(np.zeros(3), knots, control, None, 0.01)


def test_rejects_bad_weights_tolerance_and_points() -> None:
    control = np.arange(21.0).reshape(7, 3)
    knots = [0.1, 0.3, 0.5, 0.8, 1.0]
    with raises("NURBS has 6 weights for 7 control points"):
        nurbs_points(np.zeros(3), knots, control, np.ones(6), 0.01)
    with raises("spline weights must be positive finite numbers"):
        nurbs_points(np.zeros(3), knots, control, np.r_[np.ones(6), -1.0], 0.01)
    with raises("chordal tolerance must be a positive number, got 0.0"):
        nurbs_points(np.zeros(3), knots, control, None, 0.0)
    bad = control.copy()
    bad[2, 1] = np.inf
    with raises("spline knots and control points must be finite numbers"):
        nurbs_points(np.zeros(3), knots, bad, None, 0.01)


def test_absurd_size_is_refused_not_allocated() -> None:
    rng = np.random.default_rng(7)
    control = rng.normal(0, 1e6, (7, 3))
    with raises(f"spline needs more than {MAX_POINTS} points at tolerance 1e-09"):
        nurbs_points(np.zeros(3), [0.1, 0.3, 0.5, 0.8, 1.0], control, None, 1e-9)
    with raises("spline needs more than 10 points at tolerance 0.001"):
        nurbs_points(np.zeros(3), [0.1, 0.3, 0.5, 0.8, 1.0], control / 1e4, None, 1e-3, max_points=10)


def test_curve_object_is_the_documented_reading() -> None:
    start = np.array([1.0, 2.0, 3.0])
    control = np.arange(15.0).reshape(5, 3)
    curve = nx_nurbs_curve(start, [0.25, 0.5, 1.0], control)
    assert curve.degree == 3
    np.testing.assert_array_equal(curve.knots, [0, 0, 0, 0, 0.25, 0.5, 1, 1, 1, 1])
    np.testing.assert_array_equal(curve.control, np.vstack([start, control]))
