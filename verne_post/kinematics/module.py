"""Parallel module of the VERNE (paper section 3): platform pose <-> slider positions.

Frames and units: base frame R_b of the paper, z pointing DOWN, lengths in mm. The platform
pose is ``Trans(xP, yP, zP) Rot(x, alpha)``: ``platform`` arrays are (N, 3) = (xP, yP, zP) in
mm, ``alpha`` in radians, slider positions ``rho`` (N, 3) = (rho1, rho2, rho3) in mm.

Slider positions in and out of the public IK/FK functions are the controller's *readings*;
the true position is the reading plus the geometry's ``rho_offset`` (zero by default). The
closure and mode helpers (``closure_residuals``, ``closure_ok``, ``is_working_mode``,
``configuration_signs``) and the private functions work on true positions.

The machine's *working mode* (paper, Fig. 5 (m)): every slider point above its platform
points (s_i = -1, z down) and no rod crossing in leg I (R1 cos(alpha) > r1).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from . import kernels
from .geometry import Geometry
from .rows import all_of, finite_rows
from .tolerances import CLOSURE_TOL
from .trigpoly import TrigPoly, real_half_angle_roots


def closure_residuals(geom: Geometry, platform: np.ndarray, alpha: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """Residuals (N, 4) of eq. 3a, 3b, 4, 5 (mm^2) for platform (N,3) mm, alpha (N,) rad, rho (N,3) mm."""
    return np.stack(_closure_terms(geom, platform, alpha, rho), axis=-1)


def _closure_terms(geom: Geometry, platform: np.ndarray, alpha: np.ndarray, rho: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`closure_residuals`' four columns (N,) each (mm^2)."""
    x, y, z = np.moveaxis(np.asarray(platform, dtype=float), -1, 0)
    c, s = np.cos(alpha), np.sin(alpha)
    r1_, r2_, r3_ = np.moveaxis(np.asarray(rho, dtype=float), -1, 0)
    g = geom
    x1, x2 = x + g.D1_minus_d1, x + g.D2_minus_d2
    return (x1**2 + (y + g.R1 * c - g.r1) ** 2 + (z + g.R1 * s - r1_) ** 2 - g.L1**2,
            x1**2 + (y - g.R1 * c + g.r1) ** 2 + (z - g.R1 * s - r1_) ** 2 - g.L1**2,
            x2**2 + (y - g.R2 * c + g.r4) ** 2 + (z - g.R2 * s - r2_) ** 2 - g.L2**2,
            x2**2 + (y + g.R2 * c - g.r4) ** 2 + (z + g.R2 * s - r3_) ** 2 - g.L3**2)


