"""The main job's speed, stage by stage, side by side with LinuxCNC's interpreter reading the result.

    python benchmarks/pipeline.py [--points 100000]

Generates the 5-axis example at the given size (examples/generate_job.py), runs every stage of
``verne-post part.cls -o part.nc`` before time-parametrisation (``--no-timing``; the planner
has its own benchmark, benchmarks/timing.py), and in the same run times
``rs274`` interpreting the program it wrote. Target: verne-post no slower than the interpreter.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import importlib.util  # noqa: E402
import re  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import verne_post as vp  # noqa: E402
from verne_post.gcode import write_program  # noqa: E402
from verne_post.pipeline import PostOptions, gcode_format, postprocess  # noqa: E402
from verne_post.rs274 import run_rs274  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def _generator():
    spec = importlib.util.spec_from_file_location("generate_job", ROOT / "examples" / "generate_job.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["generate_job"] = module
    spec.loader.exec_module(module)
    return module


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--points", type=int, default=100_000)
    args = parser.parse_args()
    machine = vp.load_machine()
    with tempfile.TemporaryDirectory() as folder:
        source, output = Path(folder) / "job.cls", Path(folder) / "job.nc"
        source.write_text(_generator().generate(args.points))
        start = time.perf_counter()
        result = postprocess(source, machine, PostOptions(plan=False))  # timing: benchmarks/timing.py
        assert not result.violations, result.violations[:3]
        write_start = time.perf_counter()
        write_program(result.program, gcode_format(machine), output)
        write_time = time.perf_counter() - write_start
        total = time.perf_counter() - start
        tools = [int(t) for t in re.findall(r"^T(\d+) M6", output.read_text(), re.M)]
        start = time.perf_counter()
        interpreted = run_rs274(output, tool_numbers=tools, timeout=600)
        rs274_time = time.perf_counter() - start
    points, blocks = len(result.poses), len(result.program.joints)
    stages = {**result.seconds, "write": write_time}
    print(f"job: {points:,} CL points -> {blocks:,} blocks ({blocks - points:,} inserted), "
          f"{len(interpreted.moves):,} moves read back by rs274")
    print(f"\n{'stage':<12}{'seconds':>10}{'CL points/s':>14}")
    for name, seconds in stages.items():
        print(f"{name:<12}{seconds:>10.3f}{points / seconds:>14,.0f}")
    print(f"{'verne-post':<12}{total:>10.3f}{points / total:>14,.0f}   (all stages above)")
    print(f"{'rs274':<12}{rs274_time:>10.3f}{points / rs274_time:>14,.0f}   (LinuxCNC reading the program, "
          f"incl. parsing its canon output)")
    print(f"\nratio verne-post / rs274 = {total / rs274_time:.2f}  (target <= 1)")


if __name__ == "__main__":
    main()
