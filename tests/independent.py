"""An independent model of the VERNE for the tests, written from VERNE-KINEMATICS.md only.

Rod end points from the joint-point table, the table chain as explicit 4x4 matrices of
Table IV; nothing from ``verne_post.kinematics``. Units mm and rad, base frame z down.
"""

from __future__ import annotations

import numpy as np

from verne_post.machine import Geometry


def rot_x(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    m = np.zeros((*np.shape(a), 4, 4))
    m[..., 0, 0] = m[..., 3, 3] = 1
    m[..., 1, 1], m[..., 1, 2], m[..., 2, 1], m[..., 2, 2] = c, -s, s, c
    return m


def rot_z(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    m = np.zeros((*np.shape(a), 4, 4))
    m[..., 2, 2] = m[..., 3, 3] = 1
    m[..., 0, 0], m[..., 0, 1], m[..., 1, 0], m[..., 1, 1] = c, -s, s, c
    return m


def trans(x: float | np.ndarray, y: float | np.ndarray, z: float | np.ndarray) -> np.ndarray:
    x, y, z = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float), np.asarray(z, float))
    m = np.zeros((*x.shape, 4, 4))
    m[..., [0, 1, 2, 3], [0, 1, 2, 3]] = 1
    m[..., 0, 3], m[..., 1, 3], m[..., 2, 3] = x, y, z
    return m


def table_transform(g: Geometry, theta1: np.ndarray, theta2: np.ndarray) -> np.ndarray:
    """bT_t = Tz(da) Rx(theta1) Tz(dt) Rx(pi) Rz(theta2)  (Table IV)."""
    n = np.shape(theta1)
    return (trans(0, 0, np.full(n, g.da)) @ rot_x(theta1) @ trans(0, 0, np.full(n, g.dt))
            @ rot_x(np.full(n, np.pi)) @ rot_z(theta2))


