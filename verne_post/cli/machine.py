"""``verne-post machine``: check a machine file, explain it, start one, or get its JSON Schema."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from ..errors import InputError
from ..machine import load_machine
from ..output.atomic import atomic_write
from ..output.controller import DIALECTS, JOINT_ORDER
from .common import tool_length_option, user_errors
from .main import main

#: The schema's file, as the first line of a machine file names it (beside the file).
SCHEMA_FILE = "verne.schema.json"


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
    for warning in machine.warnings:
        click.echo(f"verne-post: warning: {warning}", err=True)
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
    limits, tools, positions, controller, then 'verne-post machine check' it), and beside it the
    schema its first line names, for an editor's checks (unless one is there)."""
    from ..machine import machine_text
    from ..placement.machine_facts import schema

    if Path(output).exists():
        raise InputError("exists already: give a new file (nothing is overwritten)", output)
    text = machine_text(None)
    start, end = text.index("\n  dialect: linuxcnc\n") + 1, text.index("\n\nsafe:")
    with atomic_write(output) as handle:
        handle.write(text[:start] + controller_keys(dialect) + text[end:])
    beside = Path(output).with_name(SCHEMA_FILE)
    if not beside.exists():
        with atomic_write(beside) as handle:
            handle.write(json.dumps(schema(), indent=2) + "\n")
        click.echo(f"{output}: written, and {beside} for an editor's checks")
    else:
        click.echo(f"{output}: written ({beside} is there already: kept)")


def controller_keys(dialect: str) -> str:
    """The ``controller:`` keys of a machine file: ``dialect``, then every other key commented out
    with the dialect's value (uncommented, each gives what the dialect gives)."""
    preset = DIALECTS[dialect]
    m = preset.m_codes

    def flow(lines: tuple[str, ...]) -> str:
        return json.dumps(list(lines))

    axes = ", ".join(f"{joint}: {letter}" for joint, letter in zip(JOINT_ORDER, preset.axes, strict=True))
    other = "parentheses" if preset.comment == "semicolon" else "semicolon"
    return "\n".join([
        f"  dialect: {dialect}",
        f"  # axes: {{{axes}}}   # the address of each joint",
        f"  # comment: {preset.comment:<23}# or {other}",
        "  # program_number: 1234            # " + ("its O line; " if preset.program_number_line else "")
        + "{program} in the lines below",
        f"  # program_start: {flow(preset.program_start)}",
        f"  # tool_change: {flow(preset.tool_change_lines)}   # {{tool}} {{length}} {{delta}} (mm) {{spindle}} (rpm) "
        "{name} {program}",
        f"  # program_end: {flow(preset.end_lines)}",
        "  # tool_number: 1                  # a CL tool without a number (NX TLDATA alone); absent: by hand",
        "  # block_numbers: {start: 10, step: 10}",
        "  # optional_stop: true             # M1 before every tool change but the first",
        f"  # max_line_length: {preset.max_line_length}",
        f"  # m_codes: {{spindle_cw: {m.spindle_cw}, spindle_ccw: {m.spindle_ccw}, spindle_off: {m.spindle_off}, "
        f"coolant_flood: {m.coolant_flood}, coolant_mist: {m.coolant_mist},",
        f"  #           coolant_through: {m.coolant_through}, coolant_off: {m.coolant_off}, stop: {m.stop}, "
        f"optional_stop: {m.optional_stop}, tool_change: {m.tool_change}, end: {m.end}}}",
    ])


@machine_group.command("show")
@click.argument("machine_file", metavar="FILE", type=click.Path(dir_okay=False))
@tool_length_option
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
              help="Also draw the workspace sections: PNG, or SVG when it ends in .svg (needs matplotlib).")
@user_errors
def machine_show_command(machine_file: str, tool_length: float, output: str | None) -> None:
    """What to know before the first run: joint ranges (with their letters), the reference pose, the
    workspace for a tool above the table (axis along the table normal) and the limits at its edges."""
    from ..placement.machine_facts import facts, facts_table

    machine = load_machine(machine_file)
    found = facts(machine, tool_length)
    for line in facts_table(machine, found):
        click.echo(line)
    if output is not None:
        from ..placement.workspace import plot_workspace

        plot_workspace(found.workspace, output)
