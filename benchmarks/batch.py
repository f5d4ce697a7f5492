"""Batch throughput: files per second with 1 and 2 local worker processes and on a 2-worker Dask
LocalCluster, in one run, with the scaling ratios.

    python -m benchmarks.batch [--files 40] [--min-points 500] [--max-points 5000]

Generates ``--files`` jobs of the 5-axis example (examples/generate_job.py) with sizes spread
evenly from ``--min-points`` to ``--max-points`` GOTO points (shuffled, so each worker gets a mix),
posts them with ``verne_post.batch`` (G-code, timing and verification on, as the command does) on
each executor, and checks that every run wrote the same bytes. Workers are started and have
loaded verne-post before the clock starts: the figures are the steady rate of a long batch.
The load average is printed first: on a busy machine the ratios mean little.
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
from concurrent.futures import Executor  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import verne_post as vp  # noqa: E402
from verne_post.batch import dask_client, local_executor  # noqa: E402

from .pipeline import _generator  # noqa: E402


def _warm(_: int) -> None:
    """Load the pipeline in a worker (and keep it busy a moment, so that each worker gets one)."""
    import verne_post.pipeline  # noqa: F401

    time.sleep(0.5)


@contextlib.contextmanager
def _dask(workers: int) -> Iterator[Executor]:
    """The local Dask cluster ``verne-post batch --scheduler dask`` starts, and its executor."""
    with dask_client("dask", workers) as client, client.get_executor(pure=False) as executor:
        yield executor


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--files", type=int, default=40)
    parser.add_argument("--min-points", type=int, default=500)
    parser.add_argument("--max-points", type=int, default=5000)
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} CPUs")
    sizes = np.linspace(args.min_points, args.max_points, args.files).round().astype(int)
    np.random.default_rng(0).shuffle(sizes)
    generate = _generator().generate
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        (root / "jobs").mkdir()
        files = []
        for k, points in enumerate(sizes):
            files.append(root / "jobs" / f"job_{k:02d}.cls")
            files[-1].write_text(generate(int(points)))
        print(f"{len(files)} jobs of {sizes.min()} to {sizes.max()} points ({sizes.sum()} in all)")
        runs = {"local, 1 worker": lambda: local_executor(1), "local, 2 workers": lambda: local_executor(2),
                "Dask LocalCluster, 2 workers": lambda: _dask(2)}
        rates, outputs = {}, {}
        for label, make in runs.items():
            width = 1 if "1 worker" in label else 2
            with make() as executor:
                list(executor.map(_warm, range(width)))
                start = time.perf_counter()
                results = vp.batch(files, None, vp.BatchOptions(), executor, output_dir=root / label, jobs=width)
                elapsed = time.perf_counter() - start
            failed = [r for r in results if r.status != "ok"]
            assert not failed, failed[:3]
            rates[label] = len(files) / elapsed
            outputs[label] = [Path(r.output).read_bytes() for r in results]
            print(f"{label:30s} {elapsed:7.1f} s  {rates[label]:6.2f} files/s")
        base = rates["local, 1 worker"]
        print(f"scaling, 2 local workers / 1: {rates['local, 2 workers'] / base:.2f}")
        print(f"scaling, Dask 2 workers / local 1: {rates['Dask LocalCluster, 2 workers'] / base:.2f}")
        same = all(o == outputs["local, 1 worker"] for o in outputs.values())
        print(f"outputs byte-identical across the three runs: {'yes' if same else 'NO'}")


if __name__ == "__main__":
    main()
