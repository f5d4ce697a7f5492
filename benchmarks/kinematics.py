"""Kinematics throughput on one core, side by side with a per-point Newton-Raphson baseline.

The paper says the real VERNE controller solves its kinematics iteratively (Newton-Raphson on
the closure equations). The baseline here does exactly that, point by point, on a sample of
the same poses; the closed-form paths run vectorised over all of them.

    python benchmarks/kinematics.py [--poses 1000000] [--baseline 3000]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import verne_post as vp  # noqa: E402
from verne_post.api import Status, classify, pose_margins  # noqa: E402
from verne_post.kinematics import (  # noqa: E402
    kernels,
    machine_fk_all,
    machine_fk_working,
    machine_ik_all,
    machine_ik_working,
    margins,
    wrap_angle,
)


def usable_poses(machine: vp.Machine, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n random joint sets with status ok, and their tool poses (tip mm, axis), table frame."""
    rng = np.random.default_rng(seed)
    lower = np.array([0.0, 0.0, 0.0, -np.pi / 2, -np.pi])
    upper = np.array([1300.0, 1300.0, 1300.0, np.pi / 2, np.pi])
    chunks, total = [], 0
    while total < n:
        joints = lower + (upper - lower) * rng.random((n, 5))
        fk = vp.forward_kinematics(machine, joints)
        ok = classify(machine, joints, fk.reachable, pose_margins(machine, joints, fk.platform, fk.alpha,
                                                                    fk.reachable)) == Status.OK
        chunks.append(joints[ok])
        total += int(ok.sum())
    joints = np.concatenate(chunks)[:n]
    fk = vp.forward_kinematics(machine, joints)
    return joints, fk.tip, fk.axis


def rate(function, n: int, repeat: int = 3) -> float:
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        function()
        best = min(best, time.perf_counter() - start)
    return n / best


# ------------------------------------------------------------------ Newton-Raphson baseline
# Plain-float Python, as lean as a per-point solver gets: closure equations (eq. 3a, 3b, 4, 5),
# forward-difference Jacobian, 4x4 solve, stop when the step is below 1e-10.


def _closure(g: vp.Geometry, x: float, y: float, z: float, alpha: float, r1: float, r2: float, r3: float
             ) -> list[float]:
    c, s = math.cos(alpha), math.sin(alpha)
    x1, x2 = x + g.D1_minus_d1, x + g.D2_minus_d2
    return [
        x1 * x1 + (y + g.R1 * c - g.r1) ** 2 + (z + g.R1 * s - r1) ** 2 - g.L1 * g.L1,
        x1 * x1 + (y - g.R1 * c + g.r1) ** 2 + (z - g.R1 * s - r1) ** 2 - g.L1 * g.L1,
        x2 * x2 + (y - g.R2 * c + g.r4) ** 2 + (z - g.R2 * s - r2) ** 2 - g.L2 * g.L2,
        x2 * x2 + (y + g.R2 * c - g.r4) ** 2 + (z + g.R2 * s - r3) ** 2 - g.L3 * g.L3,
    ]


def _newton(residual, x: list[float]) -> list[float]:
    h = 1e-6
    for _ in range(50):
        r = residual(x)
        jac = np.empty((4, 4))
        for k in range(4):
            shifted = list(x)
            shifted[k] += h
            rk = residual(shifted)
            for i in range(4):
                jac[i, k] = (rk[i] - r[i]) / h
        dx = np.linalg.solve(jac, r)
        x = [x[i] - float(dx[i]) for i in range(4)]
        if max(abs(float(d)) for d in dx) < 1e-10:
            break
    return x


def newton_ik(g: vp.Geometry, tip: np.ndarray, axis: np.ndarray, pair: int) -> list[float]:
    """(rho1, rho2, rho3, theta1) for one tool pose; theta2 = -phi2 (eq. 26) of the given angle pair."""
    phi1 = pair * math.atan2(math.hypot(axis[0], axis[1]), axis[2])
    phi2 = math.atan2(axis[0], -axis[1]) + (math.pi if pair < 0 else 0.0)
    c2, s2 = math.cos(phi2), math.sin(phi2)
    px, py, pz = (float(tip[k] + g.delta * axis[k]) for k in range(3))
    vx, vy, vz = c2 * px + s2 * py, s2 * px - c2 * py, g.dt - pz

    def residual(q: list[float]) -> list[float]:
        c1, s1 = math.cos(q[3]), math.sin(q[3])
        return _closure(g, vx, c1 * vy - s1 * vz, g.da + s1 * vy + c1 * vz, q[3] + phi1, q[0], q[1], q[2])

    return _newton(residual, [600.0, 600.0, 600.0, -phi1])


