"""``verne-post ik`` and ``verne-post fk``: the kinematics of single poses or CSV files."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click
import numpy as np

from ..api import (
    JOINT_NAMES,
    Status,
    classify,
    forward_kinematics,
    forward_kinematics_all,
    inverse_kinematics,
    inverse_kinematics_pairs,
    joint_bounds,
    pose_margins,
    within_limits,
)
from ..errors import InputError
from ..kinematics import machine_ik_all, module_ik_all
from ..machine import MAX_TOOL_LENGTH, Machine, load_machine
from ..output.tables import read_table, write_table
from .common import (
    COORDINATE,
    angle_scale,
    check_outputs,
    emit,
    machine_option,
    radians_option,
    rounded,
    tool_length_option,
    user_errors,
)
from .main import main


def _unit_axis(axis: tuple[float, float, float], source: str = "--axis", line: int | None = None) -> np.ndarray:
    vector = np.asarray(axis, dtype=float)
    norm = float(np.linalg.norm(vector))
    if not np.isfinite(norm) or norm < 1e-9:
        raise InputError("tool axis has zero length", source, line)
    return vector / norm


def _ik_solutions_json(machine: Machine, tip: np.ndarray, axis: np.ndarray, everything: bool, tool_length: float,
                       scale: float) -> list[dict[str, Any]]:
    geom = machine.kinematic_geometry(tool_length)
    if everything:
        sol = machine_ik_all(geom, tip[None], axis[None])
        rows = [(sol.joints[k], sol.alpha[k], sol.phi[k], bool(sol.working_mode[k])) for k in range(len(sol.alpha))]
        rows.sort(key=lambda r: not r[3])
    else:
        preferred = inverse_kinematics(machine, tip[None], axis[None], tool_length=tool_length)
        pairs = sorted(inverse_kinematics_pairs(machine, tip[None], axis[None], tool_length=tool_length),
                       key=lambda r: r.pair[0] != preferred.pair[0])
        rows = [(r.joints[0], r.alpha[0], r.phi[0], True) for r in pairs if r.status[0] != Status.UNREACHABLE]
    return [
        {
            "rho": rounded(joints[:3]),
            "theta": rounded(joints[3:] * scale),
            "alpha": rounded(alpha * scale),
            "phi": rounded(phi * scale),
            "working_mode": working,
            "within_limits": bool(within_limits(machine, joints[None])[0]),
        }
        for joints, alpha, phi, working in rows
    ]


def _module_solutions_json(machine: Machine, platform: np.ndarray, everything: bool, scale: float
                           ) -> list[dict[str, Any]]:
    sol = module_ik_all(machine.kinematic_geometry(), platform[None])
    order = sorted(range(len(sol.alpha)), key=lambda k: not sol.working_mode[k])
    lower, upper = (b[:3] for b in joint_bounds(machine))
    return [
        {
            "alpha": rounded(sol.alpha[k] * scale),
            "rho": rounded(sol.rho[k]),
            "working_mode": bool(sol.working_mode[k]),
            "within_limits": bool(np.all((sol.rho[k] >= lower) & (sol.rho[k] <= upper))),
        }
        for k in order
        if everything or sol.working_mode[k]
    ]


@main.command("ik")
@click.argument("poses", required=False, type=click.Path(dir_okay=False))
@click.option("-o", "--output", type=click.Path(dir_okay=False), help="Output CSV (batch mode; default stdout).")
@click.option("--tip", nargs=3, type=COORDINATE, help="Tool tip X Y Z in mm, table frame.")
@click.option("--axis", nargs=3, type=COORDINATE, help="Tool axis I J K, table frame (tip towards spindle).")
@click.option("--platform", nargs=3, type=COORDINATE, help="Platform centre X Y Z in mm, base frame (module only).")
@click.option("--all", "everything", is_flag=True, help="All solutions, not only the machine's working mode.")
@machine_option
@tool_length_option
@radians_option
@user_errors
def ik_command(poses: str | None, output: str | None, tip: tuple[float, ...] | None, axis: tuple[float, ...] | None,
               platform: tuple[float, ...] | None, everything: bool, machine_path: str | None, tool_length: float,
               radians: bool) -> None:
    """Inverse kinematics: tool pose (or platform position) to joints, JSON on stdout.

    With POSES.csv (header x,y,z,i,j,k): one output row per input row, same order, columns
    rho1,rho2,rho3,theta1,theta2,alpha,status; one angle pair and a continuous theta2 along
    the file.
    """
    machine = load_machine(machine_path)
    scale = angle_scale(radians)
    if poses is not None:
        if tip or axis or platform:
            raise InputError("give either a POSES file or --tip/--axis/--platform, not both")
        _ik_batch(machine, poses, output, tool_length, scale)
    elif platform:
        emit({"solutions": _module_solutions_json(machine, np.asarray(platform), everything, scale)})
    elif tip and axis:
        solutions = _ik_solutions_json(machine, np.asarray(tip), _unit_axis(axis), everything, tool_length, scale)
        emit({"solutions": solutions})
    else:
        raise InputError("give --tip X Y Z --axis I J K, --platform X Y Z, or a POSES.csv file")


def _ik_batch(machine: Machine, poses: str, output: str | None, tool_length: float, scale: float) -> None:
    from ..cl import read_pose_csv
    from ..motion.branch import solve_path

    check_outputs(poses, output)
    toolpath = read_pose_csv(poses)
    result = solve_path(machine, toolpath.tip, toolpath.axis, tool_length=tool_length).result
    labels = np.array([Status(s).label for s in range(len(Status))])[result.status]
    table = {
        "rho1": result.joints[:, 0], "rho2": result.joints[:, 1], "rho3": result.joints[:, 2],
        "theta1": result.joints[:, 3] * scale, "theta2": result.joints[:, 4] * scale,
        "alpha": result.alpha * scale, "status": labels,
    }
    write_csv(table, output, {"status": "%s"})


def write_csv(table: dict[str, np.ndarray], output: str | None, formats: dict[str, str]) -> None:
    formats = {name: formats.get(name, "%.9f") for name in table}
    if output is None:
        import tempfile

        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "out.csv"
            write_table(path, table, formats)
            click.echo(path.read_text(), nl=False)
    else:
        write_table(output, table, formats)


# ----------------------------------------------------------------------------- fk

#: Columns of the calibration's measurement and plan files that ``fk`` reads past.
MEASURED_COLUMNS = ("x", "y", "z", "i", "j", "k", "weight", "x_nominal", "y_nominal", "z_nominal")


@main.command("fk")
@click.argument("joints_file", metavar="JOINTS.csv", required=False, type=click.Path(dir_okay=False))
@click.option("-o", "--output", type=click.Path(dir_okay=False), help="Output CSV (batch mode; default stdout).")
@click.option("--rho", nargs=3, type=COORDINATE, help="Slider positions RHO1 RHO2 RHO3 in mm.")
@click.option("--theta", nargs=2, type=COORDINATE, help="Table angles THETA1 THETA2 (degrees unless --radians).")
@click.option("--all", "everything", is_flag=True, help="All assembly modes, not only the machine's.")
@machine_option
@tool_length_option
@radians_option
@user_errors
def fk_command(joints_file: str | None, output: str | None, rho: tuple[float, ...] | None,
               theta: tuple[float, ...] | None, everything: bool, machine_path: str | None, tool_length: float,
               radians: bool) -> None:
    """Forward kinematics: sliders (and table angles) to platform pose (and tool pose), JSON.

    With JOINTS.csv (header rho1,rho2,rho3,theta1,theta2[,tool_length]): output columns
    x,y,z,i,j,k,alpha,status (tool tip mm and axis in the table frame). A tool_length column
    (mm) sets each row's tool (--tool-length where its cell is empty); the other columns of a
    calibration's measurement or plan file are read past, so 'fk MEASURED.csv' predicts them.
    """
    machine = load_machine(machine_path)
    scale = angle_scale(radians)
    if joints_file is not None:
        if rho or theta:
            raise InputError("give either a JOINTS file or --rho/--theta, not both")
        _fk_batch(machine, joints_file, output, tool_length, scale)
        return
    if not rho:
        raise InputError("give --rho R1 R2 R3 [--theta T1 T2], or a JOINTS.csv file")
    thetas = np.asarray(theta if theta else (0.0, 0.0)) / scale
    joints = np.r_[rho, thetas][None]
    sol = forward_kinematics_all(machine, joints, tool_length=tool_length)
    order = sorted(range(len(sol.alpha)), key=lambda k: not sol.working_mode[k])
    solutions = []
    for k in order:
        if not (everything or sol.working_mode[k]):
            continue
        entry: dict[str, Any] = {
            "platform": rounded(sol.platform[k]),
            "alpha": rounded(sol.alpha[k] * scale),
            "working_mode": bool(sol.working_mode[k]),
        }
        if theta:
            entry.update(tip=rounded(sol.tip[k]), axis=rounded(sol.axis[k]), phi=rounded(sol.phi[k] * scale))
        solutions.append(entry)
    emit({"solutions": solutions})


def _fk_batch(machine: Machine, path: str, output: str | None, tool_length: float, scale: float) -> None:
    check_outputs(path, output)
    notes: list[str] = []
    columns, lines = read_table(path, JOINT_NAMES, ("tool_length", *MEASURED_COLUMNS), notes)
    for note in notes:
        click.echo(note, err=True)
    joints = np.column_stack([columns[c] for c in JOINT_NAMES])
    joints[:, 3:] /= scale
    tool = columns.get("tool_length", np.full(len(joints), np.nan))
    tool = np.where(np.isnan(tool), tool_length, tool)
    bad = np.flatnonzero((tool < 0) | (tool > MAX_TOOL_LENGTH))
    if bad.size:
        raise InputError(f"tool_length = {tool[bad[0]]:g} mm is outside 0 to {MAX_TOOL_LENGTH:g} mm", path,
                         int(lines[bad[0]]))
    fk = forward_kinematics(machine, joints, tool_length=tool)
    found = pose_margins(machine, joints, fk.platform, fk.alpha, fk.reachable, tool)
    status = classify(machine, joints, fk.reachable, found)
    labels = np.array([Status(s).label for s in range(len(Status))])[status]
    table = {"x": fk.tip[:, 0], "y": fk.tip[:, 1], "z": fk.tip[:, 2], "i": fk.axis[:, 0], "j": fk.axis[:, 1],
             "k": fk.axis[:, 2], "alpha": fk.alpha * scale, "status": labels}
    write_csv(table, output, {"status": "%s"})
