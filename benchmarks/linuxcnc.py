"""Planned against executed: each job posted with the default machine (timed, LinuxCNC dialect),
then run as written through LinuxCNC 2.9's own planner (``verne-post simulate``, headless), the
header's cycle time beside the executed one and the tool tip's distance from the program's path.

Run: python -m benchmarks.linuxcnc [--time-scale 5] [--jobs impeller,creo8,swarf]. The impeller
takes about 6 minutes at time scale 5 (LinuxCNC runs 1658 s of motion). Needs linuxcnc-uspace.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import verne_post as vp
from verne_post.linuxcnc.measures import path_deviation
from verne_post.linuxcnc.simulate import header_cycle_time, simulate
from verne_post.options import PostOptions
from verne_post.pipeline import post

ROOT = Path(__file__).resolve().parent.parent
#: The issue's jobs (issue 33): the impeller at the machine's offset; the two samples with
#: --tool-length 100 --work-offset auto.
JOBS = {"impeller": (ROOT / "examples" / "impeller_5axis.cls", PostOptions()),
        "creo8": (ROOT / "tests" / "data" / "cl-samples" / "creo8_profilfraesen_mm.ncl",
                  PostOptions(tool_length=100.0, work_offset="auto")),
        "swarf": (ROOT / "tests" / "data" / "cl-samples" / "nx_swarf_inch_crlf.cls",
                  PostOptions(tool_length=100.0, work_offset="auto"))}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--time-scale", type=float, default=5.0)
    parser.add_argument("--jobs", default=",".join(JOBS))
    args = parser.parse_args()
    machine = vp.load_machine()
    print(f"{'job':10s} {'header s':>9s} {'executed s':>11s} {'change':>7s} {'tip feeds mm':>13s} "
          f"{'tip between mm':>15s} {'wall s':>7s}")
    with tempfile.TemporaryDirectory() as folder:
        for name in args.jobs.split(","):
            source, options = JOBS[name]
            program = Path(folder) / f"{name}.nc"
            posted = post(str(source), machine, options, program)
            if posted.violations:
                print(f"{name:10s} does not post: {posted.violations[0].message}")
                continue
            text = program.read_text()
            start = time.perf_counter()
            result = simulate(program, machine, time_scale=args.time_scale)
            wall = time.perf_counter() - start
            planned = header_cycle_time(text)
            path = path_deviation(machine, text, result)
            change = (result.cycle_time / planned - 1.0) * 100.0 if planned else float("nan")
            print(f"{name:10s} {planned or float('nan'):9.1f} {result.cycle_time:11.1f} {change:+6.1f}% "
                  f"{path.feeds:13.4f} {path.between_cuts:15.4f} {wall:7.1f}", flush=True)


if __name__ == "__main__":
    main()
