"""Command line: ``verne-post part.cls -o part.nc`` plus ``ik``, ``fk`` and ``check``.

A thin layer: parse options, call the library, print. mm and degrees at this interface
(``--radians`` switches angles to radians); user mistakes exit with a one-line message.
"""

from __future__ import annotations

import contextlib
import functools
import io
import json
import math
import os
import sys
import warnings
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click
import numpy as np

from .allocator import keep_freed_memory
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
from .atomic import atomic_write, check_writable
from .errors import InputError, UserError, one_line, quote
from .kinematics import machine_ik_all, module_ik_all
from .machine import MAX_TOOL_LENGTH, Machine, load_machine
from .tables import read_table, write_table
from .workspace import EXTENT_Z

if TYPE_CHECKING:
    from .verify import Verification


class _DefaultToPost(click.Group):
    """``verne-post FILE ...`` runs the ``post`` command; named subcommands work as usual."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        if args and args[0] not in self.commands and args[0] not in ("--help", "-h", "--version"):
            args = ["post", *args]
        return super().parse_args(ctx, _auto_offset(args))

    def main(self, *args: Any, **kwargs: Any) -> Any:
        """Command-line mistakes as one line (``verne-post: error: ...``), exit code 2.

        Python warnings (e.g. numpy's on NaN arithmetic in rejected input) are not shown: every
        line on stderr is one of verne-post's own messages.
        """
        keep_freed_memory()
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


def _auto_offset(args: list[str]) -> list[str]:
    """``--work-offset auto`` (three numbers otherwise) becomes the hidden flag ``--auto-offset``."""
    out: list[str] = []
    for arg in args:
        if arg.lower() == "auto" and out and out[-1] == "--work-offset":
            out[-1] = "--auto-offset"
        elif arg.lower() == "--work-offset=auto":
            out.append("--auto-offset")
        else:
            out.append(arg)
    return out


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
TIP_TOL = Number(1e-6, 10.0, " mm")  # --tol, --arc-tol
AXIS_TOL = Number(1e-6, 10.0, " deg")  # --axis-tol
WORK_OFFSET = Number(-1e4, 1e4, " mm")
MAX_MESSAGES = Number(0, 10**6, integer=True)

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
    verne-post verify part.nc [--against part.cls]   check a G-code program
    verne-post batch DIR -o OUTDIR        many files at once (local processes or Dask)
    verne-post place part.cls             where to clamp the part (work offset and room)
    verne-post workspace -o ws.png        map of the tool-tip workspace for a tool axis
    verne-post toolpath part.cls          the toolpath as the reader understood it (CSV)
    verne-post ik / fk ...                kinematics of single poses or CSV files
    verne-post calibrate meas.csv -o my.yaml   identify geometry and joint zeros from measured tips
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


# How the CL file is read: one group for every command that reads one ('post', 'check', 'batch',
# 'place', 'toolpath', 'verify --against'), so that their options cannot drift apart.
_reader_options = [
    click.option("--units", type=click.Choice(["mm", "inch"]), default=None, help="Override the CL file's units."),
    click.option("--arc-tol", type=TIP_TOL, default=0.001, show_default=True,
                 help="Chordal deviation of CIRCLE arcs and splines expanded into CL points, mm (adds to --tol)."),
    click.option("--arc-direction", type=click.Choice(["cw", "ccw"]), default=None,
                 help="Direction of CIRCLE arcs about their axis (default: the CAM dialect's, e.g. NX cw)."),
    click.option("--frame", type=click.Choice(["local", "world", "apply"]), default=None,
                 help="What MSYS/CSYS mean (default: the CAM dialect's): data in that frame (local), already "
                      "in one frame (world), or to be mapped by it (apply)."),
    click.option("--feed", type=Number(1e-6, 1e7, " mm/min"), default=None, metavar="MM/MIN",
                 help="Feed of the feed moves before the CL file's first FEDRAT, in mm/min whatever the file's "
                      "units (for CAM output that gives no feed); recorded in the G-code header."),
]

def _reader_option_group(function: Callable[..., Any]) -> Callable[..., Any]:
    for option in reversed(_reader_options):
        function = option(function)
    return function


def _read_cl(cl_file: str, units: str | None, arc_tol: float, arc_direction: str | None, frame: str | None,
             feed: float | None) -> Any:
    """The CL file as the reader options say."""
    from .cl import read_toolpath

    return read_toolpath(cl_file, units=units, chordal_tolerance=arc_tol, arc_direction=arc_direction, frame=frame,
                         feed=feed)


def _decorated(function: Callable[..., Any], options: list[Callable[..., Any]]) -> Callable[..., Any]:
    for option in reversed(options):
        function = option(function)
    return function


# The choices of the pipeline ('post', 'check' and 'batch'), around the --report option.
_choices_before_report = [
    machine_option,
    click.option("--tool-length", type=TOOL_LENGTH, default=None,
                 help="Tool length in mm for tools whose length neither the CL file nor the machine gives."),
    click.option("--work-offset", nargs=3, type=WORK_OFFSET, default=None,
                 help="Part zero X Y Z in the table frame, mm (default: the machine file's); 'auto': the "
                      "offset with the most room to every limit (see 'verne-post place')."),
    click.option("--auto-offset", is_flag=True, hidden=True),
    click.option("--tol", type=TIP_TOL, default=0.005, show_default=True,
                 help="Tool tip deviation allowed between blocks, mm."),
    click.option("--axis-tol", type=AXIS_TOL, default=0.05, show_default=True,
                 help="Tool axis deviation allowed between blocks, degrees."),
    click.option("--rapid-tol", type=TIP_TOL, default=0.5, show_default=True,
                 help="Tool tip deviation allowed from a CL rapid's straight line, mm (never below it)."),
    click.option("--rapid-axis-tol", type=AXIS_TOL, default=0.5, show_default=True,
                 help="Tool axis deviation allowed in a CL rapid, degrees."),
    *_reader_options,
]
_choices_after_report = [
    click.option("--no-timing", is_flag=True,
                 help="Skip time-parametrisation: feeds from the programmed feed and joint velocities only."),
    click.option("--planner", type=click.Choice(["copp", "toppra"]), default="copp", show_default=True,
                 help="TOPP engine of the feed moves: copp-py (fast) or toppra (the reference; same plans to "
                      "solver tolerance)."),
    click.option("--optimize", is_flag=True,
                 help="Also plan each feed sequence of more than 40 blocks by a third-order linear programme "
                      "(HiGHS) and keep it where verified and faster: about 1 % off rows that climb into a "
                      "rotary limit, 0.3 % off the whole 105k-block benchmark job, for planning about 30 times "
                      "slower (the whole command about 6 times)."),
    click.option("--quiet", "-q", is_flag=True, help="No progress bar and no warnings on stderr."),
    click.option("--max-messages", type=MAX_MESSAGES, default=20, show_default=True,
                 help="Violations printed before the count."),
]

# What is written and how ('post' and 'batch').
_output_options = [
    click.option("--format", "output_format", type=click.Choice(["gcode", "csv"]), default=None,
                 help="Output format (default: from the output file's suffix; G-code for 'batch')."),
    click.option("--period", type=Number(MIN_PERIOD, 60.0, " s", zero=True), default=0.001, show_default=True,
                 help="Timed CSV sample period in s; 0 gives one row per block end."),
    click.option("--decimals", type=Number(4, 12, integer=True), default=None,
                 help="Decimals of t and the joint positions in the timed CSV (4 to 12; default 9, up to 12 for "
                      "periods under 1 ms): enough that third differences at the period carry at most 4 units/s^3 "
                      "of rounding, so the jerk can be checked from the file."),
    click.option("--no-verify", is_flag=True,
                 help="Skip reading the G-code back and verifying it with the forward kinematics before writing."),
]


def _post_options(function: Callable[..., Any]) -> Callable[..., Any]:
    return _decorated(function, [
        click.argument("cl_file", metavar="PART.cls", type=click.Path(dir_okay=False)),
        *_choices_before_report,
        click.option("--report", "report_path", type=click.Path(dir_okay=False),
                     help="Write violations and statistics: JSON, or a self-contained HTML page when it ends "
                          "in .html."),
        *_choices_after_report,
        click.option("--workers", type=Number(1, 1024, integer=True), default=os.cpu_count() or 1,
                     show_default="the cores", help="Processes: with 2 or more, the planning and the verification "
                                                    "run beside the other stages; 1 runs everything in this one."),
    ])


def _options_from(no_timing: bool, auto_offset: bool, **choices: Any) -> Any:
    """The :class:`PostOptions` of the command-line choices (machine, --quiet and the like removed)."""
    from .pipeline import PostOptions

    if auto_offset and choices["work_offset"]:
        raise InputError("give --work-offset either as X Y Z or as auto, once")
    offset = "auto" if auto_offset else choices["work_offset"] or None
    return PostOptions(**{**choices, "work_offset": offset}, plan=not no_timing)


def _run_pipeline(cl_file: str, machine_path: str | None, quiet: bool, no_timing: bool, auto_offset: bool,
                  **choices: Any) -> tuple[Machine, Any, Any]:
    """Load the machine and run every stage but writing; a progress bar on a terminal."""
    from .pipeline import postprocess

    options = _options_from(no_timing, auto_offset, **choices)
    machine = load_machine(machine_path)
    stages = (4 if no_timing else 5) + (PLACEMENT_STEPS if auto_offset else 0)
    with _progress(stages, quiet) as tick:
        result = postprocess(cl_file, machine, options, progress=lambda stage: tick())
    return machine, options, result


def _run_post(cl_file: str, output: str | None, verify: bool, report_path: str | None, max_messages: int,
              machine_path: str | None, quiet: bool, no_timing: bool, auto_offset: bool, **choices: Any) -> Any:
    """Load the machine and run every stage a part of the program at a time, writing ``output``
    (None: only check) after the warnings, violations and report (:func:`_finish`); a progress
    bar over the parts on a terminal."""
    from .pipeline import post

    options = _options_from(no_timing, auto_offset, **choices)
    machine = load_machine(machine_path)
    stream = sys.stderr if not quiet and sys.stderr.isatty() else io.StringIO()
    with click.progressbar(length=1, label="verne-post", file=stream) as bar:
        def progress(stage: str) -> None:  # "pose K of N" after each part
            if stage.startswith("pose "):
                done, total = map(int, stage.split()[1::2])
                bar.length = total
                bar.update(done - bar.pos)

        return post(cl_file, machine, options, output, verify=verify, timing_figures=bool(report_path),
                    progress=progress, before_writing=lambda posted: _finish(machine, options, posted, report_path,
                                                                             quiet, max_messages))


#: About how many progress calls a placement makes (the bar stops short of the end until done).
PLACEMENT_STEPS = 30


@contextlib.contextmanager
def _progress(steps: int, quiet: bool) -> Iterator[Callable[[], None]]:
    """A progress bar on stderr when it is a terminal (never past its last step before the end)."""
    stream = sys.stderr if not quiet and sys.stderr.isatty() else io.StringIO()
    done = 0
    with click.progressbar(length=steps, label="verne-post", file=stream) as bar:
        def tick() -> None:
            nonlocal done
            if done < steps - 1:
                done += 1
                bar.update(1)

        yield tick
        bar.update(steps - done)


def _html(report_path: str | None) -> bool:
    """The report is the HTML page (it plots whole-program arrays: the program is posted at once)."""
    return bool(report_path) and report_path.lower().endswith((".html", ".htm"))


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
    # the report after the violations: they are printed even when the report cannot be written
    if _html(report_path):
        from .report_html import write_html_report

        write_html_report(report_path, machine, options, result)
    elif report_path:
        write_json(report_path, result.report(machine, options))
    if result.violations:
        click.echo(f"verne-post: {len(result.violations)} violation(s): nothing written", err=True)
        sys.exit(3)


@main.command("post")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="Output file: G-code (default PART.nc), or a timed CSV when it ends in .csv.")
@functools.partial(_decorated, options=_output_options)
@_post_options
@user_errors
def post_command(cl_file: str, output: str | None, output_format: str | None, period: float, decimals: int | None,
                 no_verify: bool, report_path: str | None, max_messages: int, **choices: Any) -> None:
    """Postprocess PART.cls (APT/CLSF, or a CSV of poses) into joint-space G-code or a timed CSV.

    The G-code is verified before it is written (see 'verne-post verify'): a program that fails
    is not written (exit 3); one that passes carries the certified figures in its header.
    """
    from .pipeline import write_output

    target = output or str(Path(cl_file).with_suffix(".nc"))
    as_csv = (output_format or ("csv" if target.lower().endswith(".csv") else "gcode")) == "csv"
    if as_csv and choices["no_timing"]:
        raise InputError("a timed CSV needs the time-parametrisation: drop --no-timing")
    _check_outputs(cl_file, target, report_path)
    if not as_csv and not _html(report_path):  # G-code: a part of the program at a time
        posted = _run_post(cl_file, target, not no_verify, report_path, max_messages, **choices)
        if posted.verification is not None and not posted.verification.ok:
            _print_findings(posted.verification, max_messages)
            click.echo(f"verne-post: {target}: the program fails its verification: nothing written", err=True)
            sys.exit(3)
        return
    machine, options, result = _run_pipeline(cl_file, **choices)
    _finish(machine, options, result, report_path, choices["quiet"], max_messages)
    verification = write_output(result, machine, options, target, "csv" if as_csv else "gcode", period,
                                verify=not no_verify, decimals=decimals)
    if verification is not None and not verification.ok:
        _print_findings(verification, max_messages)
        click.echo(f"verne-post: {target}: the program fails its verification: nothing written", err=True)
        sys.exit(3)


@main.command("check")
@_post_options
@user_errors
def check_command(cl_file: str, report_path: str | None, max_messages: int, **choices: Any) -> None:
    """Run every check of 'post' (and the time-parametrisation) on PART.cls without writing a program."""
    _check_outputs(cl_file, report_path)
    if _html(report_path):
        machine, options, result = _run_pipeline(cl_file, **choices)
        figures = result.figures(machine, timing=False)
        _finish(machine, options, result, report_path, choices["quiet"], max_messages)
    else:
        figures = _run_post(cl_file, None, False, report_path, max_messages, **choices).figures
    if not choices["quiet"]:
        click.echo(f"verne-post: {cl_file}: ok ({figures.blocks} blocks, {figures.inserted} inserted, cycle time "
                   f"{figures.time:.1f} s)", err=True)


@main.command("batch")
@click.argument("inputs", metavar="INPUTS...", nargs=-1, required=True)
@click.option("-o", "--output-dir", required=True, type=click.Path(file_okay=False),
              help="Folder of the outputs (made if missing): one per input, same stem, .nc or .csv.")
@click.option("--jobs", type=Number(1, 4096, integer=True), default=None,
              help="Worker processes (default: the CPU count); with --scheduler dask, the local cluster's.")
@click.option("--scheduler", default=None,
              help="Run on a Dask cluster: tcp://HOST:PORT, or 'dask' for a local one "
                   "(pip install 'verne-post[dask]').")
@click.option("--summary", "summary_path", type=click.Path(dir_okay=False),
              help="One row per file: CSV, or JSON when it ends in .json.")
@click.option("--report-each", is_flag=True, help="A JSON report next to each output (STEM.json).")
@click.option("--skip-unchanged", is_flag=True,
              help="Leave out files whose output records the hash of this input, machine file, options and "
                   "verne-post version.")
@functools.partial(_decorated, options=[*_output_options, *_choices_before_report, *_choices_after_report])
@user_errors
def batch_command(inputs: tuple[str, ...], output_dir: str, jobs: int | None, scheduler: str | None,
                  summary_path: str | None, report_each: bool, skip_unchanged: bool, output_format: str | None,
                  period: float, decimals: int | None, no_verify: bool, machine_path: str | None, quiet: bool,
                  max_messages: int, no_timing: bool, auto_offset: bool, **choices: Any) -> None:
    """Postprocess many CL files (files, folders, glob patterns) into OUTDIR, on local processes
    or a Dask cluster.

    Each file is posted on its own: a bad file is recorded and the others go on. Exit code 0
    when every file was posted, 2 when any was bad input, else 3 when any could not be posted
    (violations, or a failure); --summary says which and why.
    """
    from .batch import BatchOptions, batch, exit_code, expand_inputs, open_executor, write_summary

    options = BatchOptions(_options_from(no_timing, auto_offset, **choices), output_format or "gcode", period,
                           not no_verify, decimals=decimals)
    files = expand_inputs(inputs)
    if summary_path and Path(summary_path).resolve().parent != Path(output_dir).resolve():
        check_writable(summary_path)  # now, not after the batch (OUTDIR itself is made by the batch)
    show = not quiet and sys.stderr.isatty()
    stream = sys.stderr if show else io.StringIO()
    with open_executor(scheduler, jobs, stages=show) as (executor, width, stages), click.progressbar(
            length=len(files), label="verne-post batch", file=stream, item_show_func=lambda note: note) as bar:
        def on_stage(file: str, stage: str) -> None:
            bar.current_item = f"{Path(file).name}: {stage}"
            bar.render_progress()

        results = batch(files, machine_path, options, executor, output_dir=output_dir, skip_unchanged=skip_unchanged,
                        report_each=report_each, jobs=width, stages=stages, on_stage=on_stage if show else None,
                        on_done=lambda r: bar.update(1, f"{Path(r.file).name}: {r.status}"))
    if summary_path:
        write_summary(summary_path, results)
    failed = [r for r in results if r.exit_code]
    for r in failed[:max_messages]:
        click.echo(f"verne-post: error: {r.message}", err=True)
    if len(failed) > max_messages:
        click.echo(f"verne-post: ... and {len(failed) - max_messages} more failed files", err=True)
    if not quiet:
        counts = ", ".join(f"{n} {status}" for status, n in Counter(r.status for r in results).items())
        click.echo(f"verne-post: {len(results)} files: {counts}", err=True)
    sys.exit(exit_code(results))


@main.command("toolpath")
@click.argument("cl_file", metavar="PART.cls", type=click.Path(dir_okay=False))
@click.option("-o", "--output", type=click.Path(dir_okay=False), help="Output CSV (default: stdout).")
@click.option("--quiet", "-q", is_flag=True, help="No dialect line and no warnings on stderr.")
@_reader_option_group
@user_errors
def toolpath_command(cl_file: str, output: str | None, quiet: bool, **reading: Any) -> None:
    """Write the toolpath exactly as the reader understood it, as CSV.

    Columns x,y,z (tool tip, mm, part frame), i,j,k (unit tool axis), feed (mm/min; empty on
    rapids, 1/min on inverse-time moves), motion (feed, rapid, arc, spline, cycle), line (CL
    line). Arcs, helices, splines and cycles are expanded. The dialect and the conventions used
    go to stderr, to compare with the CAM system's own display.
    """
    from .toolpath import MOTION_KINDS

    tp = _read_cl(cl_file, **reading)
    if not quiet:
        click.echo(f"verne-post: {cl_file}: {tp.dialect}; {len(tp)} poses, source units {tp.units}", err=True)
        for warning in tp.warnings:
            click.echo(f"verne-post: warning: {warning}", err=True)
    motion = tp.motion if tp.motion is not None else np.where(tp.rapid, 1, 0)
    feed = np.char.mod("%.6g", tp.feed)
    feed[~np.isfinite(tp.feed)] = ""
    table = {"x": tp.tip[:, 0], "y": tp.tip[:, 1], "z": tp.tip[:, 2], "i": tp.axis[:, 0], "j": tp.axis[:, 1],
             "k": tp.axis[:, 2], "feed": feed, "motion": np.array(MOTION_KINDS)[motion], "line": tp.line}
    _write_csv(table, output, {"x": "%.6f", "y": "%.6f", "z": "%.6f", "i": "%.9f", "j": "%.9f", "k": "%.9f",
                               "feed": "%s", "motion": "%s", "line": "%d"})


# ----------------------------------------------------------------------------- verify


def _print_findings(verification: Verification, max_messages: int) -> None:
    for f in verification.findings[:max_messages]:
        cl = f" (CL {verification.against}:{f.cl_line})" if f.cl_line is not None else ""
        click.echo(f"verne-post: error: {verification.source}:{f.line}: {f.message}{cl}", err=True)
    if len(verification.findings) > max_messages:
        click.echo(f"verne-post: ... and {len(verification.findings) - max_messages} more findings", err=True)


@main.command("verify")
@click.argument("program", metavar="PART.nc", type=click.Path(dir_okay=False))
@click.option("--against", "cl_file", type=click.Path(dir_okay=False),
              help="The CL file (APT/CLSF, or a CSV of poses) the program must follow.")
@machine_option
@click.option("--work-offset", nargs=3, type=WORK_OFFSET, default=None,
              help="Part zero X Y Z in the table frame, mm (default: the program header's, else the machine's).")
@click.option("--tol", type=TIP_TOL, default=None,
              help="Tool tip deviation allowed, mm (default: the program header's, else 0.005).")
@click.option("--axis-tol", type=AXIS_TOL, default=None,
              help="Tool axis deviation allowed, degrees (default: the program header's, else 0.05).")
@click.option("--rapid-tol", type=TIP_TOL, default=None,
              help="How far a rapid may leave its CL line (never below it; with --against), or dip below the "
                   "lower of its ends (without), mm (default: the program header's, else 0.5).")
@click.option("--report", "report_path", type=click.Path(dir_okay=False), help="Write the findings as JSON.")
@click.option("--quiet", "-q", is_flag=True, help="Nothing on stderr but the findings.")
@click.option("--max-messages", type=MAX_MESSAGES, default=20, show_default=True,
              help="Findings printed before the count.")
@_reader_option_group
@user_errors
def verify_command(program: str, cl_file: str | None, machine_path: str | None,
                   work_offset: tuple[float, float, float] | None, tol: float | None, axis_tol: float | None,
                   rapid_tol: float | None, report_path: str | None, quiet: bool, max_messages: int,
                   **reading: Any) -> None:
    """Verify a joint-space G-code program: limits and margins along the motion, and with
    --against how closely it follows the CL path. Exit 0 if it passes, 3 if not."""
    from .tables import write_json
    from .verify import verify_program

    machine = load_machine(machine_path)
    try:
        text = Path(program).read_text(encoding="utf-8", errors="replace")
    except OSError as error:
        raise InputError(f"cannot read the program: {error.strerror}", program) from None
    against = None if cl_file is None else _read_cl(cl_file, **reading)
    verification = verify_program(text, machine, source=program, against=against, work_offset=work_offset,
                                  tol=tol, axis_tol=axis_tol, rapid_tol=rapid_tol)
    if report_path:
        write_json(report_path, verification.report())
    if not verification.ok:
        _print_findings(verification, max_messages)
        click.echo(f"verne-post: {program}: {len(verification.findings)} finding(s)", err=True)
        sys.exit(3)
    if not quiet:
        click.echo(f"verne-post: {program}: {verification.certificate().lower()} ({verification.blocks} blocks, "
                   f"{verification.samples} poses checked)", err=True)


# ----------------------------------------------------------------------------- place


@main.command("place")
@click.argument("cl_file", metavar="PART.cls", type=click.Path(dir_okay=False))
@machine_option
@click.option("--tool-length", type=TOOL_LENGTH, default=None,
              help="Tool length in mm for tools whose length neither the CL file nor the machine gives.")
@click.option("--tol", type=TIP_TOL, default=0.005, show_default=True, help="As for 'post': tip deviation, mm.")
@click.option("--axis-tol", type=AXIS_TOL, default=0.05, show_default=True, help="As for 'post': axis deviation, deg.")
@_reader_option_group
@click.option("--report", "report_path", type=click.Path(dir_okay=False), help="Write the placement as JSON.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
@user_errors
def place_command(cl_file: str, machine_path: str | None, tool_length: float | None, tol: float, axis_tol: float,
                  report_path: str | None, quiet: bool, **reading: Any) -> None:
    """Where to clamp the part: the work offset at which PART.cls runs with the most room to every
    limit and singularity, and how far the part may move from it and still run.

    Prints the offset to use with 'post --work-offset X Y Z' (or use '--work-offset auto' there).
    Exit code 3 when no offset works, with the reason.
    """
    from .pipeline import PostOptions
    from .placement import place
    from .poses import machine_poses
    from .tables import write_json

    machine = load_machine(machine_path)
    options = PostOptions(tool_length=tool_length, tol=tol, axis_tol=axis_tol, plan=False, **reading)
    toolpath = _read_cl(cl_file, **reading)
    poses = machine_poses(toolpath, machine, work_offset=(0.0, 0.0, 0.0), tool_length=tool_length)
    with _progress(PLACEMENT_STEPS, quiet) as tick:
        placement = place(machine, poses, options, progress=lambda stage: tick())
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
    for axis, (minus, plus) in zip("XYZ", placement.room, strict=True):
        click.echo(f"room {axis} -{minus:.2f} / +{plus:.2f} mm")
    if not quiet:
        click.echo(f"verne-post: {placement.screened} offsets screened, {placement.seconds:.1f} s", err=True)


# ----------------------------------------------------------------------------- workspace


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
    from .workspace import plot_workspace, workspace

    if not output.lower().endswith((".png", ".svg")):
        raise InputError("the output must end in .png or .svg")
    machine = load_machine(machine_path)
    tips = None
    if program:
        from .cl import read_toolpath

        offset = np.asarray(work_offset if work_offset else machine.work_offset)
        tips = read_toolpath(program).tip + offset
    plot_workspace(workspace(machine, tool_length=tool_length, tilt=tilt, rotary=rotary, z=level, step=step),
                   output, tips)


# ----------------------------------------------------------------------------- calibrate


def _parameter_names(values: tuple[str, ...]) -> tuple[str, ...]:
    from .calibration import PARAMETERS

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
    from .calibration import calibrate, calibrated_text, plan_poses, read_measurements, report_data
    from .calibration.measurements import check_pose_count
    from .calibration.model import PARAMETERS, parameters_of
    from .calibration.report import report_html, report_json
    from .machine import machine_text

    names = _parameter_names(fix)
    machine = load_machine(machine_path)
    if plan_count is not None:
        if measured is not None:
            raise InputError("--plan writes poses to measure: give no MEASURED.csv with it")
        _check_outputs(machine_path or "", output)
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
    _check_outputs(measured, output, report_path)
    if machine_path is not None and _same_file(output, machine_path):
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


# ----------------------------------------------------------------------------- machine files


@main.group("machine")
def machine_group() -> None:
    """Machine files: check one, explain it, start one, or get the schema an editor checks it with."""


@machine_group.command("check")
@click.argument("machine_file", metavar="FILE", type=click.Path(dir_okay=False))
@user_errors
def machine_check_command(machine_file: str) -> None:
    """Validate FILE: a summary and exit 0, or every problem as FILE:LINE: key.path: reason and exit 2."""
    from .machine import machine_problems, machine_text
    from .machine_facts import summary

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
    from .machine_facts import schema

    text = json.dumps(schema(), indent=2) + "\n"
    if output is None:
        click.echo(text, nl=False)
        return
    with atomic_write(output) as handle:
        handle.write(text)


@machine_group.command("init")
@click.option("-o", "--output", type=click.Path(dir_okay=False), required=True, help="The machine file to write.")
@user_errors
def machine_init_command(output: str) -> None:
    """Write a fully commented machine file to start from: the VERNE as shipped (edit its geometry,
    limits, tools, positions, then 'verne-post machine check' it)."""
    from .machine import machine_text

    if Path(output).exists():
        raise InputError("exists already: give a new file (nothing is overwritten)", output)
    with atomic_write(output) as handle:
        handle.write(machine_text(None))


@machine_group.command("show")
@click.argument("machine_file", metavar="FILE", type=click.Path(dir_okay=False))
@tool_length_option
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
              help="Also draw the workspace sections: PNG, or SVG when it ends in .svg (needs matplotlib).")
@user_errors
def machine_show_command(machine_file: str, tool_length: float, output: str | None) -> None:
    """What to know before the first run: joint ranges, the reference pose, the workspace for a tool
    (axis along the table normal) and the tightest singularity margins in it."""
    from .machine_facts import facts, facts_table

    machine = load_machine(machine_file)
    found = facts(machine, tool_length)
    for line in facts_table(machine, found):
        click.echo(line)
    if output is not None:
        from .workspace import plot_workspace

        plot_workspace(found.workspace, output)
