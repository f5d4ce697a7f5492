"""The whole command on the main job, timed as a process, against LinuxCNC's interpreter reading its output.

    python -m benchmarks.pipeline [--points 100000] [--runs 3]

Generates the 5-axis example at the given size (examples/generate_job.py; 100,000 points make
about 105,000 blocks) and times, as separate processes, each the median of ``--runs`` runs taken
in turn (A B C A B C ..., so a drift of the machine's speed hits all three alike):

  (a) ``verne-post job.cls -o job.nc -q``: every stage, planning and verification included
      (planning and verification in helper processes beside the main one, on 2+ cores);
  (b) the same with ``--report job.json``;
  (c) LinuxCNC's ``rs274 -g`` alone reading the job.nc that (a) wrote, as verne_post.verify.rs274 runs it;
  (d) (a) with ``--workers 1``: every stage in one process, the baseline of the helpers.

Prints their seconds and the ratios (a)/(c) (target <= 3, issue 35), (b)/(a) (target <= 1.10) and
(a)/(d), the planning speed in blocks/s (the report's ``seconds.timing``: the planning's own
time, in whichever process it ran), and the report's stage timings.
"""

from __future__ import annotations

import argparse
import compileall
import importlib.util
import json
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from verne_post.verify.rs274 import INSTALL_HINT, _environment, _write_tool_table, find_rs274

ROOT = Path(__file__).resolve().parent.parent


def _generator():
    spec = importlib.util.spec_from_file_location("generate_job", ROOT / "examples" / "generate_job.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["generate_job"] = module
    spec.loader.exec_module(module)
    return module


def _seconds(command: list[str], folder: Path, env: dict[str, str]) -> float:
    """Wall time (s) of one run of ``command`` in ``folder``, which must succeed."""
    start = time.perf_counter()
    process = subprocess.run(command, cwd=folder, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True, check=False)
    elapsed = time.perf_counter() - start
    if process.returncode != 0:
        raise SystemExit(f"{command[0]} failed ({process.returncode}): {process.stderr.strip()[-500:]}")
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=100_000, help="CL points of the generated job")
    parser.add_argument("--runs", type=int, default=3, help="runs of each command (the median is printed)")
    args = parser.parse_args()
    rs274 = find_rs274()
    if rs274 is None:
        raise SystemExit(INSTALL_HINT)
    post = [sys.executable, "-m", "verne_post"]  # the verne-post command of this interpreter
    # Byte-compiled, as `pip install` leaves an installed package: an editable install under
    # PYTHONDONTWRITEBYTECODE (set on some CI machines) would compile every module on each run.
    compileall.compile_dir(ROOT / "verne_post", quiet=1)
    env = _environment(rs274)
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        (folder / "job.cls").write_text(_generator().generate(args.points))
        commands = {
            "a": [*post, "job.cls", "-o", "job.nc", "-q"],
            "b": [*post, "job.cls", "-o", "job_report.nc", "-q", "--report", "job.json"],
            "c": [rs274, "-g", "-t", "tools.tbl", "job.nc", "canon.txt"],
            "d": [*post, "job.cls", "-o", "job_one.nc", "-q", "--workers", "1"],
        }
        times: dict[str, list[float]] = {key: [] for key in commands}
        for run in range(args.runs):
            for key, command in commands.items():
                if key == "c" and run == 0:  # the tool table of the program (a) has just written
                    tools = re.findall(r"^(?:N\d+ )?T(\d+) M6", (folder / "job.nc").read_text(), re.M)
                    _write_tool_table(folder / "tools.tbl", map(int, tools))
                times[key].append(_seconds(command, folder, env))
        if "PROGRAM_END" not in (folder / "canon.txt").read_text()[-2000:]:
            raise SystemExit("rs274 did not read job.nc to its end")
        if (folder / "job.nc").read_bytes() != (folder / "job_one.nc").read_bytes():
            raise SystemExit("(a) and (d) wrote different programs")
        report = json.loads((folder / "job.json").read_text())
    median = {key: statistics.median(values) for key, values in times.items()}
    blocks, points = report["points"]["blocks"], report["points"]["cl"]
    stages = report["seconds"]
    print(f"job: {points:,} CL points -> {blocks:,} blocks; median of {args.runs} runs each, whole processes\n")
    rows = [("(a) verne-post -o job.nc -q", "a"), ("(b) ... --report job.json", "b"), ("(c) rs274 -g job.nc", "c"),
            ("(d) (a) with --workers 1", "d")]
    for label, key in rows:
        spread = ", ".join(f"{t:.2f}" for t in times[key])
        print(f"{label:<30}{median[key]:>8.2f} s   {points / median[key]:>9,.0f} CL points/s   (runs: {spread})")

    def ratio(top: str, bottom: str) -> str:
        # Also the median of the ratios run by run: the runs of one round are taken together,
        # so a drift of the machine's speed between rounds cancels out of them.
        pairs = statistics.median(a / b for a, b in zip(times[top], times[bottom], strict=True))
        return f"{median[top] / median[bottom]:.3f} (run by run: {pairs:.3f})"

    print(f"\n(a) / (c) = {ratio('a', 'c')}  (target <= 3, issue 35)")
    print(f"(b) / (a) = {ratio('b', 'a')}  (target <= 1.10)")
    print(f"(a) / (d) = {ratio('a', 'd')}  (the helper processes against one process)")
    print(f"planning: {stages['timing']:.2f} s, {blocks / stages['timing']:,.0f} blocks/s (run (b)'s report: in its "
          "helper process, beside the others; benchmarks.timing times the planner alone)")
    print(f"\n{'stage (b)':<30}{'seconds':>8}")
    for stage, seconds in stages.items():
        print(f"{stage:<30}{seconds:>8.2f}")
    rest = times["b"][-1] - sum(stages.values())
    print(f"{'rest':<30}{rest:>8.2f}   (that run's wall time minus the above: start-up, and the overlap of the "
          "helpers' stages, negative)")


if __name__ == "__main__":
    main()
