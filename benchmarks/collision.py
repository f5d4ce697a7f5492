"""The collision check's cost: the whole post of a job with the bodies checked and without
(``bodies.check: false``), in the same run, as medians of interleaved pairs, and the check's own
seconds (the post's; the verification's check runs inside ``verify``). Run:

    python -m benchmarks.collision [--pairs 5] [CL file]   # default: the impeller
    python -m benchmarks.collision --points 100000          # the generated 105k-block job
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import verne_post as vp
from benchmarks.pipeline import _generator
from verne_post.options import PostOptions
from verne_post.pipeline import post

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("cl", nargs="?", default=str(ROOT / "examples" / "impeller_5axis.cls"))
    parser.add_argument("--pairs", type=int, default=5)
    parser.add_argument("--points", type=int, default=0, help="post the generated job of this many CL points instead")
    args = parser.parse_args()
    checked = vp.load_machine()
    unchecked = checked.model_copy(update={"bodies": checked.bodies.model_copy(update={"check": False})})
    whole: dict[str, list[float]] = {"bodies checked": [], "bodies not checked": []}
    own: list[float] = []
    with tempfile.TemporaryDirectory() as folder:
        if args.points:
            args.cl = str(Path(folder) / "job.cls")
            Path(args.cl).write_text(_generator().generate(args.points))
        for _ in range(args.pairs):
            for name, machine in (("bodies checked", checked), ("bodies not checked", unchecked)):
                start = time.perf_counter()
                posted = post(args.cl, machine, PostOptions(), Path(folder) / "out.nc")
                whole[name].append(time.perf_counter() - start)
                if machine is checked:
                    own.append(posted.seconds.get("collisions", 0.0))
    base = statistics.median(whole["bodies not checked"])
    for name, values in whole.items():
        print(f"{name:20s} median {statistics.median(values):7.2f} s  ratio {statistics.median(values) / base:5.2f}")
    print(f"{'collision stage':20s} median {statistics.median(own):7.2f} s  share of the checked post "
          f"{statistics.median(own) / statistics.median(whole['bodies checked']):5.1%}")


if __name__ == "__main__":
    main()