def newton_fk(g: vp.Geometry, rho: np.ndarray) -> list[float]:
    """(xP, yP, zP, alpha) for one set of sliders, from a fixed start below the sliders."""
    r1, r2, r3 = (float(v) for v in rho)
    return _newton(lambda p: _closure(g, p[0], p[1], p[2], p[3], r1, r2, r3), [0.0, 0.0, 1400.0, 0.0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--poses", type=int, default=1_000_000)
    parser.add_argument("--baseline", type=int, default=3_000, help="poses for the per-point Newton baseline")
    parser.add_argument("--all-solutions", type=int, default=20_000, help="poses for the all-solutions paths")
    args = parser.parse_args()
    machine = vp.load_machine()
    geom = machine.kinematic_geometry()
    print(f"generating {args.poses} random usable poses (status ok, joint space sampled uniformly)...")
    joints, tip, axis = usable_poses(machine, args.poses)
    pair = np.where(wrap_angle(vp.forward_kinematics(machine, joints).alpha - joints[:, 3]) >= 0, 1, -1)

    n = len(tip)
    warm = vp.forward_kinematics(machine, joints).alpha + np.random.default_rng(1).normal(0.0, 1e-3, n)
    fk = vp.forward_kinematics(machine, joints)
    paths = {  # name: (call, repeats)
        "working-mode IK (closed form, vectorised)": (lambda: machine_ik_working(geom, tip, axis, pair=pair), 3),
        "  inverse_kinematics API (pairs, status, margins)": (lambda: vp.inverse_kinematics(machine, tip, axis), 3),
        "  margins of the working-mode poses": (lambda: margins(geom, joints, fk.platform, fk.alpha), 3),
        "working-mode FK (vectorised)": (lambda: machine_fk_working(geom, joints), 3),
        "  the same started from a neighbour's tilt": (lambda: machine_fk_working(geom, joints, warm), 3),
    }
    routes: dict[str, dict[str, float]] = {}
    for name in ("numpy", "numba"):
        os.environ[kernels.ROUTE_VARIABLE] = name
        kernels._numba_kernels.cache_clear()
        if kernels.route().split()[0] != name:
            continue  # numba not installed
        for path, (call, repeat) in paths.items():
            rate(call, n, repeat=1)  # the first call of a route compiles or loads its loops
            routes.setdefault(path, {})[name] = rate(call, n, repeat=repeat)
    os.environ.pop(kernels.ROUTE_VARIABLE)
    kernels._numba_kernels.cache_clear()
    m = args.all_solutions
    ik_all_rate = rate(lambda: machine_ik_all(geom, tip[:m], axis[:m]), m, repeat=1)
    fk_all_rate = rate(lambda: machine_fk_all(geom, joints[:m]), m, repeat=1)

    b = args.baseline
    start = time.perf_counter()
    ik_newton = np.array([newton_ik(geom, tip[k], axis[k], int(pair[k])) for k in range(b)])
    newton_ik_rate = b / (time.perf_counter() - start)
    start = time.perf_counter()
    fk_newton = np.array([newton_fk(geom, joints[k, :3]) for k in range(b)])
    newton_fk_rate = b / (time.perf_counter() - start)
    fast = machine_ik_working(geom, tip[:b], axis[:b], pair=pair[:b])
    ik_newton[:, 3] = wrap_angle(ik_newton[:, 3])
    ik_agree = np.mean(np.max(np.abs(ik_newton - fast.joints[:, :4]), axis=1) < 1e-6)
    fk_agree = np.mean(np.max(np.abs(fk_newton[:, :3] - machine_fk_working(geom, joints[:b]).platform), axis=1)
                       < 1e-6)

    print(f"\n{'path, per second on one core':<52}{'numpy':>12}{'numba':>12}{'ratio':>8}{'x Newton':>10}")
    for path, found in routes.items():
        compiled = found.get("numba", float("nan"))
        newton = newton_fk_rate if "FK" in path else newton_ik_rate
        print(f"{path:<52}{found['numpy']:>12,.0f}{compiled:>12,.0f}{compiled / found['numpy']:>8.2f}"
              f"{max(found.values()) / newton:>10.0f}")
    print(f"{'all-solutions IK (sextic, both pairs)':<52}{ik_all_rate:>12,.0f}{'':>12}{'':>8}"
          f"{ik_all_rate / newton_ik_rate:>10.1f}")
    print(f"{'Newton-Raphson IK, per point (baseline)':<52}{newton_ik_rate:>12,.0f}{'':>12}{'':>8}{1:>10}")
    print(f"{'all-modes FK (degree-12 eliminant)':<52}{fk_all_rate:>12,.0f}{'':>12}{'':>8}"
          f"{fk_all_rate / newton_fk_rate:>10.1f}")
    print(f"{'Newton-Raphson FK, per point (baseline)':<52}{newton_fk_rate:>12,.0f}{'':>12}{'':>8}{1:>10}")
    print(f"\nnumba: {'not installed' if 'numba' not in routes[next(iter(routes))] else 'the compiled loops'} "
          f"(verne_post/kinematics/_loops.py); the ratio is numba over numpy, same poses, same run")
    print(f"\nposes: {len(tip):,} (all-solutions on {m:,}, Newton on {b:,}); Newton reached the same joints "
          f"(1e-6) in {ik_agree:.1%} (IK) and {fk_agree:.1%} (FK) of its poses from a fixed start")


if __name__ == "__main__":
    main()
