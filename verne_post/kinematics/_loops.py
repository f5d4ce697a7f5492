"""The compiled loops of :mod:`.kernels` (numba ``@njit``); imported only when that route runs.

Each loop does the arithmetic of its numpy twin (named in its docstring) for one pose at a time,
with the same fixed iteration counts; where it departs from the twin, its docstring says how.
Units and frames are the twin's.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .adjugate import fill_adjugate
from .tolerances import CLOSURE_TOL, POLE_EPS

NUMBA_VERSION = str(numba.__version__)

# error_model="numpy": a division by zero gives inf/NaN as in numpy, not an exception; cache=True
# keeps the machine code in __pycache__, so a later process only loads it
_jit = numba.njit(cache=True, nogil=True, error_model="numpy")

#: Poses solved side by side: Newton's steps run over a block at a time, so the processor
#: overlaps their square roots and divisions (in SIMD lanes) instead of waiting on each pose's.
_BLOCK = 64


@_jit
def _wrap(angle: float) -> float:
    """An angle in [-2 pi, 2 pi] (rad) wrapped to [-pi, pi) (full.wrap_angle without the modulo)."""
    if angle >= math.pi:
        return angle - 2.0 * math.pi
    if angle < -math.pi:
        return angle + 2.0 * math.pi
    return angle


@_jit
def _turned(cos_a: float, sin_a: float, turn: float) -> tuple[float, float]:
    """(cos, sin) of an angle (rad) turned by ``turn`` (|turn| <= 0.2 rad): Taylor series of cos
    and sin of the turn to the 12th and 11th power (remainders below 2e-19), no libm call."""
    t2 = turn * turn
    cos_t = 1.0 + t2 * (-1 / 2 + t2 * (1 / 24 + t2 * (-1 / 720 + t2 * (1 / 40320 + t2 * (-1 / 3628800
                                                                                          + t2 / 479001600)))))
    sin_t = turn * (1.0 + t2 * (-1 / 6 + t2 * (1 / 120 + t2 * (-1 / 5040 + t2 * (1 / 362880
                                                                                 - t2 / 39916800)))))
    return cos_a * cos_t - sin_a * sin_t, sin_a * cos_t + cos_a * sin_t


@_jit
def _closure_and_mode(c, platform_x, platform_y, platform_z, cos_a, sin_a, rho1, rho2, rho3):
    """module.closure_ok and module.is_working_mode of one pose (true slider positions)."""
    d1, d2, big_r1, r1, l1, big_r2, r4, l2, l3 = c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8]
    x1, x2 = platform_x + d1, platform_x + d2
    y, z = platform_y, platform_z
    e1 = x1**2 + (y + big_r1 * cos_a - r1) ** 2 + (z + big_r1 * sin_a - rho1) ** 2 - l1**2
    e2 = x1**2 + (y - big_r1 * cos_a + r1) ** 2 + (z - big_r1 * sin_a - rho1) ** 2 - l1**2
    e3 = x2**2 + (y - big_r2 * cos_a + r4) ** 2 + (z - big_r2 * sin_a - rho2) ** 2 - l2**2
    e4 = x2**2 + (y + big_r2 * cos_a - r4) ** 2 + (z + big_r2 * sin_a - rho3) ** 2 - l3**2
    closed = (abs(e1) <= CLOSURE_TOL * l1**2 and abs(e2) <= CLOSURE_TOL * l1**2
              and abs(e3) <= CLOSURE_TOL * l2**2 and abs(e4) <= CLOSURE_TOL * l3**2)
    s = big_r2 * sin_a
    working = (rho1 - z < 0.0 and rho2 - z + s < 0.0 and rho3 - z - s < 0.0 and big_r1 * cos_a > r1)
    return closed and working


@_jit
def _ik_working(c, tip, axis, pair, theta2_at_pole, joints, alpha_out, phi_out, platform, coefficients, good,
                candidates):
    """full.machine_ik_working's fast route (numpy twin: full._newton_route): Newton on eq. 31,
    sliders, verification.

    Fills what the twin returns: joints (N, 5) true positions, alpha (N,), phi (N, 2), platform
    (N, 3), coefficients (N, 4) = (xP, A, B, X1^2), good (N,) and candidates (N,). Newton's six steps
    are the twin's; cos and sin of alpha follow each step by :func:`_turned` instead of libm.
    """
    d1, d2, big_r1, r1, l1, big_r2, r4, l2, l3 = c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8]
    delta, da, dt, alpha_max = c[9], c[10], c[11], c[12]
    k = l1**2 - big_r1**2 - r1**2
    two_rr = 2.0 * big_r1 * r1
    rr_sq = big_r1**2 + r1**2
    lane_a, lane_b, lane_x1sq = np.empty(_BLOCK), np.empty(_BLOCK), np.empty(_BLOCK)
    lane_alpha, lane_cos, lane_sin = np.empty(_BLOCK), np.empty(_BLOCK), np.empty(_BLOCK)
    for start in range(0, tip.shape[0], _BLOCK):
        size = min(_BLOCK, tip.shape[0] - start)
        for j in range(size):
            n = start + j
            ai, aj, ak = axis[n, 0], axis[n, 1], axis[n, 2]
            sin_phi1 = math.sqrt(ai * ai + aj * aj)
            phi1 = math.atan2(sin_phi1, ak)
            off_pole = sin_phi1 > POLE_EPS
            # cos and sin of phi1 and phi2 from the axis itself (what cos(atan2(...)) computes)
            norm = math.sqrt(sin_phi1 * sin_phi1 + ak * ak)
            c1, s1 = ak / norm, sin_phi1 / norm
            if off_pole:
                phi2 = math.atan2(ai, -aj)
                c2, s2 = -aj / sin_phi1, ai / sin_phi1
            else:
                phi2 = -theta2_at_pole[n]
                c2, s2 = math.cos(phi2), math.sin(phi2)
            if pair[n] < 0:
                phi1, s1 = -phi1, -s1
                if off_pole:
                    phi2, c2, s2 = phi2 + math.pi, -c2, -s2
            phi_out[n, 0], phi_out[n, 1] = phi1, _wrap(phi2)
            px, py, pz = tip[n, 0] + delta * ai, tip[n, 1] + delta * aj, tip[n, 2] + delta * ak
            vy, vz = s2 * px - c2 * py, dt - pz
            xp, a, b = c2 * px + s2 * py, vy * c1 + vz * s1, vy * s1 - vz * c1
            x1sq = (xp + d1) ** 2
            coefficients[n, 0], coefficients[n, 1], coefficients[n, 2], coefficients[n, 3] = xp, a, b, x1sq
            alpha = -a * (big_r1 - r1) / (b * (big_r1 - r1) + big_r1 * math.sqrt(k + two_rr - x1sq))
            lane_a[j], lane_b[j], lane_x1sq[j] = a, b, x1sq
            lane_alpha[j], lane_cos[j], lane_sin[j] = alpha, math.cos(alpha), math.sin(alpha)
        for _ in range(6):
            for j in range(size):
                a, b, ca, sa = lane_a[j], lane_b[j], lane_cos[j], lane_sin[j]
                y, dy = a * ca + b * sa, b * ca - a * sa
                gq = math.sqrt(rr_sq - two_rr * ca)
                h = math.sqrt(k + two_rr * ca - lane_x1sq[j])  # NaN where leg I does not reach
                f = y * gq + big_r1 * sa * h
                inverse = 1.0 / (gq * h)  # 1/gq = h inverse, 1/h = gq inverse: one division for both
                df = dy * gq + 0.5 * two_rr * sa * (y * h - big_r1 * sa * gq) * inverse + big_r1 * ca * h
                step = f / df
                step = 0.2 if step > 0.2 else (-0.2 if step < -0.2 else step)  # NaN stays NaN
                lane_alpha[j] = lane_alpha[j] - step
                lane_cos[j], lane_sin[j] = _turned(ca, sa, -step)
        for j in range(size):
            n = start + j
            alpha, ca, sa = lane_alpha[j], lane_cos[j], lane_sin[j]
            xp = coefficients[n, 0]
            platform_y, platform_z = lane_a[j] * ca + lane_b[j] * sa, da - lane_b[j] * ca + lane_a[j] * sa
            x1, x2 = xp + d1, xp + d2
            # a negative radicand (leg out of reach) gives NaN
            rho1 = platform_z - math.sqrt(l1**2 - (rr_sq - two_rr * ca) - x1**2 - platform_y**2)
            rho2 = platform_z - big_r2 * sa - math.sqrt(l2**2 - x2**2 - (platform_y - big_r2 * ca + r4) ** 2)
            rho3 = platform_z + big_r2 * sa - math.sqrt(l3**2 - x2**2 - (platform_y + big_r2 * ca - r4) ** 2)
            ok = math.isfinite(rho1) and math.isfinite(rho2) and math.isfinite(rho3) and abs(alpha) < alpha_max
            if ok:
                ok = _closure_and_mode(c, xp, platform_y, platform_z, ca, sa, rho1, rho2, rho3)
            joints[n, 0], joints[n, 1], joints[n, 2] = rho1, rho2, rho3
            joints[n, 3], joints[n, 4] = alpha - phi_out[n, 0], -phi_out[n, 1]
            alpha_out[n] = alpha
            platform[n, 0], platform[n, 1], platform[n, 2] = xp, platform_y, platform_z
            good[n] = ok
            candidates[n] = (not ok and coefficients[n, 3] <= k + two_rr and math.isfinite(
                tip[n, 0] + tip[n, 1] + tip[n, 2] + axis[n, 0] + axis[n, 1] + axis[n, 2]))


_adjugate4 = _jit(fill_adjugate)


@_jit
def _inverse_condition(m, adj, det):
    """jacobian._inverse_condition of one matrix: 4 |det| / (|M|_F |adj|_F), NaN as 0."""
    m_sq, adj_sq = 0.0, 0.0
    for i in range(4):
        for j in range(4):
            m_sq += m[i, j] * m[i, j]
            adj_sq += adj[i, j] * adj[i, j]
    value = 4.0 * abs(det) / math.sqrt(m_sq * adj_sq)
    if math.isnan(value):
        return 0.0
    return min(value, 1.7976931348623157e308)


@_jit
def _margins(c, joints, platform, alpha, out):
    """jacobian.margins of N working-mode poses (true joints): out (N, 4) = serial, parallel,
    machine, rod clearance, formed as the twin forms them."""
    d1, d2, big_r1, r1, l1, big_r2, r4, l2, l3 = c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8]
    delta, da = c[9], c[10]
    a, adj, jac = np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4))
    d_pose = np.empty((4, 3))
    offsets = (big_r1, -big_r1, -big_r2, big_r2)
    sliders_y = (r1, -r1, -r4, r4)
    lengths = (l1, l1, l2, l3)
    dxs = (d1, d1, d2, d2)
    for n in range(alpha.shape[0]):
        ca, sa = math.cos(alpha[n]), math.sin(alpha[n])
        x, y, z = platform[n, 0], platform[n, 1], platform[n, 2]
        serial = math.inf
        for k in range(4):
            slider = 0 if k < 2 else k - 1
            ux = (x + dxs[k]) / lengths[k]
            uy = (y + offsets[k] * ca - sliders_y[k]) / lengths[k]
            uz = (z + offsets[k] * sa - joints[n, slider]) / lengths[k]
            a[k, 0], a[k, 1], a[k, 2] = ux, uy, uz
            a[k, 3] = (-uy * offsets[k] * sa + uz * offsets[k] * ca) / big_r1
            serial = min(serial, abs(uz))
        det = _adjugate4(a, adj)
        parallel = _inverse_condition(a, adj, det)
        for r in range(4):
            d_pose[r, 0] = (adj[r, 0] * a[0, 2] + adj[r, 1] * a[1, 2]) / det
            d_pose[r, 1] = adj[r, 2] * a[2, 2] / det
            d_pose[r, 2] = adj[r, 3] * a[3, 2] / det
        for col in range(3):
            d_pose[3, col] /= big_r1
        t1 = joints[n, 3]
        c1, s1 = math.cos(t1), math.sin(t1)
        phi1 = alpha[n] - t1
        cp, sp = math.cos(phi1), math.sin(phi1)
        zr = z - da
        for col in range(3):
            jac[0, col] = d_pose[0, col]
            jac[1, col] = -c1 * d_pose[1, col] - s1 * d_pose[2, col] + delta * cp * d_pose[3, col]
            jac[2, col] = s1 * d_pose[1, col] - c1 * d_pose[2, col] + delta * sp * d_pose[3, col]
            jac[3, col] = delta * d_pose[3, col]
        jac[0, 3] = 0.0
        jac[1, 3] = (-delta * cp + s1 * y - c1 * zr) / delta
        jac[2, 3] = (c1 * y + s1 * zr - delta * sp) / delta
        jac[3, 3] = -1.0
        for i in range(4):
            for j in range(4):
                v = jac[i, j]
                jac[i, j] = 0.0 if math.isnan(v) else max(min(v, 1.7976931348623157e308), -1.7976931348623157e308)
        machine = 0.0
        if parallel > 0:
            machine = _inverse_condition(jac, adj, _adjugate4(jac, adj))
        out[n, 0], out[n, 1], out[n, 2], out[n, 3] = serial, parallel, machine, big_r1 * ca - r1


@_jit
def _working_branch(c, rho1, rho2, rho3, ca, sa):
    """module._working_branch of one pose at a trial alpha given by its cosine and sine: (xP, yP,
    zP) mm and eq. 13's residual (mm^2). One division by the Gram determinant, not three."""
    d1, d2, big_r1, r1, l1, big_r2, r4, l2, l3 = c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8]
    ux = -d2 + d1
    w = big_r2 * ca - r4
    uz, vz = rho2 + big_r2 * sa - rho1, rho3 - big_r2 * sa - rho1
    ra2 = l1**2 - big_r1**2 - r1**2 + 2.0 * big_r1 * r1 * ca
    uu, vv, uv = ux * ux + w * w + uz * uz, ux * ux + w * w + vz * vz, ux * ux - w * w + uz * vz
    b2, b3 = 0.5 * (ra2 - l2**2 + uu), 0.5 * (ra2 - l3**2 + vv)
    inverse_gram = 1.0 / (uu * vv - uv * uv)
    lam, mu = (b2 * vv - b3 * uv) * inverse_gram, (b3 * uu - b2 * uv) * inverse_gram
    nx, ny, nz = w * vz + w * uz, uz * ux - ux * vz, -2.0 * ux * w
    px, py, pz = lam * ux + mu * ux, lam * w - mu * w, lam * uz + mu * vz
    sign = 1.0 if nz > 0 else (-1.0 if nz < 0 else (0.0 if nz == 0 else math.nan))
    nu = math.sqrt((ra2 - px * px - py * py - pz * pz) * inverse_gram) * sign
    x, y, z = px + nu * nx - d1, py + nu * ny, pz + nu * nz + rho1
    return x, y, z, y * (big_r1 * ca - r1) - big_r1 * sa * (rho1 - z)


