"""Command line: ``verne-post part.cls -o part.nc`` plus ``ik``, ``fk`` and ``check``.

A thin layer: parse options, call the library, print. mm and degrees at this interface
(``--radians`` switches angles to radians); user mistakes exit with a one-line message.
"""

from __future__ import annotations

import functools
import io
import json
import math
import os
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click
import numpy as np

from .api import (
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
from .atomic import check_writable
from .errors import InputError, UserError, one_line, quote
from .kinematics import machine_ik_all, module_ik_all
from .machine import MAX_TOOL_LENGTH, Machine, load_machine
from .tables import read_table, write_table


class _DefaultToPost(click.Group):
    """``verne-post FILE ...`` runs the ``post`` command; named subcommands work as usual."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        if args and args[0] not in self.commands and args[0] not in ("--help", "-h", "--version"):
            args = ["post", *args]
        return super().parse_args(ctx, args)

    def main(self, *args: Any, **kwargs: Any) -> Any:
        """Command-line mistakes as one line (``verne-post: error: ...``), exit code 2.

        Python warnings (e.g. numpy's on NaN arithmetic in rejected input) are not shown: every
        line on stderr is one of verne-post's own messages.
        """
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return super().main(*args, standalone_mode=False, **kwargs)
        except click.ClickException as error:
            click.echo(f"verne-post: error: {one_line(error.format_message())}", err=True)
            sys.exit(error.exit_code)
        except click.Abort:
            click.echo("verne-post: aborted", err=True)
            sys.exit(1)


def user_errors(function: Callable[..., Any]) -> Callable[..., Any]:
    """Turn :class:`UserError` into a one-line message and its exit code (no traceback)."""

    @functools.wraps(function)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return function(*args, **kwargs)
        except UserError as error:
            click.echo(f"verne-post: error: {error}", err=True)
            sys.exit(error.exit_code)

    return wrapper


class Number(click.ParamType):
    """A finite number in [low, high] (optionally also exactly 0): NaN, infinities, values that
    overflow and absurd magnitudes are command-line mistakes, not numbers to compute with."""

    def __init__(self, low: float, high: float, unit: str = "", zero: bool = False, integer: bool = False) -> None:
        self.low, self.high, self.unit, self.zero, self.integer = low, high, unit, zero, integer
        self.name = "integer" if integer else "number"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> float | int:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            number = value
        else:
            try:
                number = int(value) if self.integer else float(value)
            except ValueError:
                self.fail(f"{quote(value)} is not {'an integer' if self.integer else 'a number'}", param, ctx)
        if not math.isfinite(number):
            self.fail(f"{quote(value)} is not a finite number", param, ctx)
        if not (self.low <= number <= self.high or (self.zero and number == 0)):
            bounds = f"{self.low} to {self.high}" if self.integer else f"{self.low:g} to {self.high:g}"
            allowed = f"0 or {bounds}" if self.zero else bounds
            self.fail(f"{quote(value)} is out of range ({allowed}{self.unit})", param, ctx)
        return number


#: Finest timed-CSV period (s): below any controller's servo period; keeps the output finite.
MIN_PERIOD = 1e-4

#: Magnitudes beyond any machine: coordinates (mm) and joint values (mm, degrees or radians).
COORDINATE = Number(-1e6, 1e6)
TOOL_LENGTH = Number(0.0, MAX_TOOL_LENGTH, " mm")

machine_option = click.option("--machine", "machine_path", type=click.Path(dir_okay=False),
                              help="Machine YAML file (default: the shipped VERNE).")
tool_length_option = click.option("--tool-length", type=TOOL_LENGTH, default=0.0, show_default=True,
                                  help="Tool length in mm (Delta = spindle nose distance + this).")
radians_option = click.option("--radians", is_flag=True, help="Angles in radians instead of degrees.")


def _check_outputs(source: str, *outputs: str | None) -> None:
    """Fail now, not after a long run: an output that cannot be written, that is the input, or
    two outputs that are one file (devices such as /dev/null excepted)."""
    given = [path for path in outputs if path]
    for k, path in enumerate(given):
        check_writable(path)
        for other, what in [(source, "the input file"), *((o, "another output") for o in given[:k])]:
            if _same_file(path, other):
                raise InputError(f"the output would overwrite {what}", path)


def _same_file(a: str, b: str) -> bool:
    if os.path.realpath(a) == os.path.realpath(b):
        return not os.path.exists(a) or os.path.isfile(a)
    try:
        return os.path.isfile(a) and os.path.samefile(a, b)
    except OSError:
        return False


def _angle_scale(radians: bool) -> float:
    return 1.0 if radians else 180.0 / np.pi


def _rounded(values: np.ndarray | float) -> Any:
    array = np.round(np.asarray(values, dtype=float), 9)
    return array.tolist()


def _emit(payload: dict[str, Any]) -> None:
    click.echo(json.dumps(payload, indent=2, allow_nan=False))


@click.group(cls=_DefaultToPost, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="verne-post")
def main() -> None:
    """Postprocessor for the VERNE 5-axis machine: CL data to joint-space G-code.

    \b
    verne-post part.cls -o part.nc        postprocess (same as 'verne-post post ...')
    verne-post check part.cls             everything but writing the program
    verne-post ik / fk ...                kinematics of single poses or CSV files
    """


# ----------------------------------------------------------------------------- ik


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
            "rho": _rounded(joints[:3]),
            "theta": _rounded(joints[3:] * scale),
            "alpha": _rounded(alpha * scale),
            "phi": _rounded(phi * scale),
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
            "alpha": _rounded(sol.alpha[k] * scale),
            "rho": _rounded(sol.rho[k]),
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
    scale = _angle_scale(radians)
    if poses is not None:
        if tip or axis or platform:
            raise InputError("give either a POSES file or --tip/--axis/--platform, not both")
        _ik_batch(machine, poses, output, tool_length, scale)
    elif platform:
        _emit({"solutions": _module_solutions_json(machine, np.asarray(platform), everything, scale)})
    elif tip and axis:
        solutions = _ik_solutions_json(machine, np.asarray(tip), _unit_axis(axis), everything, tool_length, scale)
        _emit({"solutions": solutions})
    else:
        raise InputError("give --tip X Y Z --axis I J K, --platform X Y Z, or a POSES.csv file")


def _ik_batch(machine: Machine, poses: str, output: str | None, tool_length: float, scale: float) -> None:
    from .branch import solve_path
    from .cl import read_pose_csv

    _check_outputs(poses, output)
    toolpath = read_pose_csv(poses)
    result = solve_path(machine, toolpath.tip, toolpath.axis, tool_length=tool_length).result
    labels = np.array([Status(s).label for s in range(len(Status))])[result.status]
    table = {
        "rho1": result.joints[:, 0], "rho2": result.joints[:, 1], "rho3": result.joints[:, 2],
        "theta1": result.joints[:, 3] * scale, "theta2": result.joints[:, 4] * scale,
        "alpha": result.alpha * scale, "status": labels,
    }
    _write_csv(table, output, {"status": "%s"})


def _write_csv(table: dict[str, np.ndarray], output: str | None, formats: dict[str, str]) -> None:
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

    With JOINTS.csv (header rho1,rho2,rho3,theta1,theta2): output columns
    x,y,z,i,j,k,alpha,status (tool tip mm and axis in the table frame).
    """
    machine = load_machine(machine_path)
    scale = _angle_scale(radians)
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
            "platform": _rounded(sol.platform[k]),
            "alpha": _rounded(sol.alpha[k] * scale),
            "working_mode": bool(sol.working_mode[k]),
        }
        if theta:
            entry.update(tip=_rounded(sol.tip[k]), axis=_rounded(sol.axis[k]), phi=_rounded(sol.phi[k] * scale))
        solutions.append(entry)
    _emit({"solutions": solutions})


def _fk_batch(machine: Machine, path: str, output: str | None, tool_length: float, scale: float) -> None:
    _check_outputs(path, output)
    columns, _ = read_table(path, JOINT_NAMES)
    joints = np.column_stack([columns[c] for c in JOINT_NAMES])
    joints[:, 3:] /= scale
    fk = forward_kinematics(machine, joints, tool_length=tool_length)
    found = pose_margins(machine, joints, fk.platform, fk.alpha, fk.reachable, tool_length)
    status = classify(machine, joints, fk.reachable, found)
    labels = np.array([Status(s).label for s in range(len(Status))])[status]
    table = {"x": fk.tip[:, 0], "y": fk.tip[:, 1], "z": fk.tip[:, 2], "i": fk.axis[:, 0], "j": fk.axis[:, 1],
             "k": fk.axis[:, 2], "alpha": fk.alpha * scale, "status": labels}
    _write_csv(table, output, {"status": "%s"})


# ----------------------------------------------------------------------------- post / check


def _post_options(function: Callable[..., Any]) -> Callable[..., Any]:
    options = [
        click.argument("cl_file", metavar="PART.cls", type=click.Path(dir_okay=False)),
        machine_option,
        click.option("--tool-length", type=TOOL_LENGTH, default=None,
                     help="Tool length in mm for tools whose length neither the CL file nor the machine gives."),
        click.option("--work-offset", nargs=3, type=Number(-1e4, 1e4, " mm"), default=None,
                     help="Part zero X Y Z in the table frame, mm (default: the machine file's)."),
        click.option("--units", type=click.Choice(["mm", "inch"]), default=None, help="Override the CL file's units."),
        click.option("--tol", type=Number(1e-6, 10.0, " mm"), default=0.005, show_default=True,
                     help="Tool tip deviation allowed between blocks, mm."),
        click.option("--axis-tol", type=Number(1e-6, 10.0, " deg"), default=0.05, show_default=True,
                     help="Tool axis deviation allowed between blocks, degrees."),
        click.option("--arc-tol", type=Number(1e-6, 10.0, " mm"), default=0.001, show_default=True,
                     help="Chordal deviation of CIRCLE arcs expanded into CL points, mm (adds to --tol)."),
        click.option("--report", "report_path", type=click.Path(dir_okay=False),
                     help="Write violations and statistics as JSON."),
        click.option("--no-timing", is_flag=True,
                     help="Skip time-parametrisation: feeds from the programmed feed and joint velocities only."),
        click.option("--quiet", "-q", is_flag=True, help="No progress bar and no warnings on stderr."),
        click.option("--max-messages", type=Number(0, 10**6, integer=True), default=20, show_default=True,
                     help="Violations printed before the count."),
    ]
    for option in reversed(options):
        function = option(function)
    return function


def _run_pipeline(cl_file: str, machine_path: str | None, quiet: bool, no_timing: bool,
                  **choices: Any) -> tuple[Machine, Any, Any]:
    """Load the machine and run every stage but writing; a progress bar on a terminal."""
    from .pipeline import PostOptions, postprocess

    machine = load_machine(machine_path)
    options = PostOptions(**{**choices, "work_offset": choices["work_offset"] or None}, plan=not no_timing)
    stages = 4 if no_timing else 5
    stream = sys.stderr if not quiet and sys.stderr.isatty() else io.StringIO()
    with click.progressbar(length=stages, label="verne-post", file=stream) as bar:
        result = postprocess(cl_file, machine, options, progress=lambda stage: bar.update(1))
    return machine, options, result


def _finish(machine: Machine, options: Any, result: Any, report_path: str | None, quiet: bool,
            max_messages: int) -> None:
    from .tables import write_json

    if not quiet:
        for warning in result.warnings[:max_messages]:
            click.echo(f"verne-post: warning: {one_line(warning)}", err=True)
        if len(result.warnings) > max_messages:
            click.echo(f"verne-post: ... and {len(result.warnings) - max_messages} more warnings", err=True)
    for v in result.violations[:max_messages]:
        click.echo(f"verne-post: error: {one_line(f'{result.poses.source}:{v.line}: {v.message}')}", err=True)
    if len(result.violations) > max_messages:
        click.echo(f"verne-post: ... and {len(result.violations) - max_messages} more violations", err=True)
    if report_path:  # after the violations: they are printed even when the report cannot be written
        write_json(report_path, result.report(machine, options))
    if result.violations:
        click.echo(f"verne-post: {len(result.violations)} violation(s): nothing written", err=True)
        sys.exit(3)


@main.command("post")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="Output file: G-code (default PART.nc), or a timed CSV when it ends in .csv.")
@click.option("--format", "output_format", type=click.Choice(["gcode", "csv"]), default=None,
              help="Output format (default: from the output file's suffix).")
