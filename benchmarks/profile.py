"""Where the 105k-block job's time goes, function by function: the whole post in one process under cProfile.

    python -m benchmarks.profile [--points 100000] [--top 25]

Generates the job as benchmarks.pipeline does (examples/generate_job.py, 100,000 CL points,
about 105,000 blocks), posts it with ``PostOptions(workers=1)`` (every stage in this process,
verification on, as by default) to a temporary file, and prints the stage seconds of the post
(``Posted.seconds``) of a run without the profiler and of the profiled run after it (the profiler
adds its own cost to every call, most to the stages of many small calls) and the
``--top`` functions by their own time (time in the function itself, not in what it calls), each
with its share of the profiled total.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import cProfile  # noqa: E402
import pstats  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import verne_post as vp  # noqa: E402
from benchmarks.pipeline import ROOT, _generator  # noqa: E402
from verne_post.options import PostOptions  # noqa: E402
from verne_post.pipeline import post  # noqa: E402


def _where(key: tuple[str, int, str]) -> str:
    """A function's place, short: path from the checkout (else the file's name), line, name."""
    file, line, name = key
    path = Path(file)
    if path.is_relative_to(ROOT):
        file = str(path.relative_to(ROOT))
    elif file != "~":
        file = path.name
    return f"{file}:{line}({name})" if file != "~" else name


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=100_000, help="CL points of the generated job")
    parser.add_argument("--top", type=int, default=25, help="functions to list, by own time")
    args = parser.parse_args()
    machine = vp.load_machine()
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        (folder / "job.cls").write_text(_generator().generate(args.points))
        plain = post(folder / "job.cls", machine, PostOptions(workers=1), folder / "job.nc")
        profiler = cProfile.Profile()
        profiler.enable()
        posted = post(folder / "job.cls", machine, PostOptions(workers=1), folder / "job.nc")
        profiler.disable()
    assert not posted.violations and posted.verification is not None
    stats = pstats.Stats(profiler)
    total = stats.total_tt  # type: ignore[attr-defined]
    print(f"job: {args.points:,} CL points; one process, verification on; {total:.2f} s under the profiler\n")
    print(f"{'stage':<16}{'seconds':>8}{'profiled':>10}")
    for stage, seconds in posted.seconds.items():
        print(f"{stage:<16}{plain.seconds.get(stage, float('nan')):>8.2f}{seconds:>10.2f}")
    print(f"{'total':<16}{sum(plain.seconds.values()):>8.2f}{sum(posted.seconds.values()):>10.2f}")
    rows = sorted(stats.stats.items(), key=lambda item: -item[1][2])[:args.top]  # type: ignore[attr-defined]
    print(f"\n{'own s':>7}{'share':>7}{'cum s':>7}{'calls':>9}  function")
    for key, (_, calls, own, cumulative, _) in rows:
        print(f"{own:>7.2f}{own / total:>7.1%}{cumulative:>7.2f}{calls:>9,}  {_where(key)}")


if __name__ == "__main__":
    main()
