"""``verne-post place``: where to clamp the part (the work offset with the most room)."""

from __future__ import annotations

import functools
import os
import sys
from typing import Any

import click

from ..machine import load_machine
from .common import (
    AXIS_TOL,
    TIP_TOL,
    TOOL_LENGTH,
    Number,
    decorated,
    machine_option,
    read_cl,
    reader_option_group,
    setup_file,
    setup_options,
    user_errors,
)
from .main import main
from .post import PLACEMENT_STEPS, progress_bar


@main.command("place")
@click.argument("cl_file", metavar="PART.cls", type=click.Path(dir_okay=False))
@machine_option
@click.option("--tool-length", type=TOOL_LENGTH, default=None,
              help="Tool length in mm for tools whose length neither the CL file nor the machine gives.")
@click.option("--tol", type=TIP_TOL, default=0.005, show_default=True, help="As for 'post': tip deviation, mm.")
@click.option("--axis-tol", type=AXIS_TOL, default=0.05, show_default=True, help="As for 'post': axis deviation, deg.")
@reader_option_group
@functools.partial(decorated, options=setup_options)
@click.option("--report", "report_path", type=click.Path(dir_okay=False), help="Write the placement as JSON.")
@click.option("--workers", type=Number(1, 1024, integer=True), default=os.cpu_count() or 1, show_default="the cores",
              help="Processes for the room's full checks (directions side by side); 1 runs them all in this one.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
@user_errors
def place_command(cl_file: str, machine_path: str | None, tool_length: float | None, tol: float, axis_tol: float,
                  report_path: str | None, workers: int, quiet: bool, stock: tuple[str, ...], fixtures: tuple[str, ...],
                  setup_path: str | None, **reading: Any) -> None:
    """Where to clamp the part: the work offset at which PART.cls runs with the most room to every
    limit and singularity, and how far the part may move from it and still run.

    Prints the offset to use with 'post --work-offset X Y Z' (or use '--work-offset auto' there).
    Exit code 3 when no offset works, with the reason.
    """
    from ..motion.poses import machine_poses
    from ..options import PostOptions, setup_of
    from ..output.tables import write_json
    from ..placement.search import place

    machine = load_machine(machine_path)
    options = PostOptions(tool_length=tool_length, tol=tol, axis_tol=axis_tol, plan=False, workers=workers,
                          stock=stock, fixtures=fixtures, **setup_file(setup_path), **reading)
    toolpath = read_cl(cl_file, **reading)
    poses = machine_poses(toolpath, machine, work_offset=(0.0, 0.0, 0.0), tool_length=tool_length,
                          setup=setup_of(machine, options, toolpath.units))
    with progress_bar(PLACEMENT_STEPS, quiet) as tick:
        placement = place(machine, poses, options, progress=lambda stage: tick(), room=True)
    if report_path:
        write_json(report_path, {"source": toolpath.source, "machine": machine.source, **placement.to_dict()})
    if not placement.feasible:
        hint = f" (with {toolpath.frame_hint} the tool axes point away from the table)" if toolpath.frame_hint else ""
        click.echo(f"verne-post: error: {toolpath.source}: no work offset lets the whole program run: "
                   f"{placement.reason}{hint}", err=True)
        sys.exit(3)
    x, y, z = placement.offset
    click.echo(f"work offset {x:.3f} {y:.3f} {z:.3f} mm (part zero in the table frame)")
    click.echo(f"smallest headroom {placement.margin:.3f} ({placement.limit}) at {toolpath.source}:{placement.line}")
    for axis, (minus, plus) in zip("XYZ", placement.room or (), strict=True):
        click.echo(f"room {axis} -{minus:.2f} / +{plus:.2f} mm")
    if not quiet:
        click.echo(f"verne-post: {placement.screened} offsets screened, {placement.seconds:.1f} s", err=True)
