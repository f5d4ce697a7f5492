"""``verne-post machine``: check a machine file, explain it, start one, or get its JSON Schema."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from ..errors import InputError
from ..machine import load_machine
from ..output.atomic import atomic_write
from ..output.controller import DIALECTS
from .common import tool_length_option, user_errors
from .main import main


@main.group("machine")
def machine_group() -> None:
    """Machine files: check one, explain it, start one, or get the schema an editor checks it with."""


@machine_group.command("check")
@click.argument("machine_file", metavar="FILE", type=click.Path(dir_okay=False))
@user_errors
def machine_check_command(machine_file: str) -> None:
    """Validate FILE: a summary and exit 0, or every problem as FILE:LINE: key.path: reason and exit 2."""
    from ..machine import machine_problems, machine_text
    from ..placement.machine_facts import summary

    machine, problems = machine_problems(machine_text(machine_file), machine_file)
    if problems:
        for problem in problems:
            click.echo(f"verne-post: error: {problem.error(machine_file)}", err=True)
        sys.exit(2)
    assert machine is not None
    click.echo(f"{machine_file}: valid machine file")
    for line in summary(machine):
        click.echo(f"  {line}")


@machine_group.command("schema")
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
              help="Write the JSON Schema here (default: standard output).")
@user_errors
def machine_schema_command(output: str | None) -> None:
    """The JSON Schema of machine files (every key, its bounds and units), for an editor's checks."""
    from ..placement.machine_facts import schema

    text = json.dumps(schema(), indent=2) + "\n"
    if output is None:
        click.echo(text, nl=False)
        return
    with atomic_write(output) as handle:
        handle.write(text)


@machine_group.command("init")
@click.option("-o", "--output", type=click.Path(dir_okay=False), required=True, help="The machine file to write.")
@click.option("--dialect", type=click.Choice(sorted(DIALECTS)), default="linuxcnc", show_default=True,
              help="The controller the programs are written for (controller.dialect).")
@user_errors
def machine_init_command(output: str, dialect: str) -> None:
    """Write a fully commented machine file to start from: the VERNE as shipped (edit its geometry,
    limits, tools, positions, controller, then 'verne-post machine check' it)."""
    from ..machine import machine_text

    if Path(output).exists():
        raise InputError("exists already: give a new file (nothing is overwritten)", output)
    text = machine_text(None)
    shipped = "\n  dialect: linuxcnc\n"
    assert shipped in text, "the shipped machine file sets controller.dialect"
    with atomic_write(output) as handle:
        handle.write(text.replace(shipped, f"\n  dialect: {dialect}\n"))


@machine_group.command("show")
@click.argument("machine_file", metavar="FILE", type=click.Path(dir_okay=False))
@tool_length_option
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
              help="Also draw the workspace sections: PNG, or SVG when it ends in .svg (needs matplotlib).")
@user_errors
def machine_show_command(machine_file: str, tool_length: float, output: str | None) -> None:
    """What to know before the first run: joint ranges, the reference pose, the workspace for a tool
    (axis along the table normal) and the tightest singularity margins in it."""
    from ..placement.machine_facts import facts, facts_table

    machine = load_machine(machine_file)
    found = facts(machine, tool_length)
    for line in facts_table(machine, found):
        click.echo(line)
    if output is not None:
        from ..placement.workspace import plot_workspace

        plot_workspace(found.workspace, output)
