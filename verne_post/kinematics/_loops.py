"""The compiled loops of :mod:`.kernels` (numba ``@njit``); imported only when that route runs.

Each loop does the arithmetic of its numpy twin (named in its docstring), a pose or a block of
poses at a time, with the same fixed iteration counts; where it departs from the twin, its
docstring says how. The IK runs a block of 64 poses in SIMD lanes (:func:`_solve_block`: no libm
call inside, so LLVM vectorises its loops); ``api.inverse_kinematics`` is one loop over blocks
(:func:`_inverse_kinematics`: both angle pairs, the test of their candidates for the exact route,
the statuses, margins and choice), where the numpy route makes dozens of whole-array passes.
Units and frames are the twin's.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .adjugate import adjugate_entries
from .tolerances import CLOSURE_TOL, POLE_EPS

NUMBA_VERSION = str(numba.__version__)

# error_model="numpy": a division by zero gives inf/NaN as in numpy, not an exception; cache=True
# keeps the machine code in __pycache__, so a later process only loads it
_jit = numba.njit(cache=True, nogil=True, error_model="numpy")
# the small helpers inlined into their callers' loops, which then run in SIMD lanes
_inline = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")

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


@_inline
def _turned(cos_a: float, sin_a: float, turn: float) -> tuple[float, float]:
    """(cos, sin) of an angle (rad) turned by ``turn`` (|turn| <= 0.2 rad): Taylor series of cos
    and sin of the turn to the 12th and 11th power (remainders below 2e-19), no libm call."""
    t2 = turn * turn
    cos_t = 1.0 + t2 * (-1 / 2 + t2 * (1 / 24 + t2 * (-1 / 720 + t2 * (1 / 40320 + t2 * (-1 / 3628800
                                                                                          + t2 / 479001600)))))
    sin_t = turn * (1.0 + t2 * (-1 / 6 + t2 * (1 / 120 + t2 * (-1 / 5040 + t2 * (1 / 362880
                                                                                 - t2 / 39916800)))))
    return cos_a * cos_t - sin_a * sin_t, sin_a * cos_t + cos_a * sin_t


@_inline
def _closure_and_mode(c, platform_x, platform_y, platform_z, cos_a, sin_a, rho1, rho2, rho3):
    """module.closure_ok and module.is_working_mode of one pose (true slider positions)."""
    d1, d2, big_r1, r1, l1, big_r2, r4, l2, l3 = c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8]
    x1, x2 = platform_x + d1, platform_x + d2
    y, z = platform_y, platform_z
    e1 = x1**2 + (y + big_r1 * cos_a - r1) ** 2 + (z + big_r1 * sin_a - rho1) ** 2 - l1**2
    e2 = x1**2 + (y - big_r1 * cos_a + r1) ** 2 + (z - big_r1 * sin_a - rho1) ** 2 - l1**2
    e3 = x2**2 + (y - big_r2 * cos_a + r4) ** 2 + (z - big_r2 * sin_a - rho2) ** 2 - l2**2
    e4 = x2**2 + (y + big_r2 * cos_a - r4) ** 2 + (z + big_r2 * sin_a - rho3) ** 2 - l3**2
    closed = ((abs(e1) <= CLOSURE_TOL * l1**2) & (abs(e2) <= CLOSURE_TOL * l1**2)
              & (abs(e3) <= CLOSURE_TOL * l2**2) & (abs(e4) <= CLOSURE_TOL * l3**2))
    s = big_r2 * sin_a
    working = (rho1 - z < 0.0) & (rho2 - z + s < 0.0) & (rho3 - z - s < 0.0) & (big_r1 * cos_a > r1)
    return closed & working


# Cephes' atan (S. L. Moshier, Cephes Math Library, atan.c): a rational function of degree 9/10
# on |u| <= 0.66, about 1 ulp there
_ATAN_P = (-8.750608600031904122785e-1, -1.615753718733365076637e1, -7.500855792314704667340e1,
           -1.228866684490136173410e2, -6.485021904942025371773e1)
_ATAN_Q = (2.485846490142306297962e1, 1.650270098316988542046e2, 4.328810604912902668951e2,
           4.853903996359136964868e2, 1.945506571482613964425e2)
_MOREBITS = 6.123233995736765886130e-17  # pi/4's double rounding error


@_inline
def _atan2(y: float, x: float) -> float:
    """atan2(y, x) (rad) without a libm call, so a loop of them runs in SIMD lanes: within 2 ulp of
    libm's (tests/test_kernels.py). NaN where both are 0 (libm gives 0 or pi): callers take those
    poses (the pole) by libm."""
    ay, ax = abs(y), abs(x)
    t = min(ay, ax) / max(ay, ax)  # in [0, 1]; reduced to |u| <= 0.66 by atan t = pi/4 + atan u
    big = t > 0.66
    u = (t - 1.0) / (t + 1.0) if big else t
    z = u * u
    p = (((_ATAN_P[0] * z + _ATAN_P[1]) * z + _ATAN_P[2]) * z + _ATAN_P[3]) * z + _ATAN_P[4]
    q = ((((z + _ATAN_Q[0]) * z + _ATAN_Q[1]) * z + _ATAN_Q[2]) * z + _ATAN_Q[3]) * z + _ATAN_Q[4]
    r = u + u * (z * p / q)
    r = 0.25 * math.pi + (r + 0.5 * _MOREBITS) if big else r
    r = 0.5 * math.pi - r if ay > ax else r
    r = math.pi - r if x < 0.0 else r
    return math.copysign(r, y)


# Rows of a block's lanes (:func:`_solve_block`): one row a quantity, a column a pose of the block
_TIP, _AXIS, _FLIP = 0, 3, 6  # tip x y z mm, axis i j k, 1.0 where the angle pair is -1
_PHI1, _PHI2, _C1, _S1, _C2, _S2 = 7, 8, 9, 10, 11, 12  # phi1, phi2 (rad, phi2 unwrapped), cos and sin
_XP, _A, _B, _X1SQ = 13, 14, 15, 16  # xP mm, A, B mm, X1^2 mm^2 (full._platform_coefficients)
_ALPHA, _COS, _SIN = 17, 18, 19  # alpha (rad), its cos and sin
_Y, _Z, _OK = 20, 21, 22  # yP, zP mm, 1.0 where verified a working solution
_LANES = 23


@_inline
def _gather(tip, axis, pair, start, size, lane):
    """Poses start .. start + size of tip (N, 3) mm and axis (N, 3) into the lanes' rows (the
    loops of :func:`_solve_block` read them with unit stride, so they run in SIMD lanes); pair
    (N,) +1 / -1 or, one for all, (1,)."""
    for j in range(size):
        n = start + j
        lane[_TIP, j], lane[_TIP + 1, j], lane[_TIP + 2, j] = tip[n, 0], tip[n, 1], tip[n, 2]
        lane[_AXIS, j], lane[_AXIS + 1, j], lane[_AXIS + 2, j] = axis[n, 0], axis[n, 1], axis[n, 2]
        lane[_FLIP, j] = pair[n if pair.shape[0] > 1 else 0] < 0


@_inline
def _solve_block(c, theta2_at_pole, start, size, lane, rho):
    """full._newton_route of the gathered poses of one block (true joints): Newton on eq. 31,
    sliders (rho (3, block) mm), verification, into the lanes' rows. Newton's six steps are the
    twin's; each step goes over the whole block in SIMD lanes, which needs loops without libm
    calls: phi1 and phi2 by :func:`_atan2`, their cosines and sines from the axis itself, cos and
    sin of alpha by :func:`_turned` (its start and each step); the rare poses those do not cover
    (the pole, a start tilt over 0.2 rad) take libm in a loop of their own."""
    d1, d2, big_r1, r1, l1, big_r2, r4, l2, l3 = c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8]
    delta, da, dt, alpha_max = c[9], c[10], c[11], c[12]
    k = l1**2 - big_r1**2 - r1**2
    two_rr = 2.0 * big_r1 * r1
    rr_sq = big_r1**2 + r1**2
    for j in range(size):
        ai, aj, ak = lane[_AXIS, j], lane[_AXIS + 1, j], lane[_AXIS + 2, j]
        sin_phi1 = math.sqrt(ai * ai + aj * aj)
        # cos and sin of phi1 and phi2 from the axis itself (what cos(atan2(...)) computes)
        norm = math.sqrt(sin_phi1 * sin_phi1 + ak * ak)
        phi1, phi2 = _atan2(sin_phi1, ak), _atan2(ai, -aj)
        s1, c2, s2 = sin_phi1 / norm, -aj / sin_phi1, ai / sin_phi1
        flipped = lane[_FLIP, j] != 0.0
        lane[_PHI1, j] = -phi1 if flipped else phi1
        lane[_PHI2, j] = phi2 + math.pi if flipped else phi2
        lane[_C1, j] = ak / norm
        lane[_S1, j] = -s1 if flipped else s1
        lane[_C2, j] = -c2 if flipped else c2
        lane[_S2, j] = -s2 if flipped else s2
    for j in range(size):
        ai, aj = lane[_AXIS, j], lane[_AXIS + 1, j]
        sin_phi1 = math.sqrt(ai * ai + aj * aj)
        if not sin_phi1 > POLE_EPS:  # the pole (or NaN): theta2 from the caller
            phi1 = math.atan2(sin_phi1, lane[_AXIS + 2, j])
            phi2 = -theta2_at_pole[start + j]
            lane[_PHI1, j] = -phi1 if lane[_FLIP, j] != 0.0 else phi1
            lane[_PHI2, j], lane[_C2, j], lane[_S2, j] = phi2, math.cos(phi2), math.sin(phi2)
    for j in range(size):
        c1, s1, c2, s2 = lane[_C1, j], lane[_S1, j], lane[_C2, j], lane[_S2, j]
        px = lane[_TIP, j] + delta * lane[_AXIS, j]
        py = lane[_TIP + 1, j] + delta * lane[_AXIS + 1, j]
        pz = lane[_TIP + 2, j] + delta * lane[_AXIS + 2, j]
        vy, vz = s2 * px - c2 * py, dt - pz
        xp, a, b = c2 * px + s2 * py, vy * c1 + vz * s1, vy * s1 - vz * c1
        x1sq = (xp + d1) ** 2
        alpha = -a * (big_r1 - r1) / (b * (big_r1 - r1) + big_r1 * math.sqrt(k + two_rr - x1sq))
        lane[_XP, j], lane[_A, j], lane[_B, j], lane[_X1SQ, j], lane[_ALPHA, j] = xp, a, b, x1sq, alpha
        lane[_COS, j], lane[_SIN, j] = _turned(1.0, 0.0, alpha)
    for j in range(size):
        alpha = lane[_ALPHA, j]
        if not abs(alpha) <= 0.2:  # beyond the series' reach (or NaN)
            lane[_COS, j], lane[_SIN, j] = math.cos(alpha), math.sin(alpha)
    for _ in range(6):
        for j in range(size):
            a, b, ca, sa = lane[_A, j], lane[_B, j], lane[_COS, j], lane[_SIN, j]
            y, dy = a * ca + b * sa, b * ca - a * sa
            gq = math.sqrt(rr_sq - two_rr * ca)
            h = math.sqrt(k + two_rr * ca - lane[_X1SQ, j])  # NaN where leg I does not reach
            f = y * gq + big_r1 * sa * h
            inverse = 1.0 / (gq * h)  # 1/gq = h inverse, 1/h = gq inverse: one division for both
            df = dy * gq + 0.5 * two_rr * sa * (y * h - big_r1 * sa * gq) * inverse + big_r1 * ca * h
            step = f / df
            step = 0.2 if step > 0.2 else (-0.2 if step < -0.2 else step)  # NaN stays NaN
            lane[_ALPHA, j] = lane[_ALPHA, j] - step
            lane[_COS, j], lane[_SIN, j] = _turned(ca, sa, -step)
    for j in range(size):
        ca, sa = lane[_COS, j], lane[_SIN, j]
        platform_y, platform_z = lane[_A, j] * ca + lane[_B, j] * sa, da - lane[_B, j] * ca + lane[_A, j] * sa
        x1, x2 = lane[_XP, j] + d1, lane[_XP, j] + d2
        lane[_Y, j], lane[_Z, j] = platform_y, platform_z
        # a negative radicand (leg out of reach) gives NaN
        rho1 = platform_z - math.sqrt(l1**2 - (rr_sq - two_rr * ca) - x1**2 - platform_y**2)
        rho2 = platform_z - big_r2 * sa - math.sqrt(l2**2 - x2**2 - (platform_y - big_r2 * ca + r4) ** 2)
        rho3 = platform_z + big_r2 * sa - math.sqrt(l3**2 - x2**2 - (platform_y + big_r2 * ca - r4) ** 2)
        rho[0, j], rho[1, j], rho[2, j] = rho1, rho2, rho3
        ok = (math.isfinite(rho1) & math.isfinite(rho2) & math.isfinite(rho3) & (abs(lane[_ALPHA, j]) < alpha_max)
              & _closure_and_mode(c, lane[_XP, j], platform_y, platform_z, ca, sa, rho1, rho2, rho3))
        lane[_OK, j] = 1.0 if ok else 0.0


@_inline
def _candidate(c, lane, j) -> bool:
    """Whether pose j of a solved block goes on to the exact route: not verified, leg I within
    reach at some tilt, tip and axis finite (full._newton_route's candidates)."""
    k_two_rr = c[4] ** 2 - c[2] ** 2 - c[3] ** 2 + 2.0 * c[2] * c[3]
    return (lane[_OK, j] == 0.0 and lane[_X1SQ, j] <= k_two_rr and math.isfinite(
        lane[_TIP, j] + lane[_TIP + 1, j] + lane[_TIP + 2, j] + lane[_AXIS, j] + lane[_AXIS + 1, j]
        + lane[_AXIS + 2, j]))


@_jit
def _ik_working(c, tip, axis, pair, theta2_at_pole, joints, alpha_out, phi_out, platform, coefficients, good,
                candidates):
    """full.machine_ik_working's fast route (numpy twin: full._newton_route) by blocks of poses
    (:func:`_solve_block`). Fills what the twin returns: joints (N, 5) true positions, alpha (N,),
    phi (N, 2), platform (N, 3), coefficients (N, 4) = (xP, A, B, X1^2), good (N,) and candidates
    (N,)."""
    lane, rho = np.empty((_LANES, _BLOCK)), np.empty((3, _BLOCK))
    for start in range(0, tip.shape[0], _BLOCK):
        size = min(_BLOCK, tip.shape[0] - start)
        _gather(tip, axis, pair, start, size, lane)
        _solve_block(c, theta2_at_pole, start, size, lane, rho)
        for j in range(size):
            n = start + j
            alpha, phi1, phi2 = lane[_ALPHA, j], lane[_PHI1, j], _wrap(lane[_PHI2, j])
            joints[n, 0], joints[n, 1], joints[n, 2] = rho[0, j], rho[1, j], rho[2, j]
            joints[n, 3], joints[n, 4] = alpha - phi1, -phi2
            phi_out[n, 0], phi_out[n, 1] = phi1, phi2
            alpha_out[n] = alpha
            platform[n, 0], platform[n, 1], platform[n, 2] = lane[_XP, j], lane[_Y, j], lane[_Z, j]
            for i in range(4):
                coefficients[n, i] = lane[_XP + i, j]
            good[n] = lane[_OK, j] != 0.0
            candidates[n] = _candidate(c, lane, j)


@_inline
def _times(p, q, out):
    """out = p q, ascending coefficients (len(out) = len(p) + len(q) - 1)."""
    out[:] = 0.0
    for i in range(p.shape[0]):
        for j in range(q.shape[0]):
            out[i + j] += p[i] * q[j]


@_inline
def _settled_one(c, a, b, x1sq, alpha, rho1, rho2, rho3, pieces, scratch) -> bool:
    """full.machine_ik_working's test of one candidate for the exact route (numpy twin: its
    _signed_coupling residual test and full._only_working_root): True where Newton's root alpha
    (rad) of eq. 31 is a root where a leg does not reach (a slider rho mm NaN) and surely eq. 31's
    only root of the working assembly in (-alpha_max, alpha_max), so that the all-solutions route
    would find no working solution. a, b (mm) and x1sq (mm^2) as full._platform_coefficients. The
    sextic's coefficients come from the tan-half-angle forms of cos and sin multiplied out here
    (the twin's TrigPoly arithmetic in another order: the certificate is sound either way).
    ``pieces``: the edges (pieces + 1,) rad, their cos, sin and tan(edge / 2), and (pieces, 7, 7)
    trigpoly._vincent of each piece; ``scratch`` (12, 9)."""
    edges, cos_edges, sin_edges, t_edges, vincent = pieces
    big_r1, r1, l1, alpha_max = c[2], c[3], c[4], c[12]
    k = l1**2 - big_r1**2 - r1**2
    two_rr = 2.0 * big_r1 * r1
    # the signed eq. 31 at Newton's root: is it a root, in (-alpha_max, alpha_max), a leg out of reach?
    ca, sa = math.cos(alpha), math.sin(alpha)
    yg = (a * ca + b * sa) * math.sqrt(big_r1**2 + r1**2 - two_rr * ca)
    residual = yg + big_r1 * sa * math.sqrt(k + two_rr * ca - x1sq)
    if not (abs(residual) <= 1e-9 * (abs(yg) + big_r1) and abs(alpha) < alpha_max
            and not (math.isfinite(rho1) and math.isfinite(rho2) and math.isfinite(rho3))):
        return False
    # eq. 31 squared (full._coupling) as a sextic in t = tan(alpha / 2): cos = (1 - t^2) / (1 + t^2),
    # sin = 2 t / (1 + t^2), so each factor a numerator over a power of 1 + t^2
    cos_t, sin_t, one = scratch[0, :3], scratch[1, :3], scratch[2, :3]
    cos_t[0], cos_t[1], cos_t[2] = 1.0, 0.0, -1.0
    sin_t[0], sin_t[1], sin_t[2] = 0.0, 2.0, 0.0
    one[0], one[1], one[2] = 1.0, 0.0, 1.0
    y, leg, gq = scratch[3, :3], scratch[4, :3], scratch[5, :3]
    y_sq, s_sq, term, poly, q = scratch[6, :5], scratch[7, :5], scratch[8, :7], scratch[9, :7], scratch[10, :7]
    f = scratch[11, :edges.shape[0]]
    for i in range(3):
        y[i] = a * cos_t[i] + b * sin_t[i]
        leg[i] = (x1sq - k) * one[i] - two_rr * cos_t[i]
        gq[i] = (big_r1**2 + r1**2) * one[i] - two_rr * cos_t[i]
    _times(sin_t, sin_t, s_sq)
    _times(s_sq, leg, term)
    _times(y, y, y_sq)
    _times(gq, y_sq, poly)
    scale = 0.0
    for i in range(7):
        poly[i] += big_r1**2 * term[i]
        scale = max(scale, abs(poly[i]))
    for i in range(7):
        poly[i] = poly[i] / scale
    for j in range(edges.shape[0]):
        value = 0.0
        for i in range(6, -1, -1):
            value = value * t_edges[j] + poly[i]
        if not (abs(value) > 1e-9 and abs(alpha - edges[j]) > 1e-9):
            return False
        f[j] = ((a * cos_edges[j] + b * sin_edges[j]) * math.sqrt(big_r1**2 + r1**2 - two_rr * cos_edges[j])
                + big_r1 * sin_edges[j] * math.sqrt(k + two_rr * cos_edges[j] - x1sq))
    for j in range(vincent.shape[0]):
        q[:] = 0.0
        for m in range(7):  # q = V p, a column at a time: seven independent sums
            for i in range(7):
                q[i] += vincent[j, i, m] * poly[m]
        size = 0.0
        for i in range(7):
            size = max(size, abs(q[i]))
        count = 0  # trigpoly.roots_within: Descartes' rule of signs on q
        for i in range(7):
            if not abs(q[i]) > 1e-9 * size:
                count = -1
        if count == 0:
            for i in range(6):
                count += (q[i] > 0) != (q[i + 1] > 0)
            count = count if count <= 1 else -1
        if edges[j] < alpha <= edges[j + 1]:  # Newton's root's piece
            if count != 1:
                return False
        elif not (count == 0 or (count == 1 and f[j] * f[j + 1] > 0)):
            return False
    return True


@_jit
def _settled(c, coefficients, alpha, joints, candidates, pieces, settled):
    """:func:`_settled_one` of every candidate (N,) of full.machine_ik_working's fast route:
    coefficients (N, 4) = (xP, A, B, X1^2), alpha (N,) rad, true joints (N, 5) mm, rad."""
    scratch = np.empty((12, 9))
    for n in range(alpha.shape[0]):
        settled[n] = candidates[n] and _settled_one(c, coefficients[n, 1], coefficients[n, 2], coefficients[n, 3],
                                                    alpha[n], joints[n, 0], joints[n, 1], joints[n, 2], pieces,
                                                    scratch)


_adjugate = _inline(adjugate_entries)
_LARGEST = 1.7976931348623157e308


@_inline
def _condition(sum_sq: float, adj_sum_sq: float, det: float) -> float:
    """jacobian._inverse_condition of one matrix from its and its adjugate's sums of squares:
    4 |det| / (|M|_F |adj|_F), NaN as 0."""
    value = 4.0 * abs(det) / math.sqrt(sum_sq * adj_sum_sq)
    return 0.0 if math.isnan(value) else min(value, _LARGEST)


@_inline
def _clamped(value: float) -> float:
    """numpy.nan_to_num of one number: NaN as 0, +-inf as the largest finite float."""
    return 0.0 if math.isnan(value) else max(min(value, _LARGEST), -_LARGEST)


@_inline
def _sum_of_squares(e) -> float:
    """The sum of the squares of an adjugate's 16 entries (:func:`_adjugate`), in the order of the
    twin's sum (written out: a loop inside would keep the loop around it from running in lanes)."""
    return (e[0] * e[0] + e[1] * e[1] + e[2] * e[2] + e[3] * e[3] + e[4] * e[4] + e[5] * e[5] + e[6] * e[6]
            + e[7] * e[7] + e[8] * e[8] + e[9] * e[9] + e[10] * e[10] + e[11] * e[11] + e[12] * e[12]
            + e[13] * e[13] + e[14] * e[14] + e[15] * e[15])


@_inline
def _margins_of(c, rho1, rho2, rho3, x, y, z, ca, sa, c1, s1, cp, sp):
    """jacobian.margins of one working-mode pose: true sliders mm, platform mm, and the cosines and
    sines of alpha, theta1 and phi1 = alpha - theta1 (true): (serial, parallel, machine, rod
    clearance mm), formed as the twin forms them but with every matrix entry a local number (kept
    in registers; a loop of poses runs in SIMD lanes) and one reciprocal of the determinant
    instead of twelve divisions."""
    d1, d2, big_r1, r1, l1, big_r2, r4, l2, l3 = c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8]
    delta, da = c[9], c[10]
    # A: a row a rod (1a, 1b, II, III): (xP + dx, yP + Y cos - slider y, zP + Y sin - rho) / L, and
    # the alpha column by R1 (jacobian.margins' rods)
    a00, a01, a02 = (x + d1) / l1, (y + big_r1 * ca - r1) / l1, (z + big_r1 * sa - rho1) / l1
    a10, a11, a12 = (x + d1) / l1, (y + -big_r1 * ca - -r1) / l1, (z + -big_r1 * sa - rho1) / l1
    a20, a21, a22 = (x + d2) / l2, (y + -big_r2 * ca - -r4) / l2, (z + -big_r2 * sa - rho2) / l2
    a30, a31, a32 = (x + d2) / l3, (y + big_r2 * ca - r4) / l3, (z + big_r2 * sa - rho3) / l3
    a03 = (-a01 * big_r1 * sa + a02 * big_r1 * ca) / big_r1
    a13 = (-a11 * -big_r1 * sa + a12 * -big_r1 * ca) / big_r1
    a23 = (-a21 * -big_r2 * sa + a22 * -big_r2 * ca) / big_r1
    a33 = (-a31 * big_r2 * sa + a32 * big_r2 * ca) / big_r1
    serial = min(min(min(min(math.inf, abs(a02)), abs(a12)), abs(a22)), abs(a32))
    e = _adjugate(a00, a01, a02, a03, a10, a11, a12, a13, a20, a21, a22, a23, a30, a31, a32, a33)
    sum_sq = (a00 * a00 + a01 * a01 + a02 * a02 + a03 * a03 + a10 * a10 + a11 * a11 + a12 * a12 + a13 * a13
              + a20 * a20 + a21 * a21 + a22 * a22 + a23 * a23 + a30 * a30 + a31 * a31 + a32 * a32 + a33 * a33)
    adj_sq = _sum_of_squares(e)
    parallel = _condition(sum_sq, adj_sq, e[16])
    # d(xP, yP, zP, alpha)/d rho = -diag(1, 1, 1, 1/R1) A^-1 B, B[k, slider] = -u_z of rod k
    inverse_det = 1.0 / e[16]
    p0 = ((e[0] * a02 + e[1] * a12) * inverse_det, e[2] * a22 * inverse_det, e[3] * a32 * inverse_det)
    p1 = ((e[4] * a02 + e[5] * a12) * inverse_det, e[6] * a22 * inverse_det, e[7] * a32 * inverse_det)
    p2 = ((e[8] * a02 + e[9] * a12) * inverse_det, e[10] * a22 * inverse_det, e[11] * a32 * inverse_det)
    p3 = ((e[12] * a02 + e[13] * a12) * inverse_det / big_r1, e[14] * a22 * inverse_det / big_r1,
          e[15] * a32 * inverse_det / big_r1)
    zr = z - da
    j00, j01, j02 = _clamped(p0[0]), _clamped(p0[1]), _clamped(p0[2])
    j10 = _clamped(-c1 * p1[0] - s1 * p2[0] + delta * cp * p3[0])
    j11 = _clamped(-c1 * p1[1] - s1 * p2[1] + delta * cp * p3[1])
    j12 = _clamped(-c1 * p1[2] - s1 * p2[2] + delta * cp * p3[2])
    j20 = _clamped(s1 * p1[0] - c1 * p2[0] + delta * sp * p3[0])
    j21 = _clamped(s1 * p1[1] - c1 * p2[1] + delta * sp * p3[1])
    j22 = _clamped(s1 * p1[2] - c1 * p2[2] + delta * sp * p3[2])
    j30, j31, j32 = _clamped(delta * p3[0]), _clamped(delta * p3[1]), _clamped(delta * p3[2])
    j13 = _clamped((-delta * cp + s1 * y - c1 * zr) / delta)
    j23 = _clamped((c1 * y + s1 * zr - delta * sp) / delta)
    f = _adjugate(j00, j01, j02, 0.0, j10, j11, j12, j13, j20, j21, j22, j23, j30, j31, j32, -1.0)
    jac_sq = (j00 * j00 + j01 * j01 + j02 * j02 + 0.0 + j10 * j10 + j11 * j11 + j12 * j12 + j13 * j13
              + j20 * j20 + j21 * j21 + j22 * j22 + j23 * j23 + j30 * j30 + j31 * j31 + j32 * j32 + 1.0)
    f_sq = _sum_of_squares(f)
    machine = _condition(jac_sq, f_sq, f[16]) if parallel > 0 else 0.0
    return serial, parallel, machine, big_r1 * ca - r1


