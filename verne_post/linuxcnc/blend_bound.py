"""The LinuxCNC blend's deviation at a corner, estimated with a bound, without the full forward kinematics.

:func:`~verne_post.linuxcnc.blending.blend_deviation` places the tip at the samples s of the blend
q(s) = q_c - f1 (1 - s)^2 dq1 + f2 s^2 dq2 (joints mm and rad) by the full forward kinematics and
takes its largest distance D from the CL segments around the corner. Here D~ is found with a
bound E, |D~ - D| <= E, at a fraction of the cost, so that the full kinematics runs only where
D~ - E <= budget < D~ + E could go either way, or where the guards need D itself.

Only the parallel module is estimated: its pose m = (xP, yP, zP, alpha) (mm, rad), which depends
on the sliders alone. The blend lies in the plane of its two blocks, q(a, b) = q_c - a dq1 + b dq2
(a = f1 (1 - s)^2, b = f2 s^2), and m is known at the three block ends (the linearisation's IK,
checked on the closure equations eq. 3a-5) with its slider Jacobian
(:func:`~verne_post.kinematics.jacobian.closure_inverse`). m~ is the cubic Hermite interpolant
along each block (a or b alone) plus the mixed term a b d2m/da db (the mean of its two differences
of the Jacobians): a few multiplications per sample instead of the FK's secant iterations. The
table angles, the tool pose of m~ (eq. 32-33) and the distances to the CL segments are exact (sin
and cos of the table angles' small steps from their Taylor series, to 1e-16).

The bound. Phi(m) (mm^2), the closure residuals at the sample's sliders, is 0 at the true pose m*;
its derivative is 2 a(m) (a: the rods and their alpha terms). Norms count alpha as R1 alpha (mm):
D = diag(1, 1, 1, R1), |m| = |D m|, and Frobenius norms of matrices. By the mean value theorem
Phi(m~) = 2 a_bar (m~ - m*), a_bar the mean of a between m~ and m*. With a_c the corner's,
q = |D a_c^-1| |(a_bar - a_c) D^-1| < 1 (:func:`_contraction` bounds how far the rods and their
alpha terms can move from the corner's within the blocks' own travel, which the blend's poses,
within their halves, do not leave), m~ - m* = (I + r) v with v = a_c^-1 Phi(m~) / 2 and
|r| <= q / (1 - q). The tip moves with the platform by a rotation and with alpha by Delta (P to
tip), so each sample's tip is within
E_s = (|a_c^-1[P]| + Delta |a_c^-1[alpha]| + (1 + Delta / R1) |D a_c^-1| q / (1 - q)) |Phi(m~)| / 2
of the full kinematics' ([P]: the inverse's platform rows, [alpha] its alpha row), and the
distance to the CL path, 1-Lipschitz, within the same: E = max_s E_s + ``ROUNDING``. Where a
block end's pose fails the closure equations, q > ``MAX_CONTRACTION`` or a sample leaves the
machine's working mode, E is infinite (the full kinematics decides). Checked against the full
kinematics on thousands of random corners: tests/test_blending.py.
"""

from __future__ import annotations

import math

import numpy as np

from ..kinematics.geometry import Geometry
from ..kinematics.jacobian import closure_inverse
from ..kinematics.module import closure_ok
from ..machine import Machine
from ..motion.linearise import Blocks

#: mm: the full kinematics' own rounding (its secant stops at steps of 1e-15 rad) and this one's
#: (sin and cos of the table angles to ``TAYLOR_REMAINDER``).
ROUNDING = 1e-9
#: Largest q (module docstring) the bound is used with; beyond it the full kinematics decides.
MAX_CONTRACTION = 0.5
#: rad: the first Taylor term of sin and cos left out (a sample's angles from the corner's).
TAYLOR_REMAINDER = 1e-16
#: Corners per pass: the (samples, corners) arrays of a pass stay small (160 kB each).
CHUNK = 1024


