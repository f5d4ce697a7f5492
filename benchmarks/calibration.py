"""Calibration throughput: poses per second through the whole fit, and the time for 100 and
1,000 measured poses (one core). Also what each fit achieves on 200 held-out poses.

The measurements come from the project's FK of a VERNE with its 12 geometry values off by
0.2-0.55 mm and its slider zeros off by 0.06-0.15 mm, three tools, 3 um noise (seeded).
Figures are printed, never asserted.

    python benchmarks/calibration.py [--sizes 100 1000] [--repeat 3]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import verne_post as vp  # noqa: E402
from verne_post.api import Status, classify, pose_margins  # noqa: E402
from verne_post.calibration import Poses, calibrate, parameters_of, predict  # noqa: E402


def usable_joints(machine: vp.Machine, n: int, seed: int) -> np.ndarray:
    """n random joint readings (mm, rad) whose status is ok on the nominal machine."""
    rng = np.random.default_rng(seed)
    lower = np.array([0.0, 0.0, 0.0, -np.pi / 2, -np.pi])
    upper = np.array([1300.0, 1300.0, 1300.0, np.pi / 2, np.pi])
    chunks, total = [], 0
    while total < n:
        joints = lower + (upper - lower) * rng.random((4 * n, 5))
        fk = vp.forward_kinematics(machine, joints, tool_length=80.0)
        found = pose_margins(machine, joints, fk.platform, fk.alpha, fk.reachable, 80.0)
        ok = classify(machine, joints, fk.reachable, found) == Status.OK
        chunks.append(joints[ok])
        total += int(ok.sum())
    return np.concatenate(chunks)[:n]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[100, 1000])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    machine = vp.load_machine()
    nominal = parameters_of(machine)
    rng = np.random.default_rng(4)
    truth = nominal.copy()
    truth[:12] += rng.choice([-1, 1], 12) * rng.uniform(0.2, 0.55, 12)
    truth[12:15] += rng.choice([-1, 1], 3) * rng.uniform(0.06, 0.15, 3)
    check = usable_joints(machine, 200, seed=99)
    check_tool = np.resize([45.0, 130.0], 200)
    check_tip = predict(truth, check, check_tool).tip
    print(f"{'poses':>6} {'fit s (best)':>13} {'poses/s':>9} {'evals':>6} {'RMS after um':>13} "
          f"{'held-out RMS um':>16} open directions")
    for n in args.sizes:
        joints = usable_joints(machine, n, seed=n)
        tool = np.resize([60.0, 80.0, 100.0], n)
        tip = predict(truth, joints, tool).tip + rng.normal(0.0, 0.003, (n, 3))
        poses = Poses(joints, tool, tip, np.full((n, 3), np.nan), np.ones(n))
        best = np.inf
        for _ in range(args.repeat):
            start = time.perf_counter()
            result = calibrate(nominal, poses)
            best = min(best, time.perf_counter() - start)
        error = predict(result.fitted, check, check_tool).tip - check_tip
        held_out = np.sqrt(np.mean(np.sum(error**2, axis=1))) * 1e3
        held = [",".join(d.combination) for d in result.directions if d.weak]
        print(f"{n:6d} {best:13.3f} {n / best:9.0f} {result.evaluations:6d} "
              f"{result.summary()['rms_after'] * 1e3:13.2f} {held_out:16.2f} {'; '.join(held)}")


if __name__ == "__main__":
    main()