@_jit
def _margins(c, joints, platform, alpha, out):
    """jacobian.margins of N working-mode poses (true joints): out (N, 4) = serial, parallel,
    machine, rod clearance (:func:`_margins_of`)."""
    for n in range(alpha.shape[0]):
        t1, phi1 = joints[n, 3], alpha[n] - joints[n, 3]
        out[n, 0], out[n, 1], out[n, 2], out[n, 3] = _margins_of(
            c, joints[n, 0], joints[n, 1], joints[n, 2], platform[n, 0], platform[n, 1], platform[n, 2],
            math.cos(alpha[n]), math.sin(alpha[n]), math.cos(t1), math.sin(t1), math.cos(phi1), math.sin(phi1))


@_inline
def _wrap_mod(angle: float) -> float:
    """full.wrap_angle: (angle + pi) mod 2 pi - pi, rad, Python's float modulo as numpy's (which
    leaves a number in [0, 2 pi) as it is: no fmod call for those)."""
    shifted = angle + math.pi
    if not 0.0 <= shifted < 2.0 * math.pi:
        shifted = shifted % (2.0 * math.pi)
    return shifted - math.pi


@_inline
def _within(joints, n, lower, upper) -> bool:
    """api.within_limits of row n of (N, 5) finite readings (mm, rad)."""
    inside = True
    for k in range(5):
        inside = inside & (joints[n, k] >= lower[k]) & (joints[n, k] <= upper[k])
    return inside


