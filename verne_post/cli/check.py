"""``verne-post check``: every check of 'post' without writing a program."""

from __future__ import annotations

from typing import Any

import click

from .common import check_outputs, post_options, user_errors
from .main import main
from .post import finish, refusals_reported, run_pipeline, run_post, wants_html


@main.command("check")
@post_options
@user_errors
@refusals_reported
def check_command(cl_file: str, report_path: str | None, max_messages: int, **choices: Any) -> None:
    """Run every check of 'post' (and the time-parametrisation) on PART.cls without writing a program."""
    check_outputs(cl_file, report_path)
    if wants_html(report_path):
        machine, options, result = run_pipeline(cl_file, **choices)
        figures = result.figures(machine, timing=False)
        finish(machine, options, result, report_path, choices["quiet"], max_messages)
    else:
        figures = run_post(cl_file, None, False, report_path, max_messages, **choices).figures
    if not choices["quiet"]:
        click.echo(f"verne-post: {cl_file}: ok ({figures.blocks} blocks, {figures.inserted} inserted, cycle time "
                   f"{figures.time:.1f} s)", err=True)
