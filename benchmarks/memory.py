"""Peak memory of ``verne-post part.cls -o part.nc -q`` against the program's length, in one run.

    python -m benchmarks.memory [--sizes 30000,300000] [--baseline-max 300000]

For each size the 5-axis example is generated with about that many GOTO points
(examples/generate_job.py; arcs add a few more CL points) and posted by the command in a process
of its own; its peak resident set size is the kernel's (``os.wait4`` of that process: the largest
of it and the planner's worker processes). This process imports nothing of verne-post and the
jobs are generated in processes of their own: the kernel's figure keeps the size of a process
before it starts the command (fork, then exec), which must not be this one's. Beside it, in the
same run: the footprint of starting Python and importing verne-post (the floor), and the whole
program posted at once
(``pipeline.postprocess`` and ``write_output``: the arrays of every stage for the whole program,
as before the posting in parts) up to ``--baseline-max`` points. The G-code of both is compared.
Target: 300k points within 25 % of 30k, 3M under 1 GiB (the 3M case takes minutes: give
``--sizes 3000000`` on its own, once).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import re  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent

#: The whole program at once, as ``verne-post`` posted it before the parts (postprocess + write_output).
_WHOLE = """
import sys
import verne_post as vp
from verne_post.options import PostOptions
from verne_post.pipeline import postprocess, write_output
machine = vp.load_machine()
options = PostOptions()
result = postprocess(sys.argv[1], machine, options)
assert not result.violations and write_output(result, machine, options, sys.argv[2]).ok
"""


def _peak(command: list[str]) -> tuple[float, float]:
    """Peak RSS (MiB) of ``command`` run as a process of its own, and its seconds."""
    start = time.perf_counter()
    process = subprocess.Popen(command, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(process.pid, 0)
    seconds = time.perf_counter() - start
    error = process.stderr.read().decode() if process.stderr else ""
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{' '.join(command)} failed:\n{error}")
    return usage.ru_maxrss / 1024, seconds  # ru_maxrss is in KiB on Linux


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", default="30000,300000",
                        help="GOTO points of the generated jobs, comma-separated (default 30000,300000)")
    parser.add_argument("--baseline-max", type=int, default=300_000,
                        help="largest size also posted whole-program at once (default 300000)")
    args = parser.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    floor, _ = _peak([sys.executable, "-c", "import verne_post.cli, verne_post.pipeline"])
    print(f"python + import verne-post: {floor:.0f} MiB\n")
    print(f"{'GOTO':>10}{'CL points':>11}{'parts: MiB':>12}{'s':>7}{'whole: MiB':>12}{'s':>7}   same G-code")
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for size in sizes:
            source, output, whole = (Path(folder) / name for name in ("job.cls", "job.nc", "whole.nc"))
            subprocess.run([sys.executable, str(ROOT / "examples" / "generate_job.py"), "--points", str(size), "-o",
                            str(source)], check=True, capture_output=True)
            parts, seconds = _peak([sys.executable, "-m", "verne_post", str(source), "-o", str(output), "-q"])
            points = int(re.search(r"CL POINTS (\d+)", output.read_text()[:4000]).group(1))
            line = f"{size:>10,}{points:>11,}{parts:>12.0f}{seconds:>7.1f}"
            if size <= args.baseline_max:
                at_once, whole_seconds = _peak([sys.executable, "-c", _WHOLE, str(source), str(whole)])
                same = "yes" if whole.read_bytes() == output.read_bytes() else "NO"
                line += f"{at_once:>12.0f}{whole_seconds:>7.1f}   {same}"
            print(line, flush=True)
            rows.append((size, parts))
    if len(rows) > 1:
        first = rows[0][1]
        print("\n" + "\n".join(f"{size:,} points: {mib / first:.2f} x the {rows[0][0]:,}-point peak, "
                                f"{mib - floor:.0f} MiB above the import floor" for size, mib in rows))


if __name__ == "__main__":
    main()
