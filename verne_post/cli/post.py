"""``verne-post post`` (also plain ``verne-post PART.cls``): the whole pipeline, writing G-code or a timed CSV."""

from __future__ import annotations

import contextlib
import functools
import io
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import click

from ..errors import CheckError, InputError, one_line
from ..machine import Machine, load_machine
from .common import check_outputs, decorated, output_options, post_options, setup_file, user_errors
from .main import main
from .verify import print_findings


def options_from(no_timing: bool, auto_offset: bool, **choices: Any) -> Any:
    """The :class:`PostOptions` of the command-line choices (machine, --quiet and the like removed)."""
    from ..options import PostOptions

    if auto_offset and choices["work_offset"]:
        raise InputError("give --work-offset either as X Y Z or as auto, once")
    if choices.get("placement_room") and not auto_offset:
        raise InputError("--room measures the room around an offset placement finds: give it with "
                         "--work-offset auto (or run 'verne-post place')")
    offset = "auto" if auto_offset else choices["work_offset"] or None
    setup = setup_file(choices.pop("setup_path", None))
    return PostOptions(**{**choices, "work_offset": offset}, plan=not no_timing, **setup)


def run_pipeline(cl_file: str, machine_path: str | None, quiet: bool, no_timing: bool, auto_offset: bool,
                 **choices: Any) -> tuple[Machine, Any, Any]:
    """Load the machine and run every stage but writing; a progress bar on a terminal."""
    from ..pipeline import postprocess

    options = options_from(no_timing, auto_offset, **choices)
    machine = load_machine(machine_path)
    stages = (4 if no_timing else 5) + (PLACEMENT_STEPS if auto_offset else 0)
    with progress_bar(stages, quiet) as tick:
        result = postprocess(cl_file, machine, options, progress=lambda stage: tick())
    return machine, options, result


def run_post(cl_file: str, output: str | None, verify: bool, report_path: str | None, max_messages: int,
             machine_path: str | None, quiet: bool, no_timing: bool, auto_offset: bool, **choices: Any) -> Any:
    """Load the machine and run every stage a part of the program at a time, writing ``output``
    (None: only check) after the warnings, violations and report (:func:`finish`); a progress
    bar over the parts on a terminal."""
    from ..pipeline import post

    options = options_from(no_timing, auto_offset, **choices)
    machine = load_machine(machine_path)
    stream = sys.stderr if not quiet and sys.stderr.isatty() else io.StringIO()
    with click.progressbar(length=1, label="verne-post", file=stream) as bar:
        def progress(stage: str) -> None:  # "pose K of N" after each part
            if stage.startswith("pose "):
                done, total = map(int, stage.split()[1::2])
                bar.length = total
                bar.update(done - bar.pos)

        return post(cl_file, machine, options, output, verify=verify, timing_figures=bool(report_path),
                    progress=progress, before_writing=lambda posted: finish(machine, options, posted, report_path,
                                                                            quiet, max_messages))


def refusals_reported(command: Callable[..., Any]) -> Callable[..., Any]:
    """A program refused as a whole before its checks (a turning program, one for several heads,
    a feed the controller cannot take: exit 3) still gets its ``--report`` JSON: not ok, the
    refusal as its one violation, at its CL line."""
    from ..output.tables import write_json
    from ..version import __version__

    @functools.wraps(command)
    def wrapper(**kwargs: Any) -> Any:
        try:
            return command(**kwargs)
        except CheckError as error:
            report_path = kwargs.get("report_path")
            if report_path and not wants_html(report_path):
                write_json(report_path, {"source": kwargs["cl_file"], "verne_post": __version__, "ok": False,
                                         "violations": [{"line": error.line, "kind": "refused",
                                                         "message": one_line(error.reason)}], "warnings": []})
            raise

    return wrapper


#: About how many progress calls a placement makes (the bar stops short of the end until done).
PLACEMENT_STEPS = 30


