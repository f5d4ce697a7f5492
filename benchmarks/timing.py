"""Time-parametrisation on the generated 5-axis job: speed of planning and quality of the plan.

    python -m benchmarks.timing [--points 100000] [--short 10000] [--topp3 40]

For each job prints, in one run, per TOPP2 engine (copp-py, the default, and toppra, the
reference) in one process and in as many as there are cores: planning time (blocks/s), the
planned feed time T, the lower bound LB = sum over blocks of length / min(F, min_j v_j / |dq_j/ds|) (no
acceleration limit at all), the time of a look-ahead trapezoidal-feed baseline with per-block
joint velocity clamping and no jerk limit (how common CNC controllers plan), the time of a
jerk-limited look-ahead baseline with per-block S-curves (benchmarks/scurve.py, how controllers
with S-curve planning run G-code; the issue's target is T below it), and T / LB, T / baseline,
T / S-curve baseline; and the same plan without jerk limits (T0, the trapezoid's own
assumptions), also on a grid four times finer: a verified plan too, so an upper bound on the
second-order optimum, which the default grid overestimates. Beside them the jerk-limited lower
bound LB3 (benchmarks/jerk_bound.py): no plan within the jerk limits can be faster, so T / LB3
is what is left to win and LB3 / T0 (fine) the least any jerk-limited plan costs over the
second-order optimum. Rapids are the same ruckig moves in all of them and are left out. Then, on
a random sample of the feed sequences, copp-py's TOPP3-LP (benchmarks/topp3.py): what a
third-order method gets from the jerk limits, T3 / T2, beside the plan's T / T0 on the same
sample. The row ``copp+LP`` is ``--optimize``: the default engine plus the third-order programme
(verne_post.planning.third_order) on the sequences of more than 40 blocks.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections.abc import Iterator  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import verne_post as vp  # noqa: E402
from benchmarks.jerk_bound import jerk_lower_bounds  # noqa: E402
from benchmarks.pipeline import _generator  # noqa: E402
from benchmarks.scurve import scurve_baseline_time  # noqa: E402
from benchmarks.topp3 import topp3_reference  # noqa: E402
from verne_post.motion.linearise import Blocks  # noqa: E402
from verne_post.options import PostOptions  # noqa: E402
from verne_post.pipeline import postprocess  # noqa: E402
from verne_post.planning.feed import grid  # noqa: E402
from verne_post.planning.schedule import Schedule, Segment, plan_program  # noqa: E402
from verne_post.planning.stage import feed_speed  # noqa: E402
from verne_post.planning.timing import Limits, baseline_time, lower_bound_time  # noqa: E402


def measure(points: int, engines: tuple[str, ...], sample: int) -> None:
    machine = vp.load_machine()
    with tempfile.TemporaryDirectory() as folder:
        source = Path(folder) / "job.cls"
        source.write_text(_generator().generate(points))
        result = postprocess(source, machine, PostOptions(plan=False))
    assert not result.violations, result.violations[:3]
    limits = Limits.from_machine(machine)
    rotary = np.radians(machine.timing.rotary_feed) / 60.0
    blocks = result.blocks
    speed = feed_speed(result.poses, blocks, result.duration)

    def plan(engine: str, workers: int, jerk: bool = True, optimize: bool = False) -> tuple[Schedule, float]:
        clock = time.perf_counter()
        schedule = plan_program(blocks.joints, blocks.tip, result.rapid, speed, result.poses.sequence[blocks.pose],
                                limits, rotary_feed=rotary, corner=np.radians(machine.timing.corner_angle),
                                workers=workers, jerk=jerk, engine=engine, optimize=optimize)
        return schedule, time.perf_counter() - clock

    reference, _ = plan(engines[0], 1)
    feed = [s for s in reference.segments if not s.rapid]
    bound = baseline = scurve = 0.0
    for segment in feed:
        args = (*_sequence(blocks, speed, segment), limits)
        bound += lower_bound_time(*args, angular_feed=rotary)
        baseline += baseline_time(*args, angular_feed=rotary)
        scurve += scurve_baseline_time(*args, angular_feed=rotary)
    plain = [s for s in plan(engines[0], 1, jerk=False)[0].segments if not s.rapid]
    without_jerk = sum(s.plan.total for s in plain)
    with _finer_grid(4):
        fine = sum(s.plan.total for s in plan(engines[0], 1, jerk=False)[0].segments if not s.rapid)
    jerk_bound = float(np.sum(jerk_lower_bounds([_sequence(blocks, speed, s) for s in feed], limits,
                                                angular_feed=rotary)))
    count = len(blocks.joints)
    print(f"\njob of {len(result.poses):,} CL points, {count:,} blocks, {len(feed)} feed sequences")
    print(f"  lower bound LB                {bound:8.1f} s  (no acceleration limit)")
    print(f"  trapezoidal baseline          {baseline:8.1f} s  (look-ahead, no jerk limit)")
    print(f"  S-curve baseline              {scurve:8.1f} s  (look-ahead, per-block jerk-limited S-curves)")
    print(f"  plan without jerk limits T0   {without_jerk:8.1f} s  T0 / LB = {without_jerk / bound:.3f}")
    print(f"  T0 on a 4x finer grid         {fine:8.1f} s  T0 (fine) / LB = {fine / bound:.3f}")
    print(f"  jerk-limited lower bound LB3  {jerk_bound:8.1f} s  LB3 / T0 = {jerk_bound / without_jerk:.4f}, "
          f"LB3 / T0 (fine) = {jerk_bound / fine:.4f}, LB3 / LB = {jerk_bound / bound:.4f}  (no plan is faster)")
    print(f"  {'engine':8} {'processes':>9} {'planning s':>10} {'blocks/s':>9} {'T s':>8} {'T/T0':>6} {'T/LB':>6} "
          f"{'T/trap':>6} {'T/S-curve':>9} {'T/LB3':>6}")
    for engine, optimize in [(engine, False) for engine in engines] + [(engines[0], True)]:
        for workers in (1, os.cpu_count() or 1):
            schedule, seconds = plan(engine, workers, optimize=optimize)
            total = sum(s.plan.total for s in schedule.segments if not s.rapid)
            label = f"{engine}+LP" if optimize else engine
            print(f"  {label:8} {workers:9d} {seconds:10.2f} {count / seconds:9,.0f} {total:8.1f} "
                  f"{total / without_jerk:6.3f} {total / bound:6.3f} {total / baseline:6.3f} {total / scurve:9.3f} "
                  f"{total / jerk_bound:6.3f}")
    print("  targets: planning >= 50,000 blocks/s on 2 cores; T / T0 <= 1.02; T / LB <= 1.07; T / S-curve < 1")
    if sample:
        _third_order_reference(blocks, speed, limits, feed, plain, sample)


@contextlib.contextmanager
def _finer_grid(factor: float) -> Iterator[None]:
    """The planner's TOPP2 grid ``factor`` times finer (intervals per filter width, and per block)."""
    saved = grid._GRID_PER_WINDOW, grid._MAX_INTERVALS_PER_BLOCK
    grid._GRID_PER_WINDOW, grid._MAX_INTERVALS_PER_BLOCK = (x * factor for x in saved)
    try:
        yield
    finally:
        grid._GRID_PER_WINDOW, grid._MAX_INTERVALS_PER_BLOCK = saved


