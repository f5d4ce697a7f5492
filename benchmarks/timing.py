"""Time-parametrisation on the generated 5-axis job: speed of planning and quality of the plan.

    python -m benchmarks.timing [--points 100000] [--short 10000]

For each job prints, in one run: planning time (CL points/s and blocks/s), the planned feed
time T, the lower bound LB = sum over blocks of length / min(F, min_j v_j / |dq_j/ds|) (no
acceleration limit at all), the time of a look-ahead trapezoidal-feed baseline with per-block
joint velocity clamping and no jerk limit (how common CNC controllers plan), the time of a
jerk-limited look-ahead baseline with per-block S-curves (benchmarks/scurve.py, how controllers
with S-curve planning run G-code; the issue's target is T below it), and T / LB, T / baseline,
T / S-curve baseline; and the same plan without jerk limits (T0, the trapezoid's own
assumptions). Rapids are the same ruckig moves in all of them and are left out.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import verne_post as vp  # noqa: E402
from benchmarks.pipeline import _generator  # noqa: E402
from benchmarks.scurve import scurve_baseline_time  # noqa: E402
from verne_post.pipeline import PostOptions, feed_speed, postprocess  # noqa: E402
from verne_post.schedule import plan_program  # noqa: E402
from verne_post.timing import Limits, baseline_time, lower_bound_time  # noqa: E402


def measure(points: int) -> None:
    machine = vp.load_machine()
    with tempfile.TemporaryDirectory() as folder:
        source = Path(folder) / "job.cls"
        source.write_text(_generator().generate(points))
        result = postprocess(source, machine, PostOptions())
    assert not result.violations, result.violations[:3]
    limits = Limits.from_machine(machine)
    rotary = np.radians(machine.timing.rotary_feed) / 60.0
    blocks, schedule = result.blocks, result.schedule
    speed = feed_speed(result.poses, blocks, result.duration)
    planned = bound = baseline = scurve = 0.0
    sequences = 0
    for segment in schedule.segments:
        if segment.rapid:
            continue
        rows = np.arange(segment.first - 1, segment.last + 1)
        args = (blocks.joints[rows], blocks.tip[rows], speed[segment.first:segment.last + 1], limits)
        planned += segment.plan.total
        bound += lower_bound_time(*args, angular_feed=rotary)
        baseline += baseline_time(*args, angular_feed=rotary)
        scurve += scurve_baseline_time(*args, angular_feed=rotary)
        sequences += 1
    seconds = result.seconds["timing"]
    without_jerk = plan_program(blocks.joints, blocks.tip, result.rapid, speed, result.poses.sequence[blocks.pose],
                                limits, rotary_feed=rotary, corner=np.radians(machine.timing.corner_angle),
                                workers=os.cpu_count() or 1, jerk=False)
    planned_nj = sum(s.plan.total for s in without_jerk.segments if not s.rapid)
    print(f"\njob of {len(result.poses):,} CL points, {len(blocks.joints):,} blocks, {sequences} feed sequences")
    print(f"  planning             {seconds:8.2f} s   {len(result.poses) / seconds:10,.0f} CL points/s  "
          f"{len(blocks.joints) / seconds:10,.0f} blocks/s")
    print(f"  planned feed time T  {planned:8.1f} s")
    print(f"  lower bound LB       {bound:8.1f} s   T / LB       = {planned / bound:.3f}  (target <= 1.25)")
    print(f"  trapezoidal baseline {baseline:8.1f} s   T / baseline = {planned / baseline:.3f}  (target <= 0.90)")
    print(f"  S-curve baseline     {scurve:8.1f} s   T / S-curve  = {planned / scurve:.3f}  (target < 1; "
          f"jerk-limited, per-block S-curves)")
    print(f"  without jerk limits  {planned_nj:8.1f} s   T0 / LB      = {planned_nj / bound:.3f}   "
          f"T0 / baseline = {planned_nj / baseline:.3f}  (same limits as the baseline)")
    print(f"  LB / baseline = {bound / baseline:.3f}: no plan can be faster than this share of the baseline")
    print(f"  cycle time (with rapids) {schedule.total:.1f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--points", type=int, default=100_000)
    parser.add_argument("--short", type=int, default=10_000)
    args = parser.parse_args()
    for points in (args.short, args.points):
        measure(points)


if __name__ == "__main__":
    main()
