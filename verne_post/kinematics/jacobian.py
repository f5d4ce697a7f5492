"""Analytic Jacobians and singularity measures of the VERNE.

Units: rho mm, theta and alpha rad; tip velocities in mm per unit joint rate, table frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import kernels
from .adjugate import fill_adjugate
from .geometry import Geometry
from .rows import dots


def _rod_vectors(geom: Geometry, platform: np.ndarray, alpha: np.ndarray, rho: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rod vectors B - A (N, 4, 3) mm (rods 1a, 1b, leg II, leg III), dB/dalpha (N, 4, 3), lengths (4,)."""
    g = geom
    c, s = np.cos(alpha), np.sin(alpha)
    x, y, z = platform[:, 0], platform[:, 1], platform[:, 2]
    # Platform point offsets (R_pl) rotated by alpha about x: (0, Y, 0) -> (0, Y c, Y s).
    offsets = np.array([g.R1, -g.R1, -g.R2, g.R2])
    sliders_y = np.array([g.r1, -g.r1, -g.r4, g.r4])
    dx = np.array([g.D1_minus_d1, g.D1_minus_d1, g.D2_minus_d2, g.D2_minus_d2])
    slider_z = rho[:, [0, 0, 1, 2]]
    rods = np.stack([
        x[:, None] + dx,
        y[:, None] + offsets * c[:, None] - sliders_y,
        z[:, None] + offsets * s[:, None] - slider_z,
    ], axis=-1)
    d_alpha = np.stack([np.zeros((len(c), 4)), -offsets * s[:, None], offsets * c[:, None]], axis=-1)
    return rods, d_alpha, np.array([g.L1, g.L1, g.L2, g.L3])


