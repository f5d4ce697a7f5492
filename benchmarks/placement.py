"""`verne-post place` on the impeller example (36,000 CL poses) on one core, stage by stage, next to
one full `check --no-timing` of the same program in the same run.

    python -m benchmarks.placement [--cl examples/impeller_5axis.cls]

Stages: the coarse grid, the pattern search (with the branch stage that gives it the angle
pairs), the full checks that verify the best offset, and the room (bisection on the screen and
a full check per end; ``stopped early``: checks that stopped at the first failure they found).
Target: the whole command (start-up and reading the CL file included) under 10 s.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import verne_post as vp  # noqa: E402
from verne_post.checks.stage import Checked  # noqa: E402
from verne_post.cl import read_toolpath  # noqa: E402
from verne_post.motion.poses import machine_poses  # noqa: E402
from verne_post.options import PostOptions  # noqa: E402
from verne_post.pipeline import postprocess  # noqa: E402
from verne_post.placement import search as placement  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--cl", default=str(ROOT / "examples" / "impeller_5axis.cls"))
    args = parser.parse_args()
    machine = vp.load_machine()

    # The command as a user runs it: Python start-up, imports and reading the CL file included.
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "verne_post", "place", args.cl, "-q"], check=True, capture_output=True)
    command = time.perf_counter() - start

    # The same placement in this process, timed per stage (progress calls) and per full check.
    zero = machine_poses(read_toolpath(args.cl), machine, work_offset=(0.0, 0.0, 0.0))
    stages: dict[str, float] = defaultdict(float)
    checks = {"count": 0, "early": 0, "seconds": 0.0}
    full_check = placement.check_poses

    def timed_check(*args: Any, **kwargs: Any) -> Checked:
        begin = time.perf_counter()
        checked = full_check(*args, **kwargs)
        checks["seconds"] += time.perf_counter() - begin
        checks["count"] += 1
        checks["early"] += bool(kwargs.get("first_failure") and checked.violations)
        return checked

    clock = time.perf_counter()

    def progress(stage: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        stages[stage] += now - clock
        clock = now

    placement.check_poses = timed_check
    try:
        found = placement.place(machine, zero, PostOptions(plan=False), progress=progress)
    finally:
        placement.check_poses = full_check

    start = time.perf_counter()
    result = postprocess(args.cl, machine, PostOptions(work_offset=found.offset, plan=False))
    check = time.perf_counter() - start
    assert found.feasible and not result.violations

    print(f"{Path(args.cl).name}: {len(zero):,} CL poses; offset {' '.join(f'{v:.3f}' for v in found.offset)} mm, "
          f"smallest headroom {found.margin:.4f}, {found.screened} offsets screened")
    print("room mm: " + ", ".join(f"{a} -{lo:.2f}/+{hi:.2f}" for a, (lo, hi) in zip("xyz", found.room, strict=True)))
    print(f"\n{'stage':<34}{'seconds':>9}{'share':>8}")
    names = {"coarse grid": "coarse grid", "search": "pattern search (and angle pairs)",
             "full check": "verify (full checks of the best)", "room": "room (bisection, full checks)"}
    for stage, seconds in stages.items():
        print(f"{names.get(stage, stage):<34}{seconds:>9.2f}{seconds / found.seconds:>8.0%}")
    print(f"{'placement':<34}{found.seconds:>9.2f}")
    print(f"\nfull checks: {checks['count']} ({checks['early']} stopped early), {checks['seconds']:.2f} s")
    print(f"one 'check --no-timing' at the offset found (baseline): {check:.2f} s; "
          f"placement = {found.seconds / check:.1f} checks")
    print(f"'verne-post place' command, wall: {command:.2f} s (target < 10 s)")


if __name__ == "__main__":
    main()
