"""``verne-post calibrate``: identify the geometry and joint zeros from measured tips."""

from __future__ import annotations

import click
import numpy as np

from ..errors import InputError, quote
from ..machine import Machine, load_machine
from ..output.atomic import atomic_write
from ..output.tables import write_table
from .common import TOOL_LENGTH, Number, check_outputs, machine_option, same_file, user_errors
from .main import main


def _parameter_names(values: tuple[str, ...]) -> tuple[str, ...]:
    from ..calibration import PARAMETERS

    names = tuple(name.strip() for value in values for name in value.split(",") if name.strip())
    for name in names:
        if name not in PARAMETERS:
            raise InputError(f"--fix: unknown parameter {quote(name)} (one of {', '.join(PARAMETERS)})")
    return names


def _tool_lengths(text: str | None, machine: Machine) -> list[float]:
    if text is None:
        lengths = sorted({tool.length for tool in machine.tools.values()})
        return lengths or [0.0]
    lengths = []
    for cell in text.split(","):
        lengths.append(TOOL_LENGTH.convert(cell.strip(), None, None))
    return lengths


@main.command("calibrate")
@click.argument("measured", metavar="MEASURED.csv", required=False, type=click.Path(dir_okay=False))
@machine_option
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="The calibrated machine file (YAML); with --plan the poses to measure (CSV).")
@click.option("--report", "report_path", type=click.Path(dir_okay=False),
              help="Report: JSON, or HTML when the name ends in .html/.htm.")
@click.option("--fix", multiple=True, metavar="NAME[,NAME...]",
              help="Hold parameters at their machine-file values (repeatable): geometry keys, rhoN_offset, "
                   "thetaN_offset.")
@click.option("--reject", is_flag=True, help="Drop the poses flagged as outliers and fit again.")
@click.option("--plan", "plan_count", type=Number(1, 100_000, integer=True),
              help="Suggest this many poses to measure (D-optimal, every limit and margin checked) instead.")
@click.option("--tools", help="With --plan: tool lengths in mm, comma-separated (default: the machine's tool table).")
@click.option("--seed", type=Number(0, 2**32 - 1, integer=True), default=0, show_default=True,
              help="With --plan: seed of the candidate poses.")
@user_errors
def calibrate_command(measured: str | None, machine_path: str | None, output: str, report_path: str | None,
                      fix: tuple[str, ...], reject: bool, plan_count: int | None, tools: str | None,
                      seed: int) -> None:
    """Identify the machine's geometry and joint zeros from measured tool-tip positions.

    \b
    MEASURED.csv: rho1,rho2,rho3,theta1,theta2,tool_length,x,y,z[,i,j,k][,weight]
    (joint readings mm/deg, tool length mm, measured tip mm in the table frame).
    Writes the machine file with the identified values and a calibration: block.
    'verne-post calibrate --plan N -o poses.csv' suggests the poses to measure.
    """
    from ..calibration import calibrate, calibrated_text, plan_poses, read_measurements, report_data
    from ..calibration.measurements import check_pose_count
    from ..calibration.model import PARAMETERS, parameters_of
    from ..calibration.report import report_html, report_json
    from ..machine import machine_text

    names = _parameter_names(fix)
    machine = load_machine(machine_path)
    if plan_count is not None:
        if measured is not None:
            raise InputError("--plan writes poses to measure: give no MEASURED.csv with it")
        check_outputs(machine_path or "", output)
        plan = plan_poses(machine, int(plan_count), _tool_lengths(tools, machine), names, int(seed))
        table = {"rho1": plan.joints[:, 0], "rho2": plan.joints[:, 1], "rho3": plan.joints[:, 2],
                 "theta1": np.degrees(plan.joints[:, 3]), "theta2": np.degrees(plan.joints[:, 4]),
                 "tool_length": plan.tool_length, "x_nominal": plan.tip[:, 0], "y_nominal": plan.tip[:, 1],
                 "z_nominal": plan.tip[:, 2]}
        write_table(output, table, dict.fromkeys(table, "%.4f"))
        click.echo(f"{len(plan.joints)} poses written to {output} (measure the tip there; x,y,z_nominal is where "
                   f"the machine file puts it)")
        for name, why in plan.held.items():
            click.echo(f"held: {name}: {why}")
        if plan.std_per_um:
            worst = max(plan.std_per_um, key=plan.std_per_um.get)
            click.echo(f"expected std per um of measuring noise: worst {worst} {plan.std_per_um[worst] * 1e3:.2f} um")
        return
    if measured is None:
        raise InputError("give MEASURED.csv (or --plan N to plan the measurements)")
    check_outputs(measured, output, report_path)
    if machine_path is not None and same_file(output, machine_path):
        raise InputError("the output would overwrite the machine file it starts from", output)
    measurements = read_measurements(measured, machine)
    check_pose_count(measurements, len(PARAMETERS) - len(set(names)))
    result = calibrate(parameters_of(machine), measurements.poses, names, reject)
    text = calibrated_text(machine_text(machine_path), result, measured, output)
    report = None
    if report_path is not None:
        data = report_data(result, measurements, machine.source)
        report = report_html(data) if report_path.lower().endswith((".html", ".htm")) else report_json(data)
    # Everything is computed before the first byte is written; UTF-8: a machine file may hold any text.
    with atomic_write(output, binary=True) as handle:
        handle.write(text.encode("utf-8"))
    if report is not None:
        with atomic_write(report_path, binary=True) as handle:
            handle.write(report.encode("utf-8"))
    s = result.summary()
    click.echo(f"{int(result.used.sum())} poses: tool-tip residual RMS {s['rms_before'] * 1e3:.1f} um (max "
               f"{s['max_before'] * 1e3:.1f}) -> {s['rms_after'] * 1e3:.2f} um (max {s['max_after'] * 1e3:.2f})")
    for name, why in result.reasons.items():
        click.echo(f"held: {name}: {why}")
    flagged = measurements.lines[result.outlier]
    if flagged.size:
        verb = "dropped" if reject else "flagged (use --reject to drop)"
        click.echo(f"outliers {verb}: {measured} lines {', '.join(str(int(x)) for x in flagged)}")
