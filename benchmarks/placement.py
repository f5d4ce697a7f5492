"""`verne-post place` on the impeller example (36,000 CL poses) on one core, stage by stage, next to
one full `check --no-timing` of the same program in the same run; and the command itself (which
runs the room's full checks of different directions side by side on as many cores as it has).

    python -m benchmarks.placement [--cl examples/impeller_5axis.cls] [--post 3]

Stages: the coarse grid, the pattern search (with the branch stage that gives it the angle
pairs), the full checks that verify the best offset, and the room (bisection on the screen and
a full check per end; ``stopped early``: checks that stopped at the first failure they found).
Target: the whole command (start-up and reading the CL file included) under 10 s.

``--post N`` measures instead what issue 35 targets (<= 2 s): the post with ``--work-offset auto``
against the post at the offset it finds, both as processes with the default options, in turn
(auto, fixed, auto, fixed, ...), N runs each; prints the medians and their difference, and
checks that both wrote the same program but for the auto post's header lines.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import re  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
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
    parser.add_argument("--post", type=int, default=0, metavar="N",
                        help="time the post with --work-offset auto against the post at the offset it finds, N runs")
    args = parser.parse_args()
    if args.post:
        _auto_against_fixed(args.cl, args.post)
        return
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
        # one process, so that every full check is counted here (the command runs the room's
        # checks of different directions side by side, up to its workers)
        found = placement.place(machine, zero, PostOptions(plan=False, workers=1), progress=progress)
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


def _auto_against_fixed(cl: str, runs: int) -> None:
    """The post with ``--work-offset auto`` against the post at the offset it finds (issue 35)."""
    def seconds(*extra: str) -> float:
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "verne_post", cl, "-q", *extra], check=True, capture_output=True)
        return time.perf_counter() - start

    times: dict[str, list[float]] = {"auto": [], "fixed": []}
    with tempfile.TemporaryDirectory() as name:
        auto, fixed = Path(name) / "auto.nc", Path(name) / "fixed.nc"
        offset: list[str] = []
        for _ in range(runs):
            times["auto"].append(seconds("-o", str(auto), "--work-offset", "auto"))
            offset = re.search(r"\(WORK OFFSET (\S+) (\S+) (\S+) MM", auto.read_text()).groups()  # type: ignore
            times["fixed"].append(seconds("-o", str(fixed), "--work-offset", *offset))
        body = [[line for line in path.read_text().splitlines() if not line.startswith("(")] for path in (auto, fixed)]
        assert body[0] == body[1], "the auto post and the post at its offset wrote different programs"
    median = {key: statistics.median(values) for key, values in times.items()}
    print(f"{Path(cl).name}: offset found {' '.join(offset)} mm; median of {runs} runs each, whole processes")
    for key, label in (("auto", "--work-offset auto"), ("fixed", "--work-offset at that offset")):
        print(f"{label:<32}{median[key]:>8.2f} s   (runs: {', '.join(f'{t:.2f}' for t in times[key])})")
    over = statistics.median(a - b for a, b in zip(times["auto"], times["fixed"], strict=True))
    print(f"{'auto over fixed':<32}{median['auto'] - median['fixed']:>8.2f} s   (run by run: {over:.2f} s; "
          "target <= 2 s)")


if __name__ == "__main__":
    main()