@_inline
def _cost(status: int, theta1: float, theta2: float, hint: float, has_hint: bool) -> float:
    """api.inverse_kinematics' cost of one solution: the status's penalty, then |theta1| (rad), or
    with a hint theta2's distance to it."""
    preference = abs((hint + _wrap_mod(theta2 - hint)) - hint) if has_hint else abs(theta1)
    penalty = 0.0 if status == 0 else (1e9 if status == 1 else (1e6 if status == 2 else 1e3))
    return penalty + _clamped(preference)


@_inline
def _choose(c, lower, upper, thresholds, joints, alpha, phi, cos_alpha, found_by_pair, reachable, platform, hint,
            has_hint, n, joints_out, alpha_out, phi_out, pair_out, status_out, margins_out, platform_out):
    """api.inverse_kinematics' choice between the two angle pairs' solutions of pose n (index 0:
    pair +1, 1: -1): joints (2, 5) readings mm/rad, alpha (2,) rad, phi (2, 2) rad, cos_alpha (2,),
    found_by_pair (2, 4) their margins, reachable (2,), platform (2, 3) mm; theta2 hint rad. As the
    twin: each solution's status by reach, travel and rod clearance; the cheaper (:func:`_cost`)
    chosen and its margins' status taken; where they make it singular and the other pair is ok, the
    other's margins too, and the cheaper taken. Writes row n of the chosen solution's joints
    (theta2 unwrapped near the hint), alpha, phi, pair (+1/-1), status (api.Status), margins (4, N)
    (serial, parallel, machine, rod clearance mm; NaN where unreachable) and platform."""
    serial_min, parallel_min, machine_min, rod_min = thresholds[0], thresholds[1], thresholds[2], thresholds[3]
    # api._status without margins: unreachable (1), beyond travel (the joints of a reachable pose
    # are finite) or rod clearance (2), else ok (0)
    inside = (reachable[0] and _within(joints, 0, lower, upper), reachable[1] and _within(joints, 1, lower, upper))
    plain = (1 if not reachable[0] else (2 if not inside[0] or c[2] * cos_alpha[0] - c[3] < rod_min else 0),
             1 if not reachable[1] else (2 if not inside[1] or c[2] * cos_alpha[1] - c[3] < rod_min else 0))
    best = 0 if (_cost(plain[0], joints[0, 3], joints[0, 4], hint, has_hint)
                 <= _cost(plain[1], joints[1, 3], joints[1, 4], hint, has_hint)) else 1
    chosen, status, best_cost = 0, 0, 0.0
    found = (math.nan, math.nan, math.nan, math.nan)
    for attempt in range(2):
        p = best if attempt == 0 else 1 - best
        if attempt == 1 and not (status == 3 and plain[p] == 0):
            break
        if reachable[p]:
            trial_found = (found_by_pair[p, 0], found_by_pair[p, 1], found_by_pair[p, 2], found_by_pair[p, 3])
            trial = 3 if ((trial_found[0] < serial_min) | (trial_found[1] < parallel_min)
                          | (trial_found[2] < machine_min)) else 0
            if not inside[p] or trial_found[3] < rod_min:
                trial = 2
        else:
            trial_found = (math.nan, math.nan, math.nan, math.nan)
            trial = 1
        trial_cost = _cost(trial, joints[p, 3], joints[p, 4], hint, has_hint)
        if attempt == 0 or trial_cost < best_cost:
            chosen, status, best_cost, found = p, trial, trial_cost, trial_found
    for k in range(4):
        joints_out[n, k] = joints[chosen, k]
        margins_out[k, n] = found[k]
    joints_out[n, 4] = hint + _wrap_mod(joints[chosen, 4] - hint)  # full.unwrap_near
    for k in range(3):
        platform_out[n, k] = platform[chosen, k]
    alpha_out[n], phi_out[n, 0], phi_out[n, 1] = alpha[chosen], phi[chosen, 0], phi[chosen, 1]
    pair_out[n] = 1 if chosen == 0 else -1
    status_out[n] = status