@click.option("--period", type=Number(MIN_PERIOD, 60.0, " s", zero=True), default=0.001, show_default=True,
              help="Timed CSV sample period in s; 0 gives one row per block end.")
@_post_options
@user_errors
def post_command(cl_file: str, output: str | None, output_format: str | None, period: float,
                 report_path: str | None, max_messages: int, **choices: Any) -> None:
    """Postprocess PART.cls (APT/CLSF, or a CSV of poses) into joint-space G-code or a timed CSV."""
    from .gcode import write_program
    from .pipeline import gcode_format
    from .trajectory import write_timed_csv

    target = output or str(Path(cl_file).with_suffix(".nc"))
    as_csv = (output_format or ("csv" if target.lower().endswith(".csv") else "gcode")) == "csv"
    if as_csv and choices["no_timing"]:
        raise InputError("a timed CSV needs the time-parametrisation: drop --no-timing")
    _check_outputs(cl_file, target, report_path)
    machine, options, result = _run_pipeline(cl_file, **choices)
    _finish(machine, options, result, report_path, choices["quiet"], max_messages)
    if as_csv:
        blocks = result.blocks
        write_timed_csv(target, machine, result.schedule, result.poses.tool_length[blocks.pose],
                        result.poses.line[blocks.pose], period)
    else:
        write_program(result.program, gcode_format(machine), target)


@main.command("check")
@_post_options
@user_errors
def check_command(cl_file: str, report_path: str | None, max_messages: int, **choices: Any) -> None:
    """Run every check of 'post' (and the time-parametrisation) on PART.cls without writing a program."""
    _check_outputs(cl_file, report_path)
    machine, options, result = _run_pipeline(cl_file, **choices)
    _finish(machine, options, result, report_path, choices["quiet"], max_messages)
    if not choices["quiet"]:
        click.echo(f"verne-post: {cl_file}: ok ({len(result.blocks.joints)} blocks, "
                   f"{int(np.sum(result.blocks.fraction < 1))} inserted, cycle time "
                   f"{np.sum(result.duration):.1f} s)", err=True)