@contextlib.contextmanager
def progress_bar(steps: int, quiet: bool) -> Iterator[Callable[[], None]]:
    """A progress bar on stderr when it is a terminal (never past its last step before the end)."""
    stream = sys.stderr if not quiet and sys.stderr.isatty() else io.StringIO()
    done = 0
    with click.progressbar(length=steps, label="verne-post", file=stream) as bar:
        def tick() -> None:
            nonlocal done
            if done < steps - 1:
                done += 1
                bar.update(1)

        yield tick
        bar.update(steps - done)


def wants_html(report_path: str | None) -> bool:
    """The report is the HTML page (it plots whole-program arrays: the program is posted at once)."""
    return bool(report_path) and report_path.lower().endswith((".html", ".htm"))


def finish(machine: Machine, options: Any, result: Any, report_path: str | None, quiet: bool,
           max_messages: int) -> None:
    from ..output.tables import write_json

    if not quiet:
        for warning in result.warnings[:max_messages]:
            click.echo(f"verne-post: warning: {one_line(warning)}", err=True)
        if len(result.warnings) > max_messages:
            click.echo(f"verne-post: ... and {len(result.warnings) - max_messages} more warnings", err=True)
    for v in result.violations[:max_messages]:
        click.echo(f"verne-post: error: {one_line(f'{result.poses.source}:{v.line}: {v.message}')}", err=True)
    if len(result.violations) > max_messages:
        click.echo(f"verne-post: ... and {len(result.violations) - max_messages} more violations", err=True)
    # the report after the violations: they are printed even when the report cannot be written
    if wants_html(report_path):
        from ..report.html import write_html_report
        from ..report.post_scene import post_scene

        write_html_report(report_path, machine, options, result, scene=post_scene(machine, result))
    elif report_path:
        write_json(report_path, result.report(machine, options))
    if result.violations:
        click.echo(f"verne-post: {len(result.violations)} violation(s): nothing written", err=True)
        sys.exit(3)


@main.command("post")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="Output file: G-code (default PART.nc), or a timed CSV when it ends in .csv.")
@functools.partial(decorated, options=output_options)
@post_options
@user_errors
@refusals_reported
def post_command(cl_file: str, output: str | None, output_format: str | None, period: float, decimals: int | None,
                 no_verify: bool, report_path: str | None, max_messages: int, **choices: Any) -> None:
    """Postprocess PART.cls (APT/CLSF, or a CSV of poses) into joint-space G-code or a timed CSV.

    The G-code is verified before it is written (see 'verne-post verify'): a program that fails
    is not written (exit 3); one that passes carries the certified figures in its header.
    """
    from ..pipeline import write_output

    target = output or str(Path(cl_file).with_suffix(".nc"))
    as_csv = (output_format or ("csv" if target.lower().endswith(".csv") else "gcode")) == "csv"
    if as_csv and choices["no_timing"]:
        raise InputError("a timed CSV needs the time-parametrisation: drop --no-timing")
    check_outputs(cl_file, target, report_path)
    if not as_csv and not wants_html(report_path):  # G-code: a part of the program at a time
        posted = run_post(cl_file, target, not no_verify, report_path, max_messages, **choices)
        if posted.verification is not None and not posted.verification.ok:
            print_findings(posted.verification, max_messages)
            click.echo(f"verne-post: {target}: the program fails its verification: nothing written", err=True)
            sys.exit(3)
        if posted.files and not choices["quiet"]:  # controller.split: tool
            click.echo(f"verne-post: one file per tool: {' '.join(str(f) for f in posted.files)}", err=True)
        return
    machine, options, result = run_pipeline(cl_file, **choices)
    finish(machine, options, result, report_path, choices["quiet"], max_messages)
    verification = write_output(result, machine, options, target, "csv" if as_csv else "gcode", period,
                                verify=not no_verify, decimals=decimals)
    if verification is not None and not verification.ok:
        print_findings(verification, max_messages)
        click.echo(f"verne-post: {target}: the program fails its verification: nothing written", err=True)
        sys.exit(3)
