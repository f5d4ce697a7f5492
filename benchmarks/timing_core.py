"""Feed planning throughput and plan quality on one core.

Joint polylines from the machine's IK of smooth tool paths (helices around the table axis, a
zig-zag of rows and half circles with a swinging tool axis), planned with toppra + jerk filter.
Reports waypoints planned per second (best of a few runs) and the plan time T against the
lower bound (no acceleration limit) and the look-ahead trapezoidal baseline (no jerk limit).

    python benchmarks/timing_core.py [--repeat 3]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import verne_post as vp  # noqa: E402
from verne_post.timing import Limits, baseline_time, lower_bound_time, plan_feed  # noqa: E402

TOOL = 60.0


def _axis(tilt: np.ndarray, azimuth: np.ndarray) -> np.ndarray:
    return np.stack([np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), np.cos(tilt)], axis=1)


def _joints(machine: vp.Machine, tip: np.ndarray, axis: np.ndarray) -> np.ndarray:
    hint = float(vp.inverse_kinematics(machine, tip[:1], axis[:1], tool_length=TOOL).joints[0, 4])
    chunks = []
    for part in np.array_split(np.arange(len(tip)), max(1, len(tip) // 50)):
        ik = vp.inverse_kinematics(machine, tip[part], axis[part], theta2_hint=hint, tool_length=TOOL)
        if not (ik.status == 0).all():
            raise SystemExit("benchmark path leaves the workspace")
        chunks.append(ik.joints)
        hint = float(ik.joints[-1, 4])
    joints = np.concatenate(chunks)
    joints[:, 4] = np.unwrap(joints[:, 4])
    return joints


def helix(machine: vp.Machine, n: int, turns: float) -> tuple[np.ndarray, np.ndarray]:
    a = np.linspace(0.0, 2 * np.pi * turns, n)
    tip = np.stack([40.0 * np.cos(a), 40.0 * np.sin(a), 60.0 + 2.0 * a / (2 * np.pi)], axis=1)
    tilt = np.radians(20.0 + 20.0 * 0.5 * (1 - np.cos(a / turns)))
    return _joints(machine, tip, _axis(tilt, a + 0.3)), tip


def zigzag_tip(n: int, rows: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows of 60 mm, 8 mm apart, joined by half circles, sampled evenly along the path (mm)."""
    row, turn = 60.0, np.pi * 4.0
    total = rows * row + (rows - 1) * turn
    u = np.linspace(0.0, total, n)
    period = row + turn
    k = np.minimum(np.floor(u / period), rows - 1)
    v = u - k * period
    side = np.where(k % 2 == 0, 1.0, -1.0)  # direction of travel along x on row k
    on_row = v <= row
    x = np.where(on_row, side * (v - row / 2), side * (row / 2 + 4.0 * np.sin((v - row) / 4.0)))
    y = np.where(on_row, 8.0 * k, 8.0 * k + 4.0 - 4.0 * np.cos((v - row) / 4.0))
    return np.stack([x, y - 4.0 * (rows - 1), 70.0 + 0.05 * x], axis=1), u / total


def zigzag(machine: vp.Machine, n: int, rows: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows joined by half circles, tool tilt 20..40 deg and swinging."""
    tip, phase = zigzag_tip(n, rows)
    tilt = np.radians(30.0 + 10.0 * np.sin(2 * np.pi * phase))
    azimuth = np.radians(30.0) + 0.5 * np.sin(4 * np.pi * phase)
    return _joints(machine, tip, _axis(tilt, azimuth)), tip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    machine = vp.load_machine()
    limits = Limits.from_machine(machine)
    short = helix(machine, 101, 0.2)
    cases = [
        ("helix 0.2 turn", short, 50.0),
        ("helix 0.2 turn", short, 1e5),
        ("helix 2 turns", helix(machine, 1001, 2.0), 50.0),
        ("helix 2 turns", helix(machine, 1001, 2.0), 1e5),
        ("zig-zag 4 rows", zigzag(machine, 1001, 4), 100.0),
        ("helix 20 turns", helix(machine, 10001, 20.0), 50.0),
        ("helix 20 turns", helix(machine, 10001, 20.0), 1e5),
        ("zig-zag 30 rows", zigzag(machine, 10001, 30), 100.0),
        ("zig-zag 4 rows dense", zigzag(machine, 10001, 4), 100.0),
    ]
    plan_feed(cases[0][1][0][:50], cases[0][1][1][:50], np.full(49, 50.0), limits, angular_feed=1.0)  # warm-up
    print(f"{'path':22s} {'waypoints':>9s} {'feed':>8s} {'grid':>6s} {'rounds':>6s} {'ms':>8s} {'waypoints/s':>12s}"
          f" {'T s':>8s} {'T/lower':>8s} {'T/baseline':>10s}")
    for name, (joints, tip), f in cases:
        feed = np.full(len(joints) - 1, f)
        best = np.inf
        for _ in range(args.repeat):
            start = time.perf_counter()
            plan = plan_feed(joints, tip, feed, limits, angular_feed=1.0)
            best = min(best, time.perf_counter() - start)
        lower = lower_bound_time(joints, tip, feed, limits, angular_feed=1.0)
        base = baseline_time(joints, tip, feed, limits, angular_feed=1.0)
        print(f"{name:22s} {len(joints):9d} {f:8.0f} {plan.gridpoints:6d} {plan.refinements:6d} {best * 1e3:8.1f}"
              f" {len(joints) / best:12.0f} {plan.total:8.3f} {plan.total / lower:8.3f} {plan.total / base:10.3f}")


if __name__ == "__main__":
    main()
