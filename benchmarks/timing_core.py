"""Feed planning throughput and plan quality on one core.

Joint polylines from the machine's IK of smooth tool paths (helices around the table axis, a
zig-zag of rows and half circles with a swinging tool axis), planned with toppra + jerk filter.
Reports waypoints planned per second (best of a few runs) and the plan time T against the
lower bound (no acceleration limit) and the look-ahead trapezoidal baseline (no jerk limit).

    python -m benchmarks.timing_core [--repeat 3]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import verne_post as vp  # noqa: E402
from tests.paths import helix, zigzag  # noqa: E402
from verne_post.planning.feed_planner import plan_feed  # noqa: E402
from verne_post.planning.timing import Limits, baseline_time, lower_bound_time  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    machine = vp.load_machine()
    limits = Limits.from_machine(machine)
    short = helix(machine, 101, 0.2, pitch=2.0)
    cases = [
        ("helix 0.2 turn", short, 50.0),
        ("helix 0.2 turn", short, 1e5),
        ("helix 2 turns", helix(machine, 1001, 2.0, pitch=2.0), 50.0),
        ("helix 2 turns", helix(machine, 1001, 2.0, pitch=2.0), 1e5),
        ("zig-zag 4 rows", zigzag(machine, 1001, 4), 100.0),
        ("helix 20 turns", helix(machine, 10001, 20.0, pitch=2.0), 50.0),
        ("helix 20 turns", helix(machine, 10001, 20.0, pitch=2.0), 1e5),
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
