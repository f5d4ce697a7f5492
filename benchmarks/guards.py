"""The cost of the LinuxCNC guard blocks' decision (verne_post.linuxcnc.blending.corner_guards) on the
impeller: the blocks of each part as the pipeline hands them over (one post, default machine and
options), then corner_guards on them as shipped (the blend estimate and its bound decide, the full
kinematics only where they cannot: verne_post.linuxcnc.blend_bound) and with every corner decided
by the full kinematics (an estimate whose bound tells nothing: how main decided), interleaved, as
medians; the two must give the same guards to the bit. Run: python -m benchmarks.guards [--runs 5] [CL file]."""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import verne_post as vp
from verne_post import pipeline
from verne_post.linuxcnc import blending
from verne_post.options import PostOptions

ROOT = Path(__file__).resolve().parent.parent


def _full_kinematics(machine: vp.Machine, blocks: object, corner: np.ndarray, *rest: object
                     ) -> tuple[np.ndarray, np.ndarray]:
    """An estimate whose bound is infinite: every corner goes to the full kinematics."""
    return np.zeros(len(corner)), np.full(len(corner), np.inf)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("cl", nargs="?", default=str(ROOT / "examples" / "impeller_5axis.cls"))
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args()
    machine = vp.load_machine()
    parts = []
    shipped = pipeline.corner_guards

    def capture(*given: object, **options: object) -> tuple[np.ndarray, np.ndarray]:
        parts.append((given, options))
        return shipped(*given, **options)

    pipeline.corner_guards = capture
    try:
        with tempfile.TemporaryDirectory() as folder:
            pipeline.post(args.cl, machine, PostOptions(), Path(folder) / "out.nc")
    finally:
        pipeline.corner_guards = shipped
    estimate = blending.blend_estimate
    seconds: dict[str, list[float]] = {"estimate and bound": [], "full kinematics": []}
    for _ in range(args.runs):
        found = {}
        for name, decide in (("estimate and bound", estimate), ("full kinematics", _full_kinematics)):
            blending.blend_estimate = decide
            start = time.perf_counter()
            found[name] = [blending.corner_guards(*given, **options) for given, options in parts]
            seconds[name].append(time.perf_counter() - start)
        blending.blend_estimate = estimate
        for fast, full in zip(*found.values(), strict=True):
            if not (np.array_equal(fast[0], full[0]) and np.array_equal(fast[1], full[1])):
                raise SystemExit("the guards differ")
    blocks = sum(len(given[1].joints) for given, _ in parts)  # type: ignore[attr-defined]
    guarded = sum(int(np.count_nonzero(before)) for before, _ in found["full kinematics"])
    print(f"{len(parts)} parts, {blocks} blocks, {guarded} corners guarded; the same guards both ways")
    base = statistics.median(seconds["full kinematics"])
    for name, values in seconds.items():
        print(f"corner_guards, {name:20s} median {statistics.median(values):6.3f} s  ratio "
              f"{statistics.median(values) / base:5.3f}")


if __name__ == "__main__":
    main()
