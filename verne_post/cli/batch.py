"""``verne-post batch``: many CL files at once, on local processes or Dask."""

from __future__ import annotations

import functools
import io
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import click

from ..output.atomic import check_writable
from .common import Number, choices_after_report, choices_before_report, decorated, output_options, user_errors
from .main import main
from .post import options_from


@main.command("batch")
@click.argument("inputs", metavar="INPUTS...", nargs=-1, required=True)
@click.option("-o", "--output-dir", required=True, type=click.Path(file_okay=False),
              help="Folder of the outputs (made if missing): one per input, same stem, .nc or .csv.")
@click.option("--jobs", type=Number(1, 4096, integer=True), default=None,
              help="Worker processes (default: the CPU count); with --scheduler dask, the local cluster's.")
@click.option("--scheduler", default=None,
              help="Run on a Dask cluster: tcp://HOST:PORT, or 'dask' for a local one "
                   "(pip install 'verne-post[dask]').")
@click.option("--summary", "summary_path", type=click.Path(dir_okay=False),
              help="One row per file: CSV, or JSON when it ends in .json.")
@click.option("--report-each", is_flag=True, help="A JSON report next to each output (STEM.json).")
@click.option("--skip-unchanged", is_flag=True,
              help="Leave out files whose output records the hash of this input, machine file, options and "
                   "verne-post version.")
@functools.partial(decorated, options=[*output_options, *choices_before_report, *choices_after_report])
@user_errors
def batch_command(inputs: tuple[str, ...], output_dir: str, jobs: int | None, scheduler: str | None,
                  summary_path: str | None, report_each: bool, skip_unchanged: bool, output_format: str | None,
                  period: float, decimals: int | None, no_verify: bool, machine_path: str | None, quiet: bool,
                  max_messages: int, no_timing: bool, auto_offset: bool, **choices: Any) -> None:
    """Postprocess many CL files (files, folders, glob patterns) into OUTDIR, on local processes
    or a Dask cluster.

    Each file is posted on its own: a bad file is recorded and the others go on. Exit code 0
    when every file was posted, 2 when any was bad input, else 3 when any could not be posted
    (violations, or a failure); --summary says which and why.
    """
    from ..batch import BatchOptions, batch, exit_code, expand_inputs, open_executor, write_summary

    options = BatchOptions(options_from(no_timing, auto_offset, **choices), output_format or "gcode", period,
                           not no_verify, decimals=decimals)
    files = expand_inputs(inputs)
    if summary_path and Path(summary_path).resolve().parent != Path(output_dir).resolve():
        check_writable(summary_path)  # now, not after the batch (OUTDIR itself is made by the batch)
    show = not quiet and sys.stderr.isatty()
    stream = sys.stderr if show else io.StringIO()
    with open_executor(scheduler, jobs, stages=show) as (executor, width, stages), click.progressbar(
            length=len(files), label="verne-post batch", file=stream, item_show_func=lambda note: note) as bar:
        def on_stage(file: str, stage: str) -> None:
            bar.current_item = f"{Path(file).name}: {stage}"
            bar.render_progress()

        results = batch(files, machine_path, options, executor, output_dir=output_dir, skip_unchanged=skip_unchanged,
                        report_each=report_each, jobs=width, stages=stages, on_stage=on_stage if show else None,
                        on_done=lambda r: bar.update(1, f"{Path(r.file).name}: {r.status}"))
    if summary_path:
        write_summary(summary_path, results)
    failed = [r for r in results if r.exit_code]
    for r in failed[:max_messages]:
        click.echo(f"verne-post: error: {r.message}", err=True)
    if len(failed) > max_messages:
        click.echo(f"verne-post: ... and {len(failed) - max_messages} more failed files", err=True)
    if not quiet:
        counts = ", ".join(f"{n} {status}" for status, n in Counter(r.status for r in results).items())
        click.echo(f"verne-post: {len(results)} files: {counts}", err=True)
    sys.exit(exit_code(results))