def module_jacobian(geom: Geometry, platform: np.ndarray, alpha: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """d(xP, yP, zP, alpha)/d(rho1, rho2, rho3), (N, 4, 3), from the closure equations.

    Differentiating eq. 3a, 3b, 4, 5: A d(pose) + B d(rho) = 0, so d(pose) = -A^-1 B d(rho).
    ``rho`` (N, 3) mm are slider readings (the geometry's offsets are added).
    """
    rho = geom.true_joints(rho)
    rods, d_alpha, _ = _rod_vectors(geom, platform, alpha, rho)
    a = np.concatenate([rods, dots(rods, d_alpha)[..., None]], axis=-1)
    b = np.zeros((*rods.shape[:2], 3))
    b[:, 0, 0], b[:, 1, 0], b[:, 2, 1], b[:, 3, 2] = (-rods[:, k, 2] for k in range(4))
    return -np.linalg.solve(a, b)


def closure_inverse(geom: Geometry, platform: np.ndarray, alpha: np.ndarray, rho: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(a^-1, d(pose)/d(rho)) of N module poses, entry-first ((4, 4, N) and (4, 3, N)): ``a`` is half
    the derivative of eq. 3a, 3b, 4, 5 (mm^2) with respect to (xP, yP, zP, alpha) (mm, rad), so that
    ``pose - a^-1 residuals / 2`` is a Newton step of the closure equations; d(pose)/d(rho) is
    :func:`module_jacobian`'s, by the adjugate (no LAPACK call per pose). ``rho`` (N, 3) mm are readings."""
    g = geom
    rho = geom.true_joints(rho)
    c, s = np.cos(alpha), np.sin(alpha)
    x, y, z = platform[:, 0], platform[:, 1], platform[:, 2]
    a = np.empty((4, 4, len(alpha)))
    # the rows of _rod_vectors' rods (B - A) and their alpha terms, rods 1a, 1b, leg II, leg III
    legs = ((g.R1, g.r1, g.D1_minus_d1, 0), (-g.R1, -g.r1, g.D1_minus_d1, 0), (-g.R2, -g.r4, g.D2_minus_d2, 1),
            (g.R2, g.r4, g.D2_minus_d2, 2))
    for k, (offset, slider_y, dx, slider) in enumerate(legs):
        a[k, 0] = x + dx
        a[k, 1] = y + offset * c - slider_y
        a[k, 2] = z + offset * s - rho[:, slider]
        a[k, 3] = offset * (a[k, 2] * c - a[k, 1] * s)
    adj, det = _adjugate4(a)
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = adj / det
    # d(pose) = -a^-1 b d(rho), b's only entries -rod_z: rods 1a and 1b on slider 1, II on 2, III on 3
    jac = np.stack([inverse[:, 0] * a[0, 2] + inverse[:, 1] * a[1, 2], inverse[:, 2] * a[2, 2],
                    inverse[:, 3] * a[3, 2]], axis=1)
    return inverse, jac


def singularity_measures(geom: Geometry, platform: np.ndarray, alpha: np.ndarray, rho: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
    """(serial, parallel) margins in [0, 1] for N module poses; 0 is singular.

    serial: min over the four rod equations of |cos| of the angle between the rod and its
    vertical guideway (a rod perpendicular to its guideway: the slider no longer moves the
    platform along the rod). parallel: inverse condition number of the direct-kinematics
    matrix A with rows normalised by rod length and the alpha column by R1. ``rho`` are readings.
    """
    rho = geom.true_joints(rho)
    rods, d_alpha, lengths = _rod_vectors(geom, platform, alpha, rho)
    units = rods / lengths[:, None]
    serial = np.min(np.abs(units[..., 2]), axis=-1)
    a = np.concatenate([units, dots(units, d_alpha)[..., None] / geom.R1], axis=-1)
    sv = np.linalg.svd(a, compute_uv=False)
    parallel = sv[:, -1] / sv[:, 0]
    return serial, parallel


def machine_jacobian(geom: Geometry, joints: np.ndarray, platform: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """(N, 6, 5): rows d(tip)/dq (mm per mm or per rad) and d(axis)/dq, table frame.

    q = (rho1, rho2, rho3, theta1, theta2); platform (N, 3) mm and alpha rad of the
    assembly mode (from the FK). ``joints`` are readings (mm, rad).
    """
    g = geom
    xp, yp, zp = platform[:, 0], platform[:, 1], platform[:, 2]
    true = g.true_joints(joints)
    t1, t2 = true[:, 3], true[:, 4]
    c1, s1, c2, s2 = np.cos(t1), np.sin(t1), np.cos(t2), np.sin(t2)
    phi1, phi2 = alpha - t1, -t2
    cp, sp = np.cos(phi1), np.sin(phi1)
    lateral = g.delta * sp - c1 * yp - s1 * (zp - g.da)
    n = len(t1)
    # d(lateral, tip_z)/d(xp, yp, zp, alpha, theta1)
    d_lat = np.stack([np.zeros(n), -c1, -s1, g.delta * cp, -g.delta * cp + s1 * yp - c1 * (zp - g.da)], -1)
    d_z = np.stack([np.zeros(n), s1, -c1, g.delta * sp, c1 * yp + s1 * zp - g.da * s1 - g.delta * sp], -1)
    d_xp = np.zeros((n, 5))
    d_xp[:, 0] = 1.0
    tip_x, tip_y = c2 * xp + s2 * lateral, -s2 * xp + c2 * lateral
    d_tip = np.stack([c2[:, None] * d_xp + s2[:, None] * d_lat, -s2[:, None] * d_xp + c2[:, None] * d_lat, d_z], 1)
    d_axis_phi1 = np.stack([cp * np.sin(phi2), -cp * np.cos(phi2), -sp], -1)
    d_axis_phi2 = np.stack([sp * np.cos(phi2), sp * np.sin(phi2), np.zeros(n)], -1)
    d_axis = np.zeros((n, 3, 5))
    d_axis[:, :, 3], d_axis[:, :, 4] = d_axis_phi1, -d_axis_phi1  # d phi1/d alpha = 1, /d theta1 = -1
    # Columns: (xp, yp, zp, alpha, theta1) -> chain through the module for rho.
    d_pose = module_jacobian(g, platform, alpha, joints[:, :3])
    explicit = np.concatenate([d_tip, d_axis], axis=1)  # (N, 6, 5) w.r.t. (xp, yp, zp, alpha, theta1)
    jac = np.zeros((n, 6, 5))
    jac[:, :, :3] = explicit[:, :, :4] @ d_pose
    jac[:, :, 3] = explicit[:, :, 4]
    jac[:, 0, 4], jac[:, 1, 4] = tip_y, -tip_x
    jac[:, 3:, 4] = -d_axis_phi2
    return jac




def joint_rates(jacobian: np.ndarray, tip_velocity: np.ndarray, axis_rate: np.ndarray) -> np.ndarray:
    """Joint rates (N, 5) (mm/s, rad/s) giving tip velocity (N, 3) mm/s and axis rate (N, 3) 1/s.

    The axis rate must be perpendicular to the axis (2 DOF); the 6 x 5 system is solved in
    the least-squares sense, exact when consistent.
    """
    rhs = np.concatenate([tip_velocity, axis_rate], axis=-1)[..., None]
    return (np.linalg.pinv(jacobian) @ rhs)[..., 0]


@dataclass(frozen=True)
class Margins:
    """Distances to the machine's singular and colliding configurations, per pose (N,)."""

    serial: np.ndarray  # [0, 1]: |cos| rod / guideway, worst rod
    parallel: np.ndarray  # (0, 1]: inverse Frobenius condition number of the module's direct kinematics
    machine: np.ndarray  # (0, 1]: the same for the tool Jacobian at fixed theta2
    rod_clearance: np.ndarray  # mm: R1 cos(alpha) - r1, leg I rods cross at 0


def _adjugate4(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(adjugate, determinant) of 4 x 4 matrices stored entry-first: ``a[i, j]`` is an (N,) array;
    the adjugate comes back entry-first too (4, 4, N)."""
    adj = np.empty(np.shape(a))
    return adj, fill_adjugate(a, adj)


def _inverse_condition(matrix: np.ndarray, adj: np.ndarray, det: np.ndarray) -> np.ndarray:
    """4 / (|M|_F |M^-1|_F) in [0, 1], entry-first (4, 4, N) matrices with adjugates and determinants.

    The inverse Frobenius condition number (kappa_2 <= kappa_F <= 4 kappa_2), from one
    adjugate instead of an SVD.
    """
    frobenius = np.sqrt(np.sum(matrix * matrix, axis=(0, 1)) * np.sum(adj * adj, axis=(0, 1)))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.nan_to_num(4.0 * np.abs(det) / frobenius)


def margins(geom: Geometry, joints: np.ndarray, platform: np.ndarray, alpha: np.ndarray) -> Margins:
    """All margins for N working-mode poses: joints (N, 5) mm/rad, platform (N, 3) mm, alpha rad.

    serial: min |cos| between a rod and its guideway. parallel: inverse Frobenius condition
    number of the direct-kinematics matrix A (rows by rod length, the alpha column by R1).
    machine: the same for the Jacobian of (tip, phi1) with respect to (rho1, rho2, rho3,
    theta1) at fixed theta2, phi1 times Delta and theta1 divided by Delta (all mm per mm). It
    vanishes where two working solutions of one tool pose merge (a fold of the coupled tilt).
    theta2 is left out on purpose: the rotary table's pole (axis along the table normal) is a
    singularity of its own, handled by the postprocessor's pole logic. Rotating the tip rows
    by theta2 changes no condition number, so (xP, lateral, z) rows stand for the tip.
    ``joints`` are readings (the geometry's offsets are added).
    """
    g = geom
    joints = g.true_joints(joints)
    compiled = kernels.margins(geom, joints, platform, alpha)
    if compiled is not None:
        return Margins(*compiled.T)
    c, s = np.cos(alpha), np.sin(alpha)
    x, y, z = platform[:, 0], platform[:, 1], platform[:, 2]
    rho = joints[:, :3]
    # Rods 1a, 1b, II, III: platform point offset Y (R_pl, turned by alpha), slider y, slider, length.
    rods = ((g.R1, g.r1, 0, g.L1, g.D1_minus_d1), (-g.R1, -g.r1, 0, g.L1, g.D1_minus_d1),
            (-g.R2, -g.r4, 1, g.L2, g.D2_minus_d2), (g.R2, g.r4, 2, g.L3, g.D2_minus_d2))
    a = np.empty((4, 4, len(alpha)))
    for k, (offset, slider_y, slider, length, dx) in enumerate(rods):
        ux = (x + dx) / length
        uy = (y + offset * c - slider_y) / length
        uz = (z + offset * s - rho[:, slider]) / length
        a[k, 0], a[k, 1], a[k, 2] = ux, uy, uz
        a[k, 3] = (-uy * offset * s + uz * offset * c) / g.R1
    serial = np.min(np.abs(a[:, 2]), axis=0)
    adj, det = _adjugate4(a)
    parallel = _inverse_condition(a, adj, det)
    # d(xP, yP, zP, alpha)/d rho = -diag(1, 1, 1, 1/R1) A^-1 B, B[k, slider] = -u_z of rod k.
    with np.errstate(invalid="ignore", divide="ignore"):
        d_pose = np.stack([adj[:, 0] * a[0, 2] + adj[:, 1] * a[1, 2], adj[:, 2] * a[2, 2], adj[:, 3] * a[3, 2]],
                          axis=1) / det
    d_pose[3] /= g.R1
    t1 = joints[:, 3]
    c1, s1 = np.cos(t1), np.sin(t1)
    phi1 = alpha - t1
    cp, sp = np.cos(phi1), np.sin(phi1)
    d = g.delta
    zr = z - g.da
    jac = np.empty((4, 4, len(alpha)))
    jac[0, :3] = d_pose[0]
    jac[1, :3] = -c1 * d_pose[1] - s1 * d_pose[2] + d * cp * d_pose[3]
    jac[2, :3] = s1 * d_pose[1] - c1 * d_pose[2] + d * sp * d_pose[3]
    jac[3, :3] = d * d_pose[3]
    jac[0, 3] = 0.0
    jac[1, 3] = (-d * cp + s1 * y - c1 * zr) / d
    jac[2, 3] = (c1 * y + s1 * zr - d * sp) / d
    jac[3, 3] = -1.0
    jac = np.nan_to_num(jac)
    machine = np.where(parallel > 0, _inverse_condition(jac, *_adjugate4(jac)), 0.0)
    return Margins(serial, parallel, machine, g.R1 * c - g.r1)
