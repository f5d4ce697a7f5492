"""Whole VERNE (paper section 4): tool pose in the table frame <-> joints.

Frames and units: the tool pose is given in the table frame R_t (Table IV): ``tip`` (N, 3) mm
is the tool centre point U, ``axis`` (N, 3) the unit tool axis from the tip towards the
spindle (APT i, j, k). Joints (N, 5) = (rho1, rho2, rho3) mm, (theta1, theta2) rad; the tilt
alpha of the platform (rad) and the tool-axis angles (phi1, phi2) (rad) come along.

Every axis has two angle pairs, (phi1, phi2) and (-phi1, phi2 + pi) (``pair`` = +1 / -1);
theta2 = -phi2 (eq. 26), alpha = theta1 + phi1 (eq. 30). At phi1 = 0 (axis along the table
normal) phi2 and so theta2 are free: the caller's ``theta2`` value is used there.

Joints in and out are the controller's readings: the true joint is the reading plus the
geometry's ``rho_offset`` / ``theta_offset`` (zero by default).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from . import kernels
from .geometry import Geometry
from .module import (
    _module_fk_all,
    _module_fk_working,
    closure_ok,
    is_working_mode,
    solutions_for_alpha,
    working_assembly_exact,
    working_sliders,
)
from .rows import all_of, finite_rows
from .tolerances import POLE_EPS, ROOT_PIECES
from .trigpoly import TrigPoly, real_half_angle_roots, roots_within


def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """Angle (rad) wrapped to [-pi, pi)."""
    return (np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi


def unwrap_near(angle: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """The angle (rad) equal to ``angle`` modulo 2 pi that is nearest to ``reference`` (rad)."""
    return reference + wrap_angle(np.asarray(angle) - reference)


def axis_angles(axis: np.ndarray, pair: np.ndarray | int = 1, theta2_at_pole: np.ndarray | float = 0.0
                ) -> tuple[np.ndarray, np.ndarray]:
    """(phi1, phi2) in rad of unit tool axes (N, 3), table frame, for angle pair +1 or -1.

    axis = (sin phi1 sin phi2, -sin phi1 cos phi2, cos phi1). Pair +1 has phi1 in [0, pi];
    pair -1 is (-phi1, phi2 + pi). On the pole phi2 = -theta2_at_pole.
    """
    axis = np.asarray(axis, dtype=float)
    i, j, k = axis[..., 0], axis[..., 1], axis[..., 2]
    sin_phi1 = np.hypot(i, j)
    phi1 = np.arctan2(sin_phi1, k)
    phi2 = np.where(sin_phi1 > POLE_EPS, np.arctan2(i, -j), -np.asarray(theta2_at_pole, dtype=float))
    pair = np.asarray(pair)
    at_pole = sin_phi1 <= POLE_EPS
    phi2 = np.where((pair < 0) & ~at_pole, phi2 + np.pi, phi2)
    return np.where(pair < 0, -phi1, phi1), wrap_angle(phi2)


def axis_from_angles(phi1: np.ndarray, phi2: np.ndarray) -> np.ndarray:
    """Unit tool axis (N, 3), table frame, from (phi1, phi2) in rad."""
    s1 = np.sin(phi1)
    return np.stack([s1 * np.sin(phi2), -s1 * np.cos(phi2), np.cos(phi1) + 0.0 * phi2], axis=-1)


def true_theta2(geom: Geometry, theta2: np.ndarray | float) -> np.ndarray:
    """True rotary angle (rad) of a theta2 reading (untouched without offsets: bit-identical)."""
    theta2 = np.asarray(theta2, dtype=float)
    return theta2 + geom.theta_offset[1] if geom.has_offsets else theta2


def _tilted_platform(geom: Geometry, tip: np.ndarray, axis: np.ndarray, phi2: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vx, vy, vz): platform centre P (mm) in the tilt frame after Tz(da) Rx(theta1).

    P in the table frame is tip + Delta axis; theta2 = -phi2 turns it into the tilt frame:
    v = (0, 0, dt) + Rx(pi) Rz(-phi2) (tip + Delta axis). Then P in the base frame is
    (vx, cos t1 vy - sin t1 vz, da + sin t1 vy + cos t1 vz).
    """
    p = tip + geom.delta * axis
    c2, s2 = np.cos(phi2), np.sin(phi2)
    return c2 * p[:, 0] + s2 * p[:, 1], s2 * p[:, 0] - c2 * p[:, 1], geom.dt - p[:, 2]


