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

#: Rows listed by --check, worst first.
WORST_ROWS = 5


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
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="The calibrated machine file (YAML); with --plan the poses to measure (CSV).")
@click.option("--report", "report_path", type=click.Path(dir_okay=False),
              help="Report: JSON, or HTML when the name ends in .html/.htm.")
@click.option("--fix", multiple=True, metavar="NAME[,NAME...]",
              help="Hold parameters at their machine-file values (repeatable): geometry keys, rhoN_offset, "
                   "thetaN_offset.")
@click.option("--reject", is_flag=True, help="Drop the poses flagged as outliers and fit again.")
@click.option("--check", "check_path", type=click.Path(dir_okay=False), metavar="MEASURED.csv",
              help="Predict these measured poses with --machine and print the tip errors (no fit).")
@click.option("--plan", "plan_count", type=Number(1, 100_000, integer=True),
              help="Suggest this many poses to measure (D-optimal, every limit and margin checked) instead; "
                   "with MEASURED.csv, poses to add to those.")
@click.option("--volume", metavar="SPEC",
              help="With --plan: where the probe can measure the tip, table frame, mm: box:x0,y0,z0,x1,y1,z1 or "
                   "cylinder:cx,cy,z0,z1,r (default: 400 mm above the table's face, as wide as the table).")
@click.option("--tools", help="With --plan: tool lengths in mm, comma-separated (default: the machine's tool table).")
@click.option("--seed", type=Number(0, 2**32 - 1, integer=True), default=0, show_default=True,
              help="With --plan: seed of the candidate poses.")
@user_errors
def calibrate_command(measured: str | None, machine_path: str | None, output: str | None, report_path: str | None,
                      fix: tuple[str, ...], reject: bool, check_path: str | None, plan_count: int | None,
                      volume: str | None, tools: str | None, seed: int) -> None:
    """Identify the machine's geometry and joint zeros from measured tool-tip positions.

    \b
    MEASURED.csv: rho1,rho2,rho3,theta1,theta2,tool_length,x,y,z[,i,j,k][,weight]
    (joint readings mm/deg, tool length mm, measured tip mm in the table frame).
    Writes the machine file with the identified values and a calibration: block.
    'verne-post calibrate --plan N -o poses.csv' suggests the poses to measure;
    'verne-post calibrate --check MEASURED.csv --machine CAL.yaml' predicts them, no fit.
    """
    from ..calibration import calibrate, calibrated_text, read_measurements, report_data
    from ..calibration.fit import TooFewPosesError
    from ..calibration.model import parameters_of
    from ..calibration.report import report_html, report_json
    from ..machine import machine_text

    names = _parameter_names(fix)
    machine = load_machine(machine_path)
    if check_path is not None:
        if measured is not None or plan_count is not None or output is not None:
            raise InputError("--check predicts the measured poses it is given: no MEASURED.csv, --plan or -o with it")
        _check(machine, check_path)
        return
    if output is None:
        raise InputError("give -o: the calibrated machine file (or, with --plan, the poses to measure)")
    if volume is not None and plan_count is None:
        raise InputError("--volume is for --plan: where the planned tips must lie")
    if plan_count is not None:
        _plan(machine, machine_path, measured, output, int(plan_count), tools, names, int(seed), volume)
        return
    if measured is None:
        raise InputError("give MEASURED.csv (or --plan N to plan the measurements)")
    check_outputs(measured, output, report_path)
    if machine_path is not None and same_file(output, machine_path):
        raise InputError("the output would overwrite the machine file it starts from", output)
    measurements = read_measurements(measured, machine)
    for note in measurements.notes:
        click.echo(note)
    try:
        result = calibrate(parameters_of(machine), measurements.poses, names, reject)
    except TooFewPosesError as error:
        raise InputError(error.reason, measurements.source, int(measurements.lines[-1])) from None
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
               f"{s['max_before'] * 1e3:.1f}) -> {s['rms_after'] * 1e3:.2f} um (max {s['max_after'] * 1e3:.2f}); "
               f"noise estimate {result.sigma * 1e3:.2f} um")
    for name in names:
        click.echo(f"held: {name}: fixed by --fix")
    for note in result.notes:
        click.echo(f"not determined: {note}")
    flagged = measurements.lines[result.outlier]
    if flagged.size:
        what = ("dropped" if reject else
                "flagged (the values come from the robust fit, which gives them little weight; --reject drops them)")
        click.echo(f"outliers {what}: {measured} lines {', '.join(str(int(x)) for x in flagged)}")