def _sequence(blocks: Blocks, speed: np.ndarray, segment: Segment) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A feed sequence's waypoints (joints, tips: from the block before its first) and block feeds."""
    rows = np.arange(segment.first - 1, segment.last + 1)
    return blocks.joints[rows], blocks.tip[rows], speed[segment.first:segment.last + 1]


def _third_order_reference(blocks: Blocks, speed: np.ndarray, limits: Limits, feed: list[Segment],
                           plain: list[Segment], sample: int) -> None:
    """copp-py's TOPP3-LP (benchmarks/topp3.py) on a random sample of the feed sequences, beside
    the plan's own T / T0 on the same sequences."""
    rng = np.random.default_rng(0)
    ours = ours0 = t2 = t3 = 0.0
    taken = 0
    clock = time.perf_counter()
    for k in sorted(rng.choice(len(feed), size=min(sample, len(feed)), replace=False)):
        segment = feed[k]
        times = topp3_reference(*_sequence(blocks, speed, segment), limits)
        if times is None:
            continue
        taken += 1
        ours, ours0 = ours + segment.plan.total, ours0 + plain[k].plan.total
        t2, t3 = t2 + times[0], t3 + times[1]
    print(f"  third-order reference on {taken} random feed sequences ({time.perf_counter() - clock:.0f} s; "
          f"{min(sample, len(feed)) - taken} with a rotary-only block or where the LP failed left out): "
          f"copp-py TOPP3-LP T3 / T2 = {t3 / t2:.4f}; the plan T / T0 = {ours / ours0:.4f}, T / T3 = {ours / t3:.4f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--points", type=int, default=100_000)
    parser.add_argument("--short", type=int, default=10_000)
    parser.add_argument("--engines", default="copp,toppra", help="TOPP2 engines to compare, the first the default")
    parser.add_argument("--topp3", type=int, default=40, help="sequences of the long job for TOPP3 (0: none)")
    args = parser.parse_args()
    for points, sample in ((args.short, 0), (args.points, args.topp3)):
        measure(points, tuple(args.engines.split(",")), sample)


if __name__ == "__main__":
    main()
