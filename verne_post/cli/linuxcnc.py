"""``verne-post machine export linuxcnc`` and ``verne-post simulate``: the machine as a LinuxCNC
configuration, and a program run through LinuxCNC's own planner (docs/linuxcnc.md)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import click
import numpy as np

from ..errors import InputError
from ..machine import load_machine
from ..output.atomic import atomic_write
from .common import Number, check_writable, machine_option, read_cl, reader_option_group, user_errors
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
@click.option("--against", "cl_file", type=click.Path(dir_okay=False),
              help="The CL file the program was posted from: the executed tip against its feed moves too "
                   "(at the program header's work offset, else the machine's).")
@click.option("--time-scale", type=TIME_SCALE, default=1.0, show_default=True,
              help="Run LinuxCNC this many times faster than real time (same motion; results drift above 5).")
@click.option("--report", "report_path", type=click.Path(dir_okay=False),
              help="Write the figures as JSON, with each block's planned and executed time.")
@reader_option_group
@user_errors
def simulate_command(program: str, machine_path: str | None, cl_file: str | None, time_scale: float,
                     report_path: str | None, **reading: Any) -> None:
    """Run PART.nc through LinuxCNC 2.9's task, planner and servo loop (headless, a simulation of
    the machine's exported configuration): the executed cycle time against the header's, the time
    lost per block, and how far the tool tip leaves the program's own path (and with --against the
    CL path), by forward kinematics of every servo sample."""
    from ..api import joint_bounds
    from ..linuxcnc.measures import block_times, cl_deviation, path_deviation, program_blocks
    from ..linuxcnc.simulate import header_cycle_time, simulate
    from ..planning.timing import Limits
    from ..verify.reference import Reference

    if report_path is not None:
        check_writable(report_path)
    machine = load_machine(machine_path)
    try:
        text = Path(program).read_text(encoding="utf-8", errors="replace")
    except OSError as error:
        raise InputError(f"cannot read the program: {error.strerror or error}", program) from None
    against = None if cl_file is None else read_cl(cl_file, **reading)  # read first: its errors before the run
    result = simulate(program, machine, time_scale=time_scale)
    planned = header_cycle_time(text)
    path = path_deviation(machine, text, result)
    times = block_times(machine, text, result)
    cl = None
    if against is not None:
        offset = program_blocks(text, machine).work_offset or machine.work_offset
        reference = Reference.of(against, offset)
        cl = cl_deviation(machine, text, result, reference.tip, reference.rapid)
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
    click.echo("  time per block, by planned duration: " + "; ".join(
        f"{label} {count} blocks {plan:.1f} s -> {done:.1f} s" for label, count, plan, done in times.bins if count))
    worst = times.worst(3)
    if worst:
        click.echo("  most time lost at lines: " + ", ".join(
            f"{line} ({1000 * plan:.0f} -> {1000 * done:.0f} ms)" for line, plan, done in worst))
    click.echo(f"  tool tip off the program's path: feeds {path.feeds:.4f} mm, moves between cuts "
               f"{path.between_cuts:.4f} mm (worst at line {path.worst_line})")
    if cl is not None:
        click.echo(f"  tool tip off the CL path ({cl_file}): feeds {cl.feeds:.4f} mm (worst at line {cl.worst_line})")
    click.echo(f"  joints {'within' if within else 'OUTSIDE'} their travel; peak velocity "
               f"{100 * peak_v.max():.0f} %, peak acceleration {100 * peak_a.max():.0f} % of the limits")
    for message in result.errors:
        click.echo(f"  LinuxCNC said: {message}")
    if report_path is not None:
        moved = np.isfinite(times.planned) | (times.executed > 0)
        payload = {
            "program": program, "time_scale": time_scale, "samples": len(result.t), "period_s": result.period,
            "cycle_time_s": {"executed": result.cycle_time, "header": planned},
            "tip_deviation_mm": {"feeds": path.feeds, "between_cuts": path.between_cuts,
                                 "worst_line": path.worst_line, "path_spacing_mm": path.spacing},
            "cl_deviation_mm": None if cl is None else {"against": cl_file, "feeds": cl.feeds,
                                                        "worst_line": cl.worst_line, "path_spacing_mm": cl.spacing},
            "joints_within_travel": within,
            "peak_velocity_of_limit": [float(v) for v in peak_v],
            "peak_acceleration_of_limit": [float(a) for a in peak_a],
            "time_by_planned_duration": [{"blocks": label, "count": count, "planned_s": plan, "executed_s": done}
                                         for label, count, plan, done in times.bins],
            # planned against executed along the program: a block's executed feed is its F x planned / executed
            "blocks": {"line": times.line[moved].tolist(),
                       "planned_s": [None if not np.isfinite(v) else round(float(v), 6) for v in times.planned[moved]],
                       "executed_s": [round(float(v), 6) for v in times.executed[moved]]},
            "linuxcnc_messages": list(result.errors),
        }
        with atomic_write(report_path) as handle:
            handle.write(json.dumps(payload, indent=2, allow_nan=False) + "\n")