def platform_from_tool(g: Geometry, tip: np.ndarray, axis: np.ndarray, theta1: np.ndarray, theta2: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Platform centre (N, 3) in R_b and the platform's alpha for a tool pose in R_t and table angles."""
    p_table = np.concatenate([tip + g.delta * axis, np.ones((len(tip), 1))], axis=1)
    transform = table_transform(g, theta1, theta2)
    platform = np.einsum("nij,nj->ni", transform, p_table)[:, :3]
    # The platform's z axis is minus the tool axis (tool tip at (0, 0, Delta) in R_pl).
    z_axis = -np.einsum("nij,nj->ni", transform[:, :3, :3], axis)
    alpha = np.arctan2(-z_axis[:, 1], z_axis[:, 2])
    return platform, alpha


def rod_residuals(g: Geometry, platform: np.ndarray, alpha: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """|A B|^2 - L^2 (N, 4) for rods 1a, 1b, II, III from the joint-point table."""
    points = np.array([[g.D1_minus_d1, g.R1], [g.D1_minus_d1, -g.R1], [g.D2_minus_d2, -g.R2], [g.D2_minus_d2, g.R2]])
    sliders_y = np.array([g.r1, -g.r1, -g.r4, g.r4])
    slider_rho = rho[:, [0, 0, 1, 2]]
    lengths = np.array([g.L1, g.L1, g.L2, g.L3])
    c, s = np.cos(alpha)[:, None], np.sin(alpha)[:, None]
    bx = platform[:, :1] + points[:, 0]  # only the difference D - d enters
    by = platform[:, 1:2] + points[:, 1] * c
    bz = platform[:, 2:3] + points[:, 1] * s
    return bx**2 + (by - sliders_y) ** 2 + (bz - slider_rho) ** 2 - lengths**2


def coupling(g: Geometry, platform: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Eq. 6 as printed (the ellipse relation between xP, yP and alpha)."""
    x1, y = platform[..., 0] + g.D1_minus_d1, platform[..., 1]
    s2 = np.sin(alpha) ** 2
    c = np.cos(alpha)
    return (g.R1**2 * s2 * x1**2 + (g.r1**2 - 2 * g.R1 * g.r1 * c + g.R1**2) * y**2
            - g.R1**2 * s2 * (g.L1**2 - (g.R1**2 + g.r1**2 - 2 * g.R1 * g.r1 * c)))


def module_pose(g: Geometry, rho: np.ndarray, platform: np.ndarray, alpha: np.ndarray, iterations: int = 50
                ) -> tuple[np.ndarray, np.ndarray]:
    """Platform centre (N, 3) in R_b and alpha (N,) that close the four rods of the joint-point
    table at slider heights ``rho`` (N, 3): Newton's method on :func:`rod_residuals` from the
    start ``platform``, ``alpha`` (it picks the assembly; the equations decide the pose)."""
    points_y = np.array([g.R1, -g.R1, -g.R2, g.R2])
    sliders_y = np.array([g.r1, -g.r1, -g.r4, g.r4])
    dx = np.array([g.D1_minus_d1, g.D1_minus_d1, g.D2_minus_d2, g.D2_minus_d2])
    platform, alpha = platform.astype(float).copy(), alpha.astype(float).copy()
    for _ in range(iterations):
        f = rod_residuals(g, platform, alpha, rho)
        c, s = np.cos(alpha)[:, None], np.sin(alpha)[:, None]
        bx = platform[:, :1] + dx
        by = platform[:, 1:2] + points_y * c - sliders_y
        bz = platform[:, 2:3] + points_y * s - rho[:, [0, 0, 1, 2]]
        jac = 2 * np.stack([bx, by, bz, by * (-points_y * s) + bz * (points_y * c)], axis=-1)
        step = np.linalg.solve(jac, f[..., None])[..., 0]
        platform -= step[:, :3]
        alpha -= step[:, 3]
        if np.max(np.abs(step)) < 1e-12:
            break
    return platform, alpha


def tool_from_platform(g: Geometry, platform: np.ndarray, alpha: np.ndarray, theta1: np.ndarray, theta2: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Tool tip (N, 3) and axis in R_t: the tip at (0, 0, Delta) in R_pl = Trans(P) Rot(x, alpha),
    the axis minus the platform's z axis, brought into R_t by the inverse of Table IV's chain."""
    pose = trans(platform[:, 0], platform[:, 1], platform[:, 2]) @ rot_x(alpha)
    tip_base = np.einsum("nij,j->ni", pose, np.array([0.0, 0.0, g.delta, 1.0]))
    axis_base = -pose[:, :3, 2]
    inverse = np.linalg.inv(table_transform(g, theta1, theta2))
    return np.einsum("nij,nj->ni", inverse, tip_base)[:, :3], np.einsum("nij,nj->ni", inverse[:, :3, :3], axis_base)


def machine_tips(p: np.ndarray, joints: np.ndarray, tool_length: np.ndarray, platform: np.ndarray,
                 alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tool tips (N, 3) mm and axes in R_t of a VERNE with parameters ``p``: the 12 geometry
    values (mm, the machine file's order), the slider zeros (mm) and table-angle zeros (rad),
    true joint = reading + zero, at readings ``joints`` (N, 5) mm/rad with tools (N,) mm.
    ``platform``, ``alpha``: a nearby pose of the module to start Newton's method from."""
    true = joints + np.asarray(p[12:17])
    tips, axes = np.empty((len(joints), 3)), np.empty((len(joints), 3))
    for length in np.unique(tool_length):
        rows = tool_length == length
        g = Geometry(*(float(v) for v in p[:12]), tool_length=float(length))
        found, tilt = module_pose(g, true[rows, :3], platform[rows], alpha[rows])
        tips[rows], axes[rows] = tool_from_platform(g, found, tilt, true[rows, 3], true[rows, 4])
    return tips, axes