def blend_estimate(machine: Machine, blocks: Blocks, corner: np.ndarray, f1: np.ndarray, f2: np.ndarray,
                   tool_length: np.ndarray, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(estimate, bound), (K,) mm each: the blend's largest distance from the CL path around each
    block end ``corner`` (K,) of ``blocks`` (module docstring), and how far it may be from the full
    kinematics' (inf: unknown). ``f1``/``f2`` (K,) the shares of the blocks before and after that
    the blend takes, ``tool_length`` (K,) mm, ``samples`` the blend's s."""
    g = machine.kinematic_geometry(0.0)
    joints = g.true_joints(blocks.joints)
    # the module at the block ends: pose, closure matrix inverse and slider Jacobian
    used = np.zeros(len(joints), bool)
    used[corner - 1] = used[corner] = used[corner + 1] = True
    rows = np.flatnonzero(used)
    platform, alpha = blocks.result.platform[rows], blocks.result.alpha[rows]
    with np.errstate(invalid="ignore"):
        known = np.all(np.isfinite(platform), axis=1) & np.isfinite(alpha)
        known[known] = closure_ok(g, platform[known], alpha[known], joints[rows[known], :3])
    inverse, jacobian = closure_inverse(g, platform, alpha, blocks.joints[rows, :3])
    known &= np.all(np.isfinite(inverse), axis=(0, 1))  # not at a singularity of the module
    pose = np.r_[platform.T, alpha[None]]  # (4, R)
    # the corners at other block ends are not estimated (their bound is infinite): zeros keep the
    # arithmetic quiet
    pose[:, ~known], inverse[:, :, ~known], jacobian[:, :, ~known] = 0.0, 0.0, 0.0
    at = [(np.cumsum(used) - 1)[corner + j] for j in (-1, 0, 1)]  # before, corner, after in rows
    q_c, d1, d2 = joints[corner], joints[corner] - joints[corner - 1], joints[corner + 1] - joints[corner]

    def along(jac: np.ndarray, d: np.ndarray) -> np.ndarray:
        """(4, K): d(pose) for the slider steps d (K, 5) by the Jacobians ``jac`` (4, 3, K)."""
        return jac[:, 0] * d[:, 0] + jac[:, 1] * d[:, 1] + jac[:, 2] * d[:, 2]

    m_1, m_c, m_2 = (pose[:, i] for i in at)
    j_1, j_c, j_2 = (jacobian[:, :, i] for i in at)
    c1, p1, c2, n2 = along(j_c, d1), along(j_1, d1), along(j_c, d2), along(j_2, d2)
    mixed = -0.5 * (along(j_2, d1) - c1 + c2 - along(j_1, d2))  # d2(pose)/da db
    # The interpolant's coefficients of (1, A, A^2, A^3, B, B^2, B^3, A B) (a = f1 A, b = f2 B): the
    # pose (alpha from the corner's) by cubic Hermite along each block, d(pose)/da = -c1 at a = 0 and
    # -p1 at a = 1. The joints are linear in A and B: q_c + A back + B ahead.
    k = len(corner)
    coefficients = np.zeros((8, 4, k))
    coefficients[0, :3] = m_c[:3]
    coefficients[1], coefficients[4] = -f1 * c1, f2 * c2
    coefficients[2] = f1 * f1 * (3.0 * (m_1 - m_c) + 2.0 * c1 + p1)
    coefficients[3] = f1 * f1 * f1 * (2.0 * (m_c - m_1) - c1 - p1)
    coefficients[5] = f2 * f2 * (3.0 * (m_2 - m_c) - 2.0 * c2 - n2)
    coefficients[6] = f2 * f2 * f2 * (2.0 * (m_c - m_2) + c2 + n2)
    coefficients[7] = f1 * f2 * mixed
    back, ahead = -f1[:, None] * d1, f2[:, None] * d2
    # the bound's factor of |Phi| (module docstring)
    inv = inverse[:, :, at[1]]
    norm_p = np.sqrt(np.sum(inv[:3] ** 2, axis=(0, 1)))
    norm_alpha = np.sqrt(np.sum(inv[3] ** 2, axis=0))
    scaled = np.sqrt(norm_p**2 + (g.R1 * norm_alpha) ** 2)  # |a_c^-1| with alpha in mm (R1 alpha)
    q = scaled * _contraction(g, pose, d1, d2, at)
    delta = g.spindle_nose + tool_length
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = 0.5 * (norm_p + delta * norm_alpha + (1.0 + delta / g.R1) * scaled * q / (1.0 - q))
    valid = known[at[0]] & known[at[1]] & known[at[2]] & (q <= MAX_CONTRACTION) & np.isfinite(factor)
    a, b = (1.0 - samples) ** 2, samples**2
    basis = np.stack([np.ones_like(a), a, a**2, a**3, b, b**2, b**3, a * b], axis=1)  # (S, 8)
    turns = [(angle, np.cos(angle), np.sin(angle)) for angle in (m_c[3], q_c[:, 3], q_c[:, 4])]
    tips = (blocks.tip[corner - 1], blocks.tip[corner], blocks.tip[corner + 1])
    estimate, residual = np.empty(k), np.empty(k)
    for start in range(0, k, CHUNK):
        part = slice(start, start + CHUNK)
        estimate[part], residual[part], working = _samples(
            g, basis, np.ascontiguousarray(coefficients[:, :, part]), (q_c[part], back[part], ahead[part]),
            [(angle[part], cos[part], sin[part]) for angle, cos, sin in turns], delta[part],
            [tip[part] for tip in tips])
        valid[part] &= working
    bound = factor * residual + ROUNDING
    return estimate, np.where(valid & np.isfinite(estimate) & np.isfinite(bound), bound, np.inf)


def _samples(g: Geometry, basis: np.ndarray, coefficients: np.ndarray, lines: tuple[np.ndarray, ...],
             turns: list[tuple[np.ndarray, np.ndarray, np.ndarray]], delta: np.ndarray,
             tips: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For K corners: the blend's largest distance from the CL path (mm), the largest closure residual
    |Phi| (mm^2) and whether every sample is in the machine's working mode, each (K,), from the
    interpolant (``basis`` (S, 8) and ``coefficients`` (8, 4, K): :func:`blend_estimate`), the
    joints' ``lines`` (true q_c, back, ahead: (K, 5) each, q = q_c + A back + B ahead), the corner's
    (alpha, theta1, theta2) as (angle, cos, sin), ``delta`` (P to tip, mm) and the CL ``tips``
    before, at and after the corner."""
    # einsum, not matmul: OpenBLAS's threads, spinning between calls, made these 50 times slower on 2 busy cores
    pose = np.einsum("sn,nk->sk", basis, coefficients.reshape(8, -1))
    x, y, z, d_alpha = pose.reshape(len(basis), 4, -1).transpose(1, 0, 2)
    q_c, back, ahead = lines
    a, b = basis[:, 1:2], basis[:, 4:5]
    w1, w2, w3 = (z - (q_c[:, i] + a * back[:, i] + b * ahead[:, i]) for i in range(3))  # zP - rho_i
    d_theta1, d_theta2 = (a * back[:, i] + b * ahead[:, i] for i in (3, 4))
    ca, sa = _turned(*turns[0], d_alpha)
    # the closure residuals (eq. 3a, 3b, 4, 5; kinematics.module.closure_residuals) at the sliders
    x1, x2 = (x + g.D1_minus_d1) ** 2, (x + g.D2_minus_d2) ** 2
    y1, z1, y2, z2 = g.R1 * ca - g.r1, g.R1 * sa, g.R2 * ca - g.r4, g.R2 * sa
    phi2 = ((x1 + (y + y1) ** 2 + (w1 + z1) ** 2 - g.L1**2) ** 2 + (x1 + (y - y1) ** 2 + (w1 - z1) ** 2 - g.L1**2) ** 2
            + (x2 + (y - y2) ** 2 + (w2 - z2) ** 2 - g.L2**2) ** 2
            + (x2 + (y + y2) ** 2 + (w3 + z2) ** 2 - g.L3**2) ** 2)
    # the machine's working mode (kinematics.module.is_working_mode): every slider above its
    # platform points, no rod crossing in leg I
    working = np.all((w1 > 0.0) & (w2 > z2) & (w3 > -z2) & (g.R1 * ca > g.r1), axis=0)
    # the tool pose (eq. 32-33; kinematics.full.tool_pose) relative to the corner's CL tip
    c1, s1 = _turned(*turns[1], d_theta1)
    c2, s2 = _turned(*turns[2], d_theta2)
    cp, sp = ca * c1 + sa * s1, sa * c1 - ca * s1  # phi1 = alpha - theta1
    lateral = delta * sp - c1 * y - s1 * (z - g.da)
    before, tip, after = tips
    px = c2 * x + s2 * lateral - tip[:, 0]
    py = c2 * lateral - s2 * x - tip[:, 1]
    pz = s1 * y - c1 * z + g.da * c1 - delta * cp + (g.dt - tip[:, 2])
    nearest = None
    for other in (before, after):
        e = other - tip
        length2 = np.einsum("ij,ij->i", e, e)
        u = np.clip((px * e[:, 0] + py * e[:, 1] + pz * e[:, 2]) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
        distance2 = (px - u * e[:, 0]) ** 2 + (py - u * e[:, 1]) ** 2 + (pz - u * e[:, 2]) ** 2
        nearest = distance2 if nearest is None else np.minimum(nearest, distance2)
    return np.sqrt(nearest.max(axis=0)), np.sqrt(phi2.max(axis=0)), working


def _turned(angle: np.ndarray, cos: np.ndarray, sin: np.ndarray, delta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin of ``angle`` (K,) + ``delta`` (S, K) (rad), given ``angle``'s ``cos`` and ``sin``:
    by the sum formula, with sin and cos of the small ``delta`` from as many terms of their Taylor
    series as leave the next below ``TAYLOR_REMAINDER`` (a few multiplications instead of a libm
    call; libm beyond 0.1 rad)."""
    largest = np.abs(delta).max(initial=0.0)
    if not largest <= 0.1:
        turned = angle + delta
        return np.cos(turned), np.sin(turned)
    d2 = delta * delta
    # sin: delta (1 - d2/(2 3) (1 - d2/(4 5) ...)), cos: 1 - d2/(1 2) (1 - d2/(3 4) ...) to the powers
    # 2 n + 1 and 2 n; the first left out at most largest^(2 n + 2) / (2 n + 2)!
    terms = next(n for n in range(1, 6) if largest ** (2 * n + 2) / math.factorial(2 * n + 2) < TAYLOR_REMAINDER)
    sin_delta, cos_delta = 1.0, 1.0
    for i in range(terms, 0, -1):
        sin_delta = 1.0 - d2 / ((2 * i) * (2 * i + 1)) * sin_delta
        cos_delta = 1.0 - d2 / ((2 * i - 1) * (2 * i)) * cos_delta
    sin_delta = delta * sin_delta
    return cos * cos_delta - sin * sin_delta, sin * cos_delta + cos * sin_delta


def _contraction(geom: Geometry, pose: np.ndarray, d1: np.ndarray, d2: np.ndarray, at: list[np.ndarray]) -> np.ndarray:
    """(K,): a bound of |(a - a_c) D^-1| (Frobenius, D = diag(1, 1, 1, R1): alpha as R1 alpha, mm) over
    the blend (module docstring): each rod (mm) moves at most by the platform's and its slider's
    travel and R alpha's turn between the corner and the farther block end, its alpha term (mm^2)
    by R times that plus the rod's length times R alpha's turn. The blend stays within the
    blocks' halves; the whole blocks' travel covers its bends."""
    g = geom
    travel_p = np.maximum(np.linalg.norm(pose[:3, at[0]] - pose[:3, at[1]], axis=0),
                          np.linalg.norm(pose[:3, at[2]] - pose[:3, at[1]], axis=0))
    turn = np.maximum(np.abs(pose[3, at[0]] - pose[3, at[1]]), np.abs(pose[3, at[2]] - pose[3, at[1]]))
    slider = np.maximum(np.abs(d1[:, :3]), np.abs(d2[:, :3])).max(axis=1)
    total = np.zeros(len(turn))
    for radius, length in ((g.R1, g.L1), (g.R1, g.L1), (g.R2, g.L2), (g.R2, g.L3)):
        rod = travel_p + radius * turn + slider
        total += rod**2 + ((radius * rod + (length + rod) * radius * turn) / g.R1) ** 2
    return np.sqrt(total)
