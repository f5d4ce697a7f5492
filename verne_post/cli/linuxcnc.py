"""``verne-post machine export linuxcnc`` and ``verne-post simulate``: the machine as a LinuxCNC
configuration, and a program run through LinuxCNC's own planner (docs/linuxcnc.md)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import click
import numpy as np

from ..errors import InputError
from ..machine import load_machine
from ..output.atomic import atomic_write
from .common import Number, check_writable, machine_option, user_errors
from .machine import machine_group
from .main import main

#: Time scales simulate takes: above 5 the results drift (docs/linuxcnc.md).
TIME_SCALE = Number(0.1, 10.0)


@machine_group.group("export")
def export_group() -> None:
    """The machine file as another system's configuration."""


@export_group.command("linuxcnc")
@click.option("-o", "--output", "directory", type=click.Path(file_okay=False), required=True,
              help="The directory to write verne.ini, verne.hal and verne.tbl into (created if missing).")
@machine_option
@user_errors
def export_linuxcnc_command(directory: str, machine_path: str | None) -> None:
    """A LinuxCNC 2.9 configuration of the machine in joint space (trivkins, 5 joints, the machine
    file's limits and home), a simulation as written: run it with 'linuxcnc DIR/verne.ini'."""
    from ..linuxcnc.export import export_config

    ini = export_config(load_machine(machine_path), directory)
    click.echo(f"{ini}: LinuxCNC configuration (run: linuxcnc {ini})")


@main.command("simulate")
@click.argument("program", metavar="PART.nc", type=click.Path(dir_okay=False))
@machine_option
@click.option("--time-scale", type=TIME_SCALE, default=1.0, show_default=True,
              help="Run LinuxCNC this many times faster than real time (same motion; results drift above 5).")
@click.option("--report", "report_path", type=click.Path(dir_okay=False), help="Write the figures as JSON.")
@user_errors
def simulate_command(program: str, machine_path: str | None, time_scale: float, report_path: str | None) -> None:
    """Run PART.nc through LinuxCNC 2.9's task, planner and servo loop (headless, a simulation of
    the machine's exported configuration): the executed cycle time against the header's, and how far
    the tool tip leaves the program's own path (by forward kinematics of every servo sample)."""
    from ..api import joint_bounds
    from ..linuxcnc.simulate import header_cycle_time, path_deviation, simulate
    from ..planning.timing import Limits

    if report_path is not None:
        check_writable(report_path)
    machine = load_machine(machine_path)
    try:
        text = Path(program).read_text(encoding="utf-8", errors="replace")
    except OSError as error:
        raise InputError(f"cannot read the program: {error.strerror or error}", program) from None
    result = simulate(program, machine, time_scale=time_scale)
    planned = header_cycle_time(text)
    path = path_deviation(machine, text, result)
    lower, upper = joint_bounds(machine)
    within = bool(np.all((result.joints >= lower - 1e-9) & (result.joints <= upper + 1e-9)))
    limits = Limits.from_machine(machine)
    velocity = np.abs(np.diff(result.joints, axis=0)) / result.period
    acceleration = np.abs(np.diff(result.joints, n=2, axis=0)) / result.period**2
    peak_v = velocity.max(axis=0, initial=0.0) / limits.velocity
    peak_a = acceleration.max(axis=0, initial=0.0) / limits.acceleration

    click.echo(f"{program}: run by LinuxCNC (time scale {time_scale:g}), {len(result.t)} servo samples")
    if planned is not None:
        change = 100.0 * (result.cycle_time - planned) / planned if planned > 0 else math.nan
        click.echo(f"  cycle time: executed {result.cycle_time:.3f} s, header {planned:.1f} s ({change:+.1f} %)")
    else:
        click.echo(f"  cycle time: executed {result.cycle_time:.3f} s (the header gives none)")
    click.echo(f"  tool tip off the program's path: feeds {path.feeds:.4f} mm, moves between cuts "
               f"{path.between_cuts:.4f} mm (worst at line {path.worst_line})")
    click.echo(f"  joints {'within' if within else 'OUTSIDE'} their travel; peak velocity "
               f"{100 * peak_v.max():.0f} %, peak acceleration {100 * peak_a.max():.0f} % of the limits")
    for message in result.errors:
        click.echo(f"  LinuxCNC said: {message}")
    if report_path is not None:
        payload = {
            "program": program, "time_scale": time_scale, "samples": len(result.t), "period_s": result.period,
            "cycle_time_s": {"executed": result.cycle_time, "header": planned},
            "tip_deviation_mm": {"feeds": path.feeds, "between_cuts": path.between_cuts,
                                 "worst_line": path.worst_line, "path_spacing_mm": path.spacing},
            "joints_within_travel": within,
            "peak_velocity_of_limit": [float(v) for v in peak_v],
            "peak_acceleration_of_limit": [float(a) for a in peak_a],
            "linuxcnc_messages": list(result.errors),
        }
        with atomic_write(report_path) as handle:
            handle.write(json.dumps(payload, indent=2, allow_nan=False) + "\n")