@_jit
def _fk_working(c, joints, alpha_guess, warm, platform, alpha_out, good, tip, axis):
    """module._module_fk_working's secant route and full.tool_pose for N joint sets (true
    positions; (N, 3) sliders alone: no tool pose): fills platform (N, 3) mm, alpha (N,) rad,
    good (N,) (a verified working assembly), tip (N, 3) mm and axis (N, 3), table frame. The
    secant's steps are the twin's; cos and sin of the trial alpha follow each step by
    :func:`_turned` (libm for a step over 0.2 rad), and the tool pose takes cos and sin of phi1 =
    alpha - theta1 from theirs."""
    delta, da, dt = c[9], c[10], c[11]
    for n in range(joints.shape[0]):
        rho1, rho2, rho3 = joints[n, 0], joints[n, 1], joints[n, 2]
        a0 = alpha_guess[n] if warm else 0.0
        if math.isnan(a0):
            a0 = 0.0
        elif math.isinf(a0):
            a0 = 1.7976931348623157e308 if a0 > 0 else -1.7976931348623157e308
        first = 1e-4 if warm else 0.02
        a1 = a0 + first
        ca, sa = math.cos(a0), math.sin(a0)
        f0 = _working_branch(c, rho1, rho2, rho3, ca, sa)[3]
        ca, sa = _turned(ca, sa, first)
        x, y, z, f1 = _working_branch(c, rho1, rho2, rho3, ca, sa)
        for _ in range(12):
            slope = f1 - f0
            step = f1 * (a1 - a0) / slope if slope != 0 else 0.0
            if math.isnan(step):
                step = 0.0
            step = 0.3 if step > 0.3 else (-0.3 if step < -0.3 else step)
            a0, f0 = a1, f1
            a1 -= step
            if abs(step) <= 0.2:
                ca, sa = _turned(ca, sa, -step)
            else:
                ca, sa = math.cos(a1), math.sin(a1)
            x, y, z, f1 = _working_branch(c, rho1, rho2, rho3, ca, sa)
            if abs(step) < 1e-15:
                break
        alpha = a1 if abs(a1) <= math.pi else math.atan2(sa, ca)
        ok = math.isfinite(x) and math.isfinite(y) and math.isfinite(z)
        if ok:
            ok = _closure_and_mode(c, x, y, z, ca, sa, rho1, rho2, rho3)
        if not ok:
            x, y, z, alpha = math.nan, math.nan, math.nan, math.nan
        platform[n, 0], platform[n, 1], platform[n, 2] = x, y, z
        alpha_out[n] = alpha
        good[n] = ok
        if joints.shape[1] < 5:
            continue
        theta1, theta2 = joints[n, 3], joints[n, 4]
        c1, s1, c2, s2 = math.cos(theta1), math.sin(theta1), math.cos(theta2), math.sin(theta2)
        cos_phi1, sin_phi1 = ca * c1 + sa * s1, sa * c1 - ca * s1
        if not ok or not math.isfinite(theta1):
            cos_phi1, sin_phi1 = math.nan, math.nan
        lateral = delta * sin_phi1 - c1 * y - s1 * (z - da)
        tip[n, 0] = c2 * x + s2 * lateral
        tip[n, 1] = -s2 * x + c2 * lateral
        tip[n, 2] = s1 * y - c1 * z + da * c1 - delta * cos_phi1 + dt
        axis[n, 0] = -sin_phi1 * s2
        axis[n, 1] = -sin_phi1 * c2
        axis[n, 2] = cos_phi1 + 0.0 * theta2


LOOPS = {"ik_working": _ik_working, "margins": _margins, "fk_working": _fk_working}