def _plan(machine: Machine, machine_path: str | None, measured: str | None, output: str, count: int,
          tools: str | None, names: tuple[str, ...], seed: int, volume_spec: str | None) -> None:
    """``--plan``: write ``count`` poses to measure (added to ``measured`` when given)."""
    from ..calibration import PARAMETERS, parse_volume, plan_poses, read_measurements
    from ..calibration.directions import WEAK_STD, explain
    from ..calibration.model import SCALE, to_interface, unit

    check_outputs(machine_path or "", output)
    if measured is not None:
        check_outputs(measured, output)
    volume = parse_volume(volume_spec) if volume_spec is not None else None
    given = read_measurements(measured, machine).poses if measured is not None else None
    plan = plan_poses(machine, count, _tool_lengths(tools, machine), names, seed, volume, given)
    table = {"rho1": plan.joints[:, 0], "rho2": plan.joints[:, 1], "rho3": plan.joints[:, 2],
             "theta1": np.degrees(plan.joints[:, 3]), "theta2": np.degrees(plan.joints[:, 4]),
             "tool_length": plan.tool_length, "x_nominal": plan.tip[:, 0], "y_nominal": plan.tip[:, 1],
             "z_nominal": plan.tip[:, 2]}
    write_table(output, table, dict.fromkeys(table, "%.4f"))
    click.echo(f"{len(plan.joints)} poses written to {output}, tips in {plan.volume.spec} (measure the tip there; "
               "x,y,z_nominal is where the machine file puts it)")
    for name in names:
        click.echo(f"held: {name}: fixed by --fix")
    for direction in plan.directions:
        if direction.weak:
            click.echo(f"not determined: {explain(direction)}")
    determined = {n: v for n, v in plan.std.items() if v < WEAK_STD * SCALE[PARAMETERS.index(n)]}
    if determined:
        worst = max(determined, key=determined.get)
        std = to_interface(worst, determined[worst]) * 1e3
        click.echo(f"expected std with 3 um measuring noise: worst {worst} {std:.2f} "
                   f"{'mdeg' if unit(worst) == 'deg' else 'um'} (of the parameters the plan determines)")


def _check(machine: Machine, path: str) -> None:
    """``--check``: the tip errors of measured poses predicted by ``machine`` (no fit)."""
    from ..calibration import predict, read_measurements
    from ..calibration.model import parameters_of

    measurements = read_measurements(path, machine)
    for note in measurements.notes:
        click.echo(note)
    poses = measurements.poses
    error = predict(parameters_of(machine), poses.joints, poses.tool_length).tip - poses.tip
    norm = np.linalg.norm(error, axis=1)
    click.echo(f"{len(norm)} poses predicted by {machine.source}: tip error (predicted - measured) RMS "
               f"{np.sqrt(np.mean(norm**2)) * 1e3:.2f} um, max {norm.max() * 1e3:.2f} um")
    for k in np.argsort(-norm, kind="stable")[:WORST_ROWS]:
        dx, dy, dz = error[k] * 1e3
        click.echo(f"  {path}:{int(measurements.lines[k])}: {norm[k] * 1e3:.2f} um (x {dx:+.2f}, y {dy:+.2f}, "
                   f"z {dz:+.2f}), tool {poses.tool_length[k]:g} mm")
