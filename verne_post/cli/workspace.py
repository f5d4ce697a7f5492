"""``verne-post workspace``: a map of the tool-tip workspace for a tool axis."""

from __future__ import annotations

import click
import numpy as np

from ..errors import InputError
from ..machine import load_machine
from ..placement.workspace import EXTENT_Z
from .common import WORK_OFFSET, Number, machine_option, tool_length_option, user_errors
from .main import main


@main.command("workspace")
@click.option("-o", "--output", type=click.Path(dir_okay=False), required=True,
              help="Image file: PNG, or SVG when it ends in .svg.")
@machine_option
@tool_length_option
@click.option("--tilt", type=Number(-180.0, 180.0, " deg"), default=0.0, show_default=True,
              help="Tool axis angle from the table normal, degrees.")
@click.option("--rotary", type=Number(-3600.0, 3600.0, " deg"), default=0.0, show_default=True,
              help="Rotary table angle theta2, degrees (turns the tool axis about the table normal).")
@click.option("--z", "level", type=Number(*EXTENT_Z, " mm"), default=None,
              help="Height of the plan view, mm, table frame (default: where the x-z section is widest).")
# 3 mm: 27 s and 0.65 GiB on this project's 2-core machine; the grid's memory grows as 1 / step^2
@click.option("--step", type=Number(3.0, 200.0, " mm"), default=10.0, show_default=True, help="Grid spacing, mm.")
@click.option("--program", type=click.Path(dir_okay=False), help="Overlay this CL file's tool tips.")
@click.option("--work-offset", nargs=3, type=WORK_OFFSET, default=None,
              help="Work offset of --program, mm (default: the machine file's).")
@user_errors
def workspace_command(output: str, machine_path: str | None, tool_length: float, tilt: float, rotary: float,
                      level: float | None, step: float, program: str | None,
                      work_offset: tuple[float, float, float] | None) -> None:
    """Map of the tool-tip positions (table frame) the machine reaches with the tool axis at
    --tilt and --rotary: x-z and y-z sections through the table centre and a plan view,
    coloured by the smallest headroom to any limit, the limiting constraints labelled."""
    from ..placement.workspace import plot_workspace, workspace

    if not output.lower().endswith((".png", ".svg")):
        raise InputError("the output must end in .png or .svg")
    machine = load_machine(machine_path)
    tips = None
    if program:
        from ..cl import read_toolpath

        offset = np.asarray(work_offset if work_offset else machine.work_offset)
        tips = read_toolpath(program).tip + offset
    plot_workspace(workspace(machine, tool_length=tool_length, tilt=tilt, rotary=rotary, z=level, step=step),
                   output, tips)