@_jit
def _inverse_kinematics(c, offsets, has_offsets, lower, upper, thresholds, tip, axis, theta2_at_pole, hint,
                        has_hint, pieces, joints_out, alpha_out, phi_out, pair_out, status_out, margins_out,
                        platform_out, exact):
    """api.inverse_kinematics of N poses in one pass (numpy twin: api._inverse_kinematics_stepwise
    over full.machine_ik_working): both angle pairs solved a block at a time (:func:`_solve_block`),
    their candidates tested (:func:`_settled_one`), the choice made (:func:`_choose`). tip (N, 3)
    mm, axis (N, 3) unit, table frame; theta2 at the pole (N,) true rad, hint (N,) reading rad;
    offsets (5,) mm, rad; joint bounds (5,); thresholds: serial, parallel, machine, rod clearance
    (mm). Fills the chosen solutions' rows but where exact (N,) is True: a candidate that only the
    all-solutions route (numpy) settles; the caller solves those poses the twin's way."""
    lanes, rho = np.empty((2, _LANES, _BLOCK)), np.empty((2, 3, _BLOCK))
    found = np.empty((2, 4, _BLOCK))
    one_pair = (np.ones(1), -np.ones(1))
    joints, alpha, phi, cos_alpha = np.empty((2, 5)), np.empty(2), np.empty((2, 2)), np.empty(2)
    reachable, platform, found_by_pair = np.empty(2, np.bool_), np.empty((2, 3)), np.empty((2, 4))
    settle_scratch = np.empty((12, 9))
    for start in range(0, tip.shape[0], _BLOCK):
        size = min(_BLOCK, tip.shape[0] - start)
        for p in range(2):
            lane, sliders, margins = lanes[p], rho[p], found[p]
            _gather(tip, axis, one_pair[p], start, size, lane)
            _solve_block(c, theta2_at_pole, start, size, lane, sliders)
            for j in range(size):  # both pairs' margins in lanes (garbage where a pair does not reach: not read)
                ca, sa, cp, sp = lane[_COS, j], lane[_SIN, j], lane[_C1, j], lane[_S1, j]
                serial, parallel, machine, rod = _margins_of(
                    c, sliders[0, j], sliders[1, j], sliders[2, j], lane[_XP, j], lane[_Y, j], lane[_Z, j], ca, sa,
                    ca * cp + sa * sp, sa * cp - ca * sp, cp, sp)  # theta1 = alpha - phi1
                margins[0, j], margins[1, j], margins[2, j], margins[3, j] = serial, parallel, machine, rod
        for j in range(size):
            n = start + j
            exact[n] = False
            for p in range(2):
                lane = lanes[p]
                ok = lane[_OK, j] != 0.0
                if not ok and _candidate(c, lane, j) and not _settled_one(
                        c, lane[_A, j], lane[_B, j], lane[_X1SQ, j], lane[_ALPHA, j], rho[p, 0, j], rho[p, 1, j],
                        rho[p, 2, j], pieces, settle_scratch):
                    exact[n] = True
                reachable[p] = ok
                alpha[p] = lane[_ALPHA, j] if ok else math.nan
                cos_alpha[p] = lane[_COS, j]
                phi[p, 0], phi[p, 1] = lane[_PHI1, j], _wrap(lane[_PHI2, j])
                true = (rho[p, 0, j], rho[p, 1, j], rho[p, 2, j], alpha[p] - phi[p, 0], -phi[p, 1])
                for k in range(5):  # Geometry.readings of full.machine_ik_working's joints, NaN where unreachable
                    value = true[k] if ok else math.nan
                    joints[p, k] = value - offsets[k] if has_offsets else value
                for k in range(4):
                    found_by_pair[p, k] = found[p, k, j]
                platform[p, 0] = lane[_XP, j]
                platform[p, 1], platform[p, 2] = (lane[_Y, j], lane[_Z, j]) if ok else (math.nan, math.nan)
            if not exact[n]:
                _choose(c, lower, upper, thresholds, joints, alpha, phi, cos_alpha, found_by_pair, reachable, platform,
                        hint[n], has_hint, n, joints_out, alpha_out, phi_out, pair_out, status_out, margins_out,
                        platform_out)


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
        a0 = _clamped(alpha_guess[n]) if warm else 0.0
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


LOOPS = {"ik_working": _ik_working, "margins": _margins, "fk_working": _fk_working, "settled": _settled,
         "inverse_kinematics": _inverse_kinematics}