def _platform_coefficients(geom: Geometry, tip: np.ndarray, axis: np.ndarray, phi1: np.ndarray,
                           phi2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(xP, A, B) with yP = A cos(alpha) + B sin(alpha), zP = da - B cos(alpha) + A sin(alpha)."""
    vx, vy, vz = _tilted_platform(geom, tip, axis, phi2)
    c1, s1 = np.cos(phi1), np.sin(phi1)
    return vx, vy * c1 + vz * s1, vy * s1 - vz * c1


def _coupling(geom: Geometry, x1: np.ndarray, a: np.ndarray, b: np.ndarray, c, s):
    """Eq. 31 with alpha = theta1 + phi1 as unknown: trigonometric degree 3 (sextic in tan(alpha/2))."""
    g = geom
    k = g.L1**2 - g.R1**2 - g.r1**2
    y = a * c + b * s
    return g.R1**2 * (s * s) * (x1**2 - k - 2.0 * g.R1 * g.r1 * c) + (
        g.R1**2 + g.r1**2 - 2.0 * g.R1 * g.r1 * c) * (y * y)


def _platform_pose(geom: Geometry, xp: np.ndarray, a: np.ndarray, b: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    c, s = np.cos(alpha), np.sin(alpha)
    return np.stack([xp, a * c + b * s, geom.da - b * c + a * s], axis=-1)


def _only_working_root(geom: Geometry, a: np.ndarray, b: np.ndarray, x1sq: np.ndarray, root: np.ndarray
                       ) -> np.ndarray:
    """(N,) bool: where ``root`` (rad), a root of the signed eq. 31 (working mode, s1 = -1) in
    (-alpha_max, alpha_max), is surely its only one there. Eq. 31 squared (:func:`_coupling`, a
    sextic in tan(alpha/2)) is F F~, the signed forms of both assemblies of leg I. Its roots are
    counted in ROOT_PIECES pieces (:func:`roots_within`); each piece must hold none, or exactly
    one: ``root`` itself, or a root of F~ alone, which a piece tells by F keeping its sign over it
    (at a simple root of F F~ that is F's, F changes sign). Not sure anywhere (a root near a
    piece's end, a coefficient near 0, leg I out of reach at an end): False."""
    edges = np.linspace(-geom.alpha_max, geom.alpha_max, ROOT_PIECES + 1)
    poly = _coupling(geom, np.sqrt(x1sq), a, b, *TrigPoly.cos_sin(len(a)))
    num = poly.num / np.max(np.abs(poly.num), axis=1, keepdims=True)
    t = np.tan(0.5 * edges)
    at_edges = np.polynomial.polynomial.polyval(t, num.T)  # (N, pieces + 1): F F~ at the ends
    f = _signed_coupling(geom, a[:, None], b[:, None], x1sq[:, None], edges)[0]  # NaN: leg I out of reach
    sure = all_of(np.abs(at_edges) > 1e-9)
    piece = np.searchsorted(edges, root) - 1
    sure &= all_of(np.abs(root[:, None] - edges) > 1e-9)
    for j in range(ROOT_PIECES):
        count = roots_within(num, t[j], t[j + 1])
        sign_kept = f[:, j] * f[:, j + 1] > 0  # False where NaN
        sure &= np.where(piece == j, count == 1, (count == 0) | ((count == 1) & sign_kept))
    return sure


def _signed_coupling(geom: Geometry, a: np.ndarray, b: np.ndarray, x1sq: np.ndarray, alpha: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 31 in its signed form (working mode, s1 = -1) at ``alpha`` (rad), F = y G + R1 sin(alpha)
    H (NaN where leg I does not reach), and its term y G (mm^2), whose size scales F."""
    g = geom
    c, s = np.cos(alpha), np.sin(alpha)
    yg = (a * c + b * s) * np.sqrt(g.R1**2 + g.r1**2 - 2.0 * g.R1 * g.r1 * c)
    with np.errstate(invalid="ignore"):
        return yg + g.R1 * s * np.sqrt(g.L1**2 - g.R1**2 - g.r1**2 + 2.0 * g.R1 * g.r1 * c - x1sq), yg


@dataclass(frozen=True)
class MachineIK:
    """Working-mode IK for N tool poses; NaN rows where the pose is unreachable."""

    joints: np.ndarray  # (N, 5) rho1..3 mm, theta1, theta2 rad
    alpha: np.ndarray  # (N,) rad
    phi: np.ndarray  # (N, 2) rad
    platform: np.ndarray  # (N, 3) mm, base frame
    reachable: np.ndarray  # (N,) bool


def machine_ik_working(geom: Geometry, tip: np.ndarray, axis: np.ndarray, pair: np.ndarray | int = 1,
                       theta2_at_pole: np.ndarray | float = 0.0, exact_fallback: bool = True) -> MachineIK:
    """Working-mode joints for tool tips (N, 3) mm and unit axes (N, 3), table frame, one angle pair.

    The working alpha is the root in (-alpha_max, alpha_max) of the signed form of eq. 31,
    F(alpha) = yP sqrt(R1^2 + r1^2 - 2 R1 r1 cos) + R1 sin sqrt(a^2 - X1^2) (eq. 13 with
    s1 = -1 and eq. 9), found by Newton's method from its linearisation at alpha = 0. The
    result is verified (closure equations, s_i = -1); poses where Newton did not land on a
    working solution go through the all-solutions route, except those leg I cannot reach at
    any tilt (X1^2 > L1^2 - (R1 - r1)^2: then eq. 9 has no real solution). Without
    ``exact_fallback`` they are reported unreachable (a fast screen, e.g. for placement).
    """
    tip = np.atleast_2d(np.asarray(tip, dtype=float))
    axis = np.atleast_2d(np.asarray(axis, dtype=float))
    n = tip.shape[0]
    pair = np.broadcast_to(np.asarray(pair), (n,))
    # The caller's theta2 at the pole is a reading, like every joint out of here.
    theta2_at_pole = np.broadcast_to(true_theta2(geom, theta2_at_pole), (n,))
    g = geom
    fast = kernels.ik_working(geom, tip, axis, pair, theta2_at_pole)
    if fast is None:
        fast = _newton_route(geom, tip, axis, pair, theta2_at_pole)
    joints, alpha, phi, platform, coefficients, good, candidates = fast
    xp, a, b, x1sq = coefficients.T
    rho = joints[:, :3]
    retry = np.flatnonzero(candidates)
    if retry.size and exact_fallback:
        # Newton found a root of eq. 31 in (-alpha_max, alpha_max) where a leg does not reach: if
        # it is the only root there, no working solution exists and the all-solutions route (the
        # sextic's eigenvalues, most of this function's time where poses are out of reach) would
        # find none. The compiled route tests every candidate in one loop.
        settled = kernels.settled(geom, coefficients, alpha, joints, candidates)
        if settled is not None:
            retry = np.flatnonzero(candidates & ~settled)
        else:
            residual, yg = _signed_coupling(geom, a[retry], b[retry], x1sq[retry], alpha[retry])
            newton_root = ((np.abs(residual) <= 1e-9 * (np.abs(yg) + g.R1)) & (np.abs(alpha[retry]) < g.alpha_max)
                           & ~finite_rows(rho[retry]))
            if newton_root.any():
                rows = retry[newton_root]
                retry = np.setdiff1d(retry, rows[_only_working_root(geom, a[rows], b[rows], x1sq[rows],
                                                                    alpha[rows])])
    if retry.size and exact_fallback:
        exact = _machine_ik_all(geom, tip[retry], axis[retry], pair=pair[retry], theta2_at_pole=theta2_at_pole[retry])
        wm = exact.working_mode
        order = np.lexsort((np.abs(exact.alpha[wm]), exact.pose_index[wm]))
        found, first = np.unique(exact.pose_index[wm][order], return_index=True)
        target = retry[found]
        joints[target] = exact.joints[wm][order][first]
        alpha[target] = exact.alpha[wm][order][first]
        platform[target] = _platform_pose(geom, xp[target], a[target], b[target], alpha[target])
        good[target] = True
    bad = np.flatnonzero(~good)
    joints[bad], alpha[bad], platform[bad, 1:] = np.nan, np.nan, np.nan
    return MachineIK(geom.readings(joints), alpha, phi, platform, good)


def _newton_route(geom: Geometry, tip: np.ndarray, axis: np.ndarray, pair: np.ndarray, theta2_at_pole: np.ndarray
                  ) -> tuple[np.ndarray, ...]:
    """numpy route of :func:`machine_ik_working`'s fast part (its compiled twin: kernels.ik_working):
    joints (N, 5) true positions (rho NaN where a leg does not reach), alpha (N,) rad, phi (N, 2)
    rad, platform (N, 3) mm, (xP, A, B, X1^2) (N, 4), good (N,): a verified working solution, and
    the candidates (N,) for the exact route: not good, leg I within reach, tip and axis finite."""
    phi1, phi2 = axis_angles(axis, pair, theta2_at_pole)
    xp, a, b = _platform_coefficients(geom, tip, axis, phi1, phi2)
    g = geom
    x1sq = (xp + g.D1_minus_d1) ** 2
    k = g.L1**2 - g.R1**2 - g.r1**2
    two_rr = 2.0 * g.R1 * g.r1
    with np.errstate(invalid="ignore", divide="ignore"):
        h0 = np.sqrt(k + two_rr - x1sq)
        alpha = -a * (g.R1 - g.r1) / (b * (g.R1 - g.r1) + g.R1 * h0)
        for _ in range(6):
            c, s = np.cos(alpha), np.sin(alpha)
            y, dy = a * c + b * s, b * c - a * s
            gq = np.sqrt(g.R1**2 + g.r1**2 - two_rr * c)
            h = np.sqrt(k + two_rr * c - x1sq)
            f = y * gq + g.R1 * s * h
            df = dy * gq + y * (0.5 * two_rr * s / gq) + g.R1 * (c * h - s * 0.5 * two_rr * s / h)
            alpha = alpha - np.clip(f / df, -0.2, 0.2)
    platform = _platform_pose(geom, xp, a, b, alpha)
    rho = working_sliders(geom, platform, alpha)
    good = finite_rows(rho) & (np.abs(alpha) < g.alpha_max)
    # judged at every pose, not the good ones gathered (a pose's verdict is its own; numpy gathers
    # rows of (N, 3) arrays slowly): the others' NaN and inf say False
    with np.errstate(invalid="ignore"):
        good &= is_working_mode(geom, platform, alpha, rho)
        good &= closure_ok(geom, platform, alpha, rho)
    joints = np.column_stack([rho, alpha - phi1, -phi2])
    candidates = ~good & (x1sq <= k + two_rr) & finite_rows(tip) & finite_rows(axis)
    return (joints, alpha, np.column_stack([phi1, phi2]), platform, np.column_stack([xp, a, b, x1sq]), good,
            candidates)


@dataclass(frozen=True)
class MachineIKSolutions:
    """All IK solutions of the machine for N poses, flattened by ``pose_index``."""

    pose_index: np.ndarray  # (K,) int
    joints: np.ndarray  # (K, 5) rho mm, theta rad
    alpha: np.ndarray  # (K,) rad
    phi: np.ndarray  # (K, 2) rad
    pair: np.ndarray  # (K,) +1 / -1
    working_mode: np.ndarray  # (K,) bool


def machine_ik_all(geom: Geometry, tip: np.ndarray, axis: np.ndarray, pair: np.ndarray | int | None = None,
                   theta2_at_pole: np.ndarray | float = 0.0) -> MachineIKSolutions:
    """All IK solutions for tips (N, 3) mm and axes (N, 3), table frame: roots of eq. 31.

    ``pair`` None gives both angle pairs (up to 2 x 16 solutions per pose). Eq. 31 is solved
    in alpha = theta1 + phi1 as a sextic in tan(alpha/2); each real root gives the platform
    pose and, through eq. 10-13, up to 4 slider sets (more on the special cases of Table II).
    """
    found = _machine_ik_all(geom, tip, axis, pair, true_theta2(geom, theta2_at_pole))
    return found if not geom.has_offsets else replace(found, joints=geom.readings(found.joints))


def _machine_ik_all(geom: Geometry, tip: np.ndarray, axis: np.ndarray, pair: np.ndarray | int | None,
                    theta2_at_pole: np.ndarray | float) -> MachineIKSolutions:
    """:func:`machine_ik_all` in true joint positions (theta2 at the pole a true value too)."""
    tip = np.atleast_2d(np.asarray(tip, dtype=float))
    axis = np.atleast_2d(np.asarray(axis, dtype=float))
    n = tip.shape[0]
    theta2_at_pole = np.broadcast_to(np.asarray(theta2_at_pole, dtype=float), (n,))
    pairs = (1, -1) if pair is None else (None,)
    parts = []
    for p in pairs:
        pp = np.broadcast_to(np.asarray(pair if p is None else p), (n,))
        phi1, phi2 = axis_angles(axis, pp, theta2_at_pole)
        xp, a, b = _platform_coefficients(geom, tip, axis, phi1, phi2)
        c, s = TrigPoly.cos_sin(n)
        poly = _coupling(geom, xp + geom.D1_minus_d1, a, b, c, s)
        index, alpha = real_half_angle_roots(poly.num)
        alpha = _polish(geom, xp[index] + geom.D1_minus_d1, a[index], b[index], alpha)
        platform = _platform_pose(geom, xp[index], a[index], b[index], alpha)
        order = np.argsort(index, kind="stable")
        sol = solutions_for_alpha(geom, platform[order], alpha[order], index[order])
        k = sol.pose_index
        joints = np.column_stack([sol.rho, sol.alpha - phi1[k], -phi2[k]])
        parts.append((k, joints, sol.alpha, np.column_stack([phi1[k], phi2[k]]), pp[k], sol.working_mode))
    index, joints, alpha, phi, pair_, working = (np.concatenate(x) for x in zip(*parts, strict=False))
    key = np.column_stack([index, np.round(joints, 6)])
    _, first = np.unique(key, axis=0, return_index=True)
    first = np.sort(first)
    order = first[np.lexsort((joints[first, 0], alpha[first], -pair_[first], index[first]))]
    return MachineIKSolutions(index[order], joints[order], alpha[order], phi[order], pair_[order], working[order])


def _polish(geom: Geometry, x1: np.ndarray, a: np.ndarray, b: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    h = 1e-7
    for _ in range(3):
        f = _coupling(geom, x1, a, b, np.cos(alpha), np.sin(alpha))
        df = (_coupling(geom, x1, a, b, np.cos(alpha + h), np.sin(alpha + h))
              - _coupling(geom, x1, a, b, np.cos(alpha - h), np.sin(alpha - h))) / (2 * h)
        alpha = alpha - np.clip(np.divide(f, df, out=np.zeros_like(f), where=df != 0), -1e-3, 1e-3)
    return alpha


def tool_pose(geom: Geometry, platform: np.ndarray, alpha: np.ndarray, theta1: np.ndarray, theta2: np.ndarray,
              delta: np.ndarray | float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 32-33: tool tip (N, 3) mm and unit axis (N, 3) in the table frame.

    ``platform`` (N, 3) mm base frame, alpha rad, theta1/theta2 the *true* table angles in rad
    (not readings). ``delta`` (mm, one or per pose): P to tool tip, default the geometry's.
    """
    g = geom
    delta = g.delta if delta is None else delta
    xp, yp, zp = platform[:, 0], platform[:, 1], platform[:, 2]
    c1, s1 = np.cos(theta1), np.sin(theta1)
    c2, s2 = np.cos(theta2), np.sin(theta2)
    phi1 = alpha - theta1
    lateral = delta * np.sin(phi1) - c1 * yp - s1 * (zp - g.da)
    tip = np.stack([
        c2 * xp + s2 * lateral,
        -s2 * xp + c2 * lateral,
        s1 * yp - c1 * zp + g.da * c1 - delta * np.cos(phi1) + g.dt,
    ], axis=-1)
    return tip, axis_from_angles(phi1, -theta2)


@dataclass(frozen=True)
class MachineFK:
    """Working-mode FK for N joint sets; NaN where no working assembly exists."""

    tip: np.ndarray  # (N, 3) mm, table frame
    axis: np.ndarray  # (N, 3) unit, table frame
    platform: np.ndarray  # (N, 3) mm, base frame
    alpha: np.ndarray  # (N,) rad
    reachable: np.ndarray  # (N,) bool


def machine_fk_working(geom: Geometry, joints: np.ndarray, alpha_guess: np.ndarray | None = None) -> MachineFK:
    """Tool tip (mm) and axis in the table frame for joints (N, 5): rho mm, theta rad.

    ``alpha_guess`` (rad): optional start for the platform tilt (see module_fk_working).
    """
    joints = geom.true_joints(np.atleast_2d(np.asarray(joints, dtype=float)))
    fast = kernels.fk_working(geom, joints, alpha_guess)
    if fast is None:
        module = _module_fk_working(geom, joints[:, :3], alpha_guess)
        tip, axis = tool_pose(geom, module.platform, module.alpha, joints[:, 3], joints[:, 4])
        return MachineFK(tip, axis, module.platform, module.alpha, module.reachable)
    platform, alpha, good, tip, axis = fast
    retry = np.flatnonzero(~good)
    if retry.size:
        platform[retry], alpha[retry] = working_assembly_exact(geom, joints[retry, :3])
        tip[retry], axis[retry] = tool_pose(geom, platform[retry], alpha[retry], joints[retry, 3], joints[retry, 4])
    return MachineFK(tip, axis, platform, alpha, np.isfinite(alpha))


@dataclass(frozen=True)
class MachineFKSolutions:
    """Every assembly mode for N joint sets, flattened by ``pose_index``."""

    pose_index: np.ndarray
    tip: np.ndarray  # (K, 3) mm, table frame
    axis: np.ndarray  # (K, 3)
    phi: np.ndarray  # (K, 2) rad
    platform: np.ndarray  # (K, 3) mm, base frame
    alpha: np.ndarray  # (K,) rad
    working_mode: np.ndarray  # (K,) bool


def machine_fk_all(geom: Geometry, joints: np.ndarray) -> MachineFKSolutions:
    """All assembly modes (eq. 32-33 over the module's FK solutions) for joints (N, 5)."""
    joints = geom.true_joints(np.atleast_2d(np.asarray(joints, dtype=float)))
    module = _module_fk_all(geom, joints[:, :3])
    j = joints[module.pose_index]
    tip, axis = tool_pose(geom, module.platform, module.alpha, j[:, 3], j[:, 4])
    phi = np.column_stack([wrap_angle(module.alpha - j[:, 3]), wrap_angle(-j[:, 4])])
    return MachineFKSolutions(module.pose_index, tip, axis, phi, module.platform, module.alpha, module.working_mode)