def closure_ok(geom: Geometry, platform: np.ndarray, alpha: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """True where all four closure equations hold to ``CLOSURE_TOL`` relative to L^2."""
    ok = None
    for residual, scale in zip(_closure_terms(geom, platform, alpha, rho),
                               (geom.L1**2, geom.L1**2, geom.L2**2, geom.L3**2), strict=True):
        holds = np.abs(residual) <= CLOSURE_TOL * scale
        ok = holds if ok is None else ok & holds
    return ok


def _slider_heights(geom: Geometry, platform: np.ndarray, alpha: np.ndarray, rho: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per leg (N,) each: rho_i minus the height of its platform point (mm), whose signs are s_i."""
    z = np.asarray(platform, dtype=float)[..., 2]
    s = geom.R2 * np.sin(alpha)
    rho = np.asarray(rho, dtype=float)
    return rho[..., 0] - z, rho[..., 1] - z + s, rho[..., 2] - z - s


def configuration_signs(geom: Geometry, platform: np.ndarray, alpha: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """Configuration indices s_i (N, 3) of eq. 10-12: signs of rho_i minus the platform point height."""
    return np.sign(np.stack(_slider_heights(geom, platform, alpha, rho), axis=-1))


def is_working_mode(geom: Geometry, platform: np.ndarray, alpha: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """The machine's mode: s_i = -1 for every leg and R1 cos(alpha) > r1 (no rod crossing)."""
    first, second, third = _slider_heights(geom, platform, alpha, rho)  # each below 0 as its sign is; NaN neither
    return (first < 0) & (second < 0) & (third < 0) & (geom.R1 * np.cos(alpha) > geom.r1)


# --------------------------------------------------------------------------- coupling (eq. 6-8)


def coupling_cubic(geom: Geometry, platform: np.ndarray) -> np.ndarray:
    """Coefficients (N, 4) = (p1, p2, p3, p4) of eq. 8 in cos(alpha), for platform (N, 3) mm."""
    platform = np.asarray(platform, dtype=float)
    x1 = platform[..., 0] + geom.D1_minus_d1
    y = platform[..., 1]
    R1, r1 = geom.R1, geom.r1
    k = geom.L1**2 - R1**2 - r1**2
    p1 = np.full_like(y, 2 * R1**3 * r1)
    p2 = R1**2 * k - R1**2 * x1**2
    p3 = -2 * R1**3 * r1 - 2 * R1 * r1 * y**2
    p4 = R1**2 * x1**2 + (R1**2 + r1**2) * y**2 - R1**2 * k
    return np.stack([p1, p2, p3, p4], axis=-1)


def coupling_ellipse(geom: Geometry, alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Semi-axes (a, b) in mm of the ellipse (eq. 7) of platform positions with orientation alpha.

    The ellipse is centred on xP = -(D1 - d1), yP = 0; ``a`` along x, ``b`` along y.
    """
    c = np.cos(alpha)
    R1, r1 = geom.R1, geom.r1
    a2 = geom.L1**2 - (R1**2 + r1**2 - 2 * R1 * r1 * c)
    b2 = R1**2 * np.sin(alpha) ** 2 * a2 / (r1**2 - 2 * R1 * r1 * c + R1**2)
    return np.sqrt(a2), np.sqrt(b2)


def _cubic_about(geom: Geometry, x1: np.ndarray, y: np.ndarray, end: float) -> tuple[np.ndarray, ...]:
    """Eq. 8 rewritten in w = 1 - end*cos(alpha) (end = +1 or -1), w >= 0, accurate near w = 0.

    The constant term f(end) = yP^2 (R1 - end r1)^2 is formed directly, so the small root
    (alpha near 0 or pi) keeps full relative precision.
    """
    R1, r1 = geom.R1, geom.r1
    p1 = 2 * R1**3 * r1
    p2 = R1**2 * (geom.L1**2 - R1**2 - r1**2) - R1**2 * x1**2
    p3 = -2 * R1**3 * r1 - 2 * R1 * r1 * y**2
    # f(c) with c = end (1 - w): Taylor coefficients about c = end, in powers of w.
    q0 = y**2 * (R1 - end * r1) ** 2
    q1 = -end * (3 * p1 + 2 * end * p2 + p3)
    q2 = 3 * p1 * end + p2
    q3 = -end * p1
    return q0, q1, q2, q3


def _newton_cubic(q: tuple[np.ndarray, ...], w: np.ndarray, iterations: int) -> np.ndarray:
    q0, q1, q2, q3 = q
    for _ in range(iterations):
        f = ((q3 * w + q2) * w + q1) * w + q0
        fp = (3 * q3 * w + 2 * q2) * w + q1
        w = w - np.divide(f, fp, out=np.zeros_like(f), where=fp != 0)
    return w


def _alpha_from_w(w: np.ndarray, end: float) -> np.ndarray:
    """|alpha| from w = 1 - end*cos(alpha) without the loss of acos near 0 and pi."""
    half = 2.0 * np.arcsin(np.sqrt(np.clip(w, 0.0, 2.0) / 2.0))
    return half if end > 0 else np.pi - half


# --------------------------------------------------------------------------- inverse kinematics


def _slider_terms(geom: Geometry, platform: np.ndarray, c: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, ...]:
    """Slider-height offsets and radicands of eq. 10-12 for each leg."""
    x, y, z = np.moveaxis(platform, -1, 0)
    g = geom
    x1, x2 = x + g.D1_minus_d1, x + g.D2_minus_d2
    rad1 = g.L1**2 - (g.R1**2 + g.r1**2 - 2 * g.R1 * g.r1 * c) - x1**2 - y**2
    rad2 = g.L2**2 - x2**2 - (y - g.R2 * c + g.r4) ** 2
    rad3 = g.L3**2 - x2**2 - (y + g.R2 * c - g.r4) ** 2
    return z, z - g.R2 * s, z + g.R2 * s, rad1, rad2, rad3


def working_sliders(geom: Geometry, platform: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Eq. 10-12 with s_i = -1: slider positions (N, 3) mm; NaN where a leg cannot reach."""
    z1, z2, z3, rad1, rad2, rad3 = _slider_terms(geom, platform, np.cos(alpha), np.sin(alpha))
    with np.errstate(invalid="ignore"):
        return np.stack([z1 - np.sqrt(rad1), z2 - np.sqrt(rad2), z3 - np.sqrt(rad3)], axis=-1)


@dataclass(frozen=True)
class ModuleIK:
    """Working-mode IK of the parallel module for N platform positions (NaN where unreachable)."""

    rho: np.ndarray  # (N, 3) mm
    alpha: np.ndarray  # (N,) rad
    reachable: np.ndarray  # (N,) bool


def module_ik_working(geom: Geometry, platform: np.ndarray) -> ModuleIK:
    """Slider positions (mm) and tilt alpha (rad) of the working mode for platform (N, 3) mm, base frame.

    The working root of eq. 8 lies in r1/R1 < cos(alpha) <= 1 (eq. 8 is >= 0 at cos = +-1 and
    < 0 at cos = r1/R1 inside the workspace). At the fringe of leg I's reach (leg I nearly
    horizontal) that interval can hold three roots, two of them working; the one nearest
    alpha = 0 is returned. It is found by Newton's method in w = 1 - cos(alpha), started at
    the small root of the quadratic truncation, converging monotonically because the cubic
    is convex and decreasing there. The sign of alpha follows eq. 13 with s1 = -1.
    """
    platform = np.atleast_2d(np.asarray(platform, dtype=float))
    x1 = platform[:, 0] + geom.D1_minus_d1
    y = platform[:, 1]
    q = _cubic_about(geom, x1, y, 1.0)
    # Start at the small root of the quadratic truncation (stable form), then Newton.
    discriminant = np.maximum(q[1] ** 2 - 4.0 * q[2] * q[0], 0.0)
    w = _newton_cubic(q, 2.0 * q[0] / (np.sqrt(discriminant) - q[1]), 8)
    magnitude = _alpha_from_w(w, 1.0)
    alpha = np.where(y > 0, -magnitude, magnitude)
    rho = working_sliders(geom, platform, alpha)
    reachable = (w >= 0) & (geom.R1 * np.cos(alpha) > geom.r1) & finite_rows(rho) & np.isfinite(w)
    reachable &= closure_ok(geom, platform, alpha, np.where(reachable[:, None], rho, 0.0))
    rho = geom.readings(np.where(reachable[:, None], rho, np.nan))
    return ModuleIK(rho, np.where(reachable, alpha, np.nan), reachable)


@dataclass(frozen=True)
class ModuleIKSolutions:
    """All IK solutions of the module, flattened: solution k belongs to input pose ``pose_index[k]``."""

    pose_index: np.ndarray  # (K,) int
    alpha: np.ndarray  # (K,) rad
    rho: np.ndarray  # (K, 3) mm
    signs: np.ndarray  # (K, 3) configuration indices s_i (0 on a serial singularity)
    working_mode: np.ndarray  # (K,) bool


def _cubic_alphas(geom: Geometry, platform: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """All real alpha (rad) of eq. 8, as (pose index, alpha) pairs; +-acos(c) for each root c."""
    p = coupling_cubic(geom, platform)
    n = p.shape[0]
    companion = np.zeros((n, 3, 3))
    companion[:, 0, :] = -p[:, 1:] / p[:, :1]
    companion[:, 1, 0] = companion[:, 2, 1] = 1.0
    roots = np.linalg.eigvals(companion)
    real = np.abs(roots.imag) <= 1e-7
    index, which = np.nonzero(real)
    c = roots.real[index, which]
    keep = np.abs(c) <= 1.0 + 1e-7
    index, c = index[keep], c[keep]
    x1 = platform[index, 0] + geom.D1_minus_d1
    y = platform[index, 1]
    end = np.where(c >= 0, 1.0, -1.0)
    polished = np.empty_like(c)
    for e in (1.0, -1.0):
        m = end == e
        w = _newton_cubic(_cubic_about(geom, x1[m], y[m], e), np.clip(1.0 - e * c[m], 0.0, 2.0), 3)
        polished[m] = _alpha_from_w(w, e)
    alpha = np.concatenate([polished, -polished])
    index = np.concatenate([index, index])
    # alpha = 0 and alpha = pi appear twice (+-); keep one of each.
    distinct = np.ones(alpha.size, bool)
    distinct[polished.size :] = np.abs(np.sin(polished)) > 1e-12
    return index[distinct], alpha[distinct]


def solutions_for_alpha(
    geom: Geometry, platform: np.ndarray, alpha: np.ndarray, index: np.ndarray
) -> ModuleIKSolutions:
    """Every (rho1, rho2, rho3) of eq. 10-12 for given (platform, alpha) candidates.

    rho1 takes the sign of eq. 13 (both signs where sin(alpha) or yP(R1 cos - r1) vanish,
    Table II); rho2 and rho3 take both signs. Candidates violating the closure equations
    (e.g. alpha not a true root) are dropped.
    """
    c, s = np.cos(alpha), np.sin(alpha)
    z1, z2, z3, rad1, rad2, rad3 = _slider_terms(geom, platform, c, s)
    tol = CLOSURE_TOL * np.array([geom.L1**2, geom.L2**2, geom.L3**2])
    ok = (rad1 >= -tol[0]) & (rad2 >= -tol[1]) & (rad3 >= -tol[2])
    h1, h2, h3 = (np.sqrt(np.clip(r, 0.0, None)) for r in (rad1, rad2, rad3))
    signs = np.array([[a, b, d] for a in (-1, 1) for b in (-1, 1) for d in (-1, 1)], float)
    rows, combo = np.nonzero(ok[:, None] & np.ones((1, 8), bool))
    sg = signs[combo]
    rho = np.stack([z1[rows] + sg[:, 0] * h1[rows], z2[rows] + sg[:, 1] * h2[rows], z3[rows] + sg[:, 2] * h3[rows]], -1)
    keep = closure_ok(geom, platform[rows], alpha[rows], rho)
    # A zero radicand gives the same rho for both signs: keep the s = -1 copy, flag s = 0.
    for leg, h in enumerate((h1, h2, h3)):
        double = h[rows] <= np.sqrt(tol[leg])
        keep &= ~(double & (sg[:, leg] > 0))
        sg[double, leg] = 0.0
    rows, rho, sg = rows[keep], rho[keep], sg[keep]
    a = alpha[rows]
    working = all_of(sg < 0) & (geom.R1 * np.cos(a) > geom.r1)
    return ModuleIKSolutions(index[rows], a, rho, sg.astype(np.int8), working)


def module_ik_all(geom: Geometry, platform: np.ndarray) -> ModuleIKSolutions:
    """All IK solutions (up to 16 per position; more on yP = 0, Tables I-II) for platform (N, 3) mm."""
    platform = np.atleast_2d(np.asarray(platform, dtype=float))
    index, alpha = _cubic_alphas(geom, platform)
    solutions = solutions_for_alpha(geom, platform[index], alpha, index)
    order = np.lexsort((solutions.rho[:, 2], solutions.rho[:, 1], solutions.rho[:, 0], solutions.alpha,
                        solutions.pose_index))
    found = ModuleIKSolutions(*(getattr(solutions, f)[order] for f in ModuleIKSolutions.__dataclass_fields__))
    return found if not geom.has_offsets else replace(found, rho=geom.readings(found.rho))


# --------------------------------------------------------------------------- forward kinematics


def _fk_elimination(geom: Geometry, rho: np.ndarray, c, s):
    """Exact elimination of xP, yP, zP (own route, equivalent to eq. 14, 18, 21).

    yP, zP solve the linear pair (eq. 13) and (eq. 4 - eq. 5) by Cramer's rule with
    determinant ``det`` (twice the paper's eq. 23); xP follows from eq. 9 - eq. 4, linear in
    xP; eq. 4 is what remains. Returns (det, Ny, Nz, Mx, G) with yP = Ny/det, zP = Nz/det,
    xP = Mx / (2 (delta1 - delta2) det) and G = 0 the eliminant, a trigonometric polynomial
    of degree 6 in alpha (degree 12 in tan(alpha/2)).
    """
    g = geom
    rho1, rho2, rho3 = rho[:, 0], rho[:, 1], rho[:, 2]
    d1, d2 = g.D1_minus_d1, g.D2_minus_d2
    w = g.R2 * c - g.r4
    a11, a12, b1 = g.R1 * c - g.r1, g.R1 * s, g.R1 * s * rho1
    a21 = -4.0 * w
    a22 = 2.0 * (rho3 - rho2) - 4.0 * g.R2 * s
    b2 = (g.L2**2 - g.L3**2) + (rho2 + rho3) * (rho3 - rho2) - 2.0 * g.R2 * s * (rho2 + rho3)
    det = a11 * a22 - a12 * a21
    ny = b1 * a22 - a12 * b2
    nz = a11 * b2 - a21 * b1
    a_sq = g.L1**2 - g.R1**2 - g.r1**2 + 2.0 * g.R1 * g.r1 * c
    slider2 = g.R2 * s + rho2
    mx = ((a_sq - g.L2**2 - d1**2 + d2**2) * det + w * (w * det - 2.0 * ny)
          + (rho1 - slider2) * (2.0 * nz - (rho1 + slider2) * det))
    k = 2.0 * (d1 - d2)
    eliminant = (mx + k * d2 * det) ** 2 + k**2 * ((ny - w * det) ** 2 + (nz - slider2 * det) ** 2
                                                  - g.L2**2 * det**2)
    return det, ny, nz, mx, eliminant


@dataclass(frozen=True)
class ModuleFKSolutions:
    """All FK solutions (assembly modes) of the module, flattened by ``pose_index``."""

    pose_index: np.ndarray  # (K,) int
    platform: np.ndarray  # (K, 3) mm, base frame
    alpha: np.ndarray  # (K,) rad
    working_mode: np.ndarray  # (K,) bool


def _platform_from_alpha(geom: Geometry, rho: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    det, ny, nz, mx, _ = _fk_elimination(geom, rho, np.cos(alpha), np.sin(alpha))
    k = 2.0 * (geom.D1_minus_d1 - geom.D2_minus_d2)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.stack([mx / (k * det), ny / det, nz / det], axis=-1)


def _polish_alpha(geom: Geometry, rho: np.ndarray, alpha: np.ndarray, iterations: int = 3) -> np.ndarray:
    """Newton steps on the eliminant G(alpha) (numerical derivative) to full precision."""
    h = 1e-7
    for _ in range(iterations):
        g0 = _fk_elimination(geom, rho, np.cos(alpha), np.sin(alpha))[4]
        gp = _fk_elimination(geom, rho, np.cos(alpha + h), np.sin(alpha + h))[4]
        gm = _fk_elimination(geom, rho, np.cos(alpha - h), np.sin(alpha - h))[4]
        slope = (gp - gm) / (2 * h)
        step = np.divide(g0, slope, out=np.zeros_like(g0), where=slope != 0)
        alpha = alpha - np.clip(step, -1e-3, 1e-3)
    return alpha


def _degenerate_solutions(geom: Geometry, rho: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Solutions at alpha where ``det`` = 0 and the linear pair is consistent (eq. 23 case).

    There (e.g. rho2 = rho3 on a machine with L2 = L3, alpha in {0, pi}) (yP, zP) lies on a
    line p0 + lambda n; eq. 9 - eq. 4 gives xP as a quadratic in lambda and eq. 4 becomes a
    quartic in lambda.
    """
    g = geom
    out_i, out_p, out_a = [], [], []
    for i, (rho1, rho2, rho3) in enumerate(rho):
        if not np.all(np.isfinite((rho1, rho2, rho3))):
            continue
        a_, b_, e_ = (rho3 - rho2) * g.R1, 2.0 * (g.r1 * g.R2 - g.r4 * g.R1), (rho3 - rho2) * g.r1
        norm = np.hypot(a_, b_)
        if norm == 0 or abs(e_) > norm:
            continue
        base, spread = np.arctan2(b_, a_), np.arccos(e_ / norm)
        for alpha in {round(base + spread, 15), round(base - spread, 15)}:
            c, s = np.cos(alpha), np.sin(alpha)
            w = g.R2 * c - g.r4
            m = np.array([[g.R1 * c - g.r1, g.R1 * s], [-4.0 * w, 2.0 * (rho3 - rho2) - 4.0 * g.R2 * s]])
            rhs = np.array([g.R1 * s * rho1,
                            g.L2**2 - g.L3**2 + (rho2 + rho3) * (rho3 - rho2) - 2 * g.R2 * s * (rho2 + rho3)])
            p0, *_ = np.linalg.lstsq(m, rhs, rcond=None)
            if np.linalg.norm(m @ p0 - rhs) > 1e-9 * g.L2**2:
                continue  # inconsistent: no solution at this alpha
            n = np.array([-m[0, 1], m[0, 0]]) if np.any(m[0]) else np.array([-m[1, 1], m[1, 0]])
            n = n / np.linalg.norm(n)
            # Quadratics in lambda: y = p0y + l ny, z = p0z + l nz.
            def quad(cy: float, cz: float, p: np.ndarray = p0, n: np.ndarray = n) -> np.ndarray:
                # (y - cy)^2 + (z - cz)^2 as ascending coefficients in lambda
                dy, dz = p[0] - cy, p[1] - cz
                return np.array([dy**2 + dz**2, 2 * (dy * n[0] + dz * n[1]), n[0] ** 2 + n[1] ** 2])

            constant = np.array([1.0, 0.0, 0.0])
            a_sq = g.L1**2 - g.R1**2 - g.r1**2 + 2 * g.R1 * g.r1 * c
            q9 = a_sq * constant - quad(0.0, rho1)  # = X1^2
            q4 = g.L2**2 * constant - quad(w, g.R2 * s + rho2)  # = X2^2
            d1, d2 = g.D1_minus_d1, g.D2_minus_d2
            x_poly = (q9 - q4 - (d1**2 - d2**2) * constant) / (2 * (d1 - d2))  # xP(lambda)
            x2 = x_poly + d2 * constant
            quartic = np.polynomial.polynomial.polymul(x2, x2)
            quartic[:3] -= q4
            for lam in np.roots(quartic[::-1]):
                if abs(lam.imag) > 1e-6 * (1 + abs(lam)):
                    continue
                lam = lam.real
                y, z = p0 + lam * n
                xp = np.polynomial.polynomial.polyval(lam, x_poly)
                out_i.append(i)
                out_p.append([xp, y, z])
                out_a.append(alpha)
    return np.array(out_i, int), np.array(out_p, float).reshape(-1, 3), np.array(out_a, float)


def module_fk_all(geom: Geometry, rho: np.ndarray) -> ModuleFKSolutions:
    """All assembly modes (platform (K, 3) mm, alpha rad) for slider readings rho (N, 3) mm.

    Roots of the degree-12 eliminant in tan(alpha/2), polished and verified on the closure
    equations (eq. 2); consistent degenerate cases of eq. 23 are solved separately.
    """
    return _module_fk_all(geom, geom.true_joints(np.atleast_2d(np.asarray(rho, dtype=float))))


def _module_fk_all(geom: Geometry, rho: np.ndarray) -> ModuleFKSolutions:
    """:func:`module_fk_all` of true slider positions (N, 3) mm."""
    c, s = TrigPoly.cos_sin(rho.shape[0])
    eliminant = _fk_elimination(geom, rho, c, s)[4]
    index, alpha = real_half_angle_roots(eliminant.num)
    alpha = _polish_alpha(geom, rho[index], alpha)
    platform = _platform_from_alpha(geom, rho[index], alpha)
    d_index, d_platform, d_alpha = _degenerate_solutions(geom, rho)
    index = np.concatenate([index, d_index])
    platform = np.concatenate([platform, d_platform])
    alpha = np.concatenate([alpha, d_alpha])
    alpha = np.angle(np.exp(1j * alpha))
    finite = finite_rows(platform)
    index, platform, alpha = index[finite], platform[finite], alpha[finite]
    ok = closure_ok(geom, platform, alpha, rho[index])
    index, platform, alpha = index[ok], platform[ok], alpha[ok]
    # Remove duplicates (double roots, pi candidates found twice).
    key = np.column_stack([index, np.round(alpha, 7), np.round(platform, 4)])
    _, first = np.unique(key, axis=0, return_index=True)
    first = np.sort(first)
    index, platform, alpha = index[first], platform[first], alpha[first]
    order = np.lexsort((alpha, index))
    index, platform, alpha = index[order], platform[order], alpha[order]
    working = is_working_mode(geom, platform, alpha, rho[index])
    return ModuleFKSolutions(index, platform, alpha, working)


@dataclass(frozen=True)
class ModuleFK:
    """Working-mode FK of the module for N slider sets (NaN where no working assembly exists)."""

    platform: np.ndarray  # (N, 3) mm, base frame
    alpha: np.ndarray  # (N,) rad
    reachable: np.ndarray  # (N,) bool


def _working_branch(geom: Geometry, rho: np.ndarray, alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Working-branch platform (N, 3) mm at a trial alpha, and the eq. 13 residual there (mm^2).

    For a fixed alpha, eq. 9, 4 and 5 are three spheres in P (leg I through the midpoints of
    its rods); of their two intersections the machine's is the lower one (larger z, z down).
    Eq. 13 (3a - 3b) is what the true alpha must also satisfy.
    """
    g = geom
    c, s = np.cos(alpha), np.sin(alpha)
    rho1, rho2, rho3 = rho[:, 0], rho[:, 1], rho[:, 2]
    ux = -g.D2_minus_d2 + g.D1_minus_d1  # same for both legs II and III
    w = g.R2 * c - g.r4
    # common terms evaluated once, each in the order the whole expressions evaluate it (the same numbers)
    r2_s, ww = g.R2 * s, w * w
    uz, vz = rho2 + r2_s - rho1, rho3 - r2_s - rho1
    ra2 = g.L1**2 - g.R1**2 - g.r1**2 + 2.0 * g.R1 * g.r1 * c
    in_plane = ux * ux + ww
    uu, vv, uv = in_plane + uz * uz, in_plane + vz * vz, ux * ux - ww + uz * vz
    b2, b3 = 0.5 * (ra2 - g.L2**2 + uu), 0.5 * (ra2 - g.L3**2 + vv)
    gram = uu * vv - uv * uv
    lam, mu = (b2 * vv - b3 * uv) / gram, (b3 * uu - b2 * uv) / gram
    # n = u x v with u = (ux, w, uz), v = (ux, -w, vz)
    nx, ny, nz = w * vz + w * uz, uz * ux - ux * vz, -2.0 * ux * w
    px, py, pz = lam * ux + mu * ux, lam * w - mu * w, lam * uz + mu * vz
    with np.errstate(invalid="ignore"):
        nu = np.sqrt((ra2 - px * px - py * py - pz * pz) / gram) * np.sign(nz)
    y, z = py + nu * ny, pz + nu * nz + rho1
    platform = np.stack([px + nu * nx - g.D1_minus_d1, y, z], axis=-1)
    residual = y * (g.R1 * c - g.r1) - g.R1 * s * (rho1 - z)
    return platform, residual


def module_fk_working(geom: Geometry, rho: np.ndarray, alpha_guess: np.ndarray | None = None) -> ModuleFK:
    """Platform position (N, 3) mm and alpha (rad) of the machine's assembly mode for slider readings rho (N, 3) mm.

    Fast path: secant iterations on eq. 13 along the working branch of the three-sphere
    intersection (:func:`_working_branch`), from alpha = 0 (the working alpha is small and the
    residual smooth and monotone near it) or from ``alpha_guess`` (rad, e.g. the neighbours'
    alpha along a path: then 2-3 steps suffice). Poses where that does not land on a verified
    working-mode solution are solved by the exact all-modes route (:func:`module_fk_all`).
    """
    return _module_fk_working(geom, geom.true_joints(np.atleast_2d(np.asarray(rho, dtype=float))), alpha_guess)


def _module_fk_working(geom: Geometry, rho: np.ndarray, alpha_guess: np.ndarray | None = None) -> ModuleFK:
    """:func:`module_fk_working` of true slider positions (N, 3) mm."""
    compiled = kernels.fk_working(geom, rho, alpha_guess)
    platform, alpha, good = _secant_route(geom, rho, alpha_guess) if compiled is None else compiled[:3]
    retry = np.flatnonzero(~good)
    if retry.size:
        platform[retry], alpha[retry] = working_assembly_exact(geom, rho[retry])
    return ModuleFK(platform, alpha, np.isfinite(alpha))


def _secant_route(geom: Geometry, rho: np.ndarray, alpha_guess: np.ndarray | None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """numpy route of :func:`module_fk_working`'s secant iteration (its compiled twin:
    kernels.fk_working): platform (N, 3) mm, alpha (N,) rad and good (N,), a verified working
    assembly (NaN where not), for true slider positions rho (N, 3) mm."""
    warm = alpha_guess is not None
    a0 = np.nan_to_num(np.asarray(alpha_guess, dtype=float)) if warm else np.zeros(rho.shape[0])
    a1 = a0 + (1e-4 if warm else 0.02)
    _, f0 = _working_branch(geom, rho, a0)
    platform, f1 = _working_branch(geom, rho, a1)
    # The poses still iterating (most need 2-3 steps, a few more), their rows gathered: each pose's
    # numbers are its own, and a pose's platform and alpha are written back once, when it stops
    # (numpy gathers and scatters rows of (N, 3) arrays several times slower than whole arrays).
    active = np.arange(rho.shape[0])
    rho_a, plat_a, a0_a, a1_a, f0_a, f1_a = rho, platform, a0, a1, f0, f1
    for _ in range(12):
        slope = f1_a - f0_a
        step = np.clip(np.nan_to_num(np.divide(f1_a * (a1_a - a0_a), slope, out=np.zeros_like(slope),
                                               where=slope != 0)), -0.3, 0.3)
        a0_a, f0_a = a1_a, f1_a
        a1_a = a1_a - step
        plat_a, f1_a = _working_branch(geom, rho_a, a1_a)
        going = np.abs(step) >= 1e-15
        if going.all():
            continue
        stopped = active[~going]
        a1[stopped], platform[stopped] = a1_a[~going], np.compress(~going, plat_a, axis=0)
        active = active[going]
        if not active.size:
            break
        rho_a, plat_a = np.compress(going, rho_a, axis=0), np.compress(going, plat_a, axis=0)
        a0_a, a1_a, f0_a, f1_a = a0_a[going], a1_a[going], f0_a[going], f1_a[going]
    if active.size:  # still going after the last step: where it stands
        a1[active], platform[active] = a1_a, plat_a
    alpha = np.angle(np.exp(1j * a1))
    good = finite_rows(platform)
    with np.errstate(invalid="ignore"):  # judged at every pose (as in _newton_route); the others say False
        good &= closure_ok(geom, platform, alpha, rho) & is_working_mode(geom, platform, alpha, rho)
    platform[~good], alpha[~good] = np.nan, np.nan
    return platform, alpha, good


def working_assembly_exact(geom: Geometry, rho: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Platform (N, 3) mm and alpha (N,) rad of the working assembly of true slider positions
    rho (N, 3) mm by the all-modes route (NaN where there is none): where the fast route fails."""
    platform, alpha = np.full((len(rho), 3), np.nan), np.full(len(rho), np.nan)
    exact = _module_fk_all(geom, rho)
    found = exact.pose_index[exact.working_mode]
    # Several working assemblies cannot occur in the reachable workspace; if they do,
    # take the one with the smallest |alpha| (closest to the machine's home posture).
    order = np.lexsort((np.abs(exact.alpha[exact.working_mode]), found))
    found, first = np.unique(found[order], return_index=True)
    platform[found] = exact.platform[exact.working_mode][order][first]
    alpha[found] = exact.alpha[exact.working_mode][order][first]
    return platform, alpha
