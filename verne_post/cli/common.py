"""What the commands share: one-line user errors, checked numbers, and the option groups of the
commands that read a CL file or run the pipeline (one list each, so that they cannot drift apart).
"""

from __future__ import annotations

import functools
import json
import math
import os
import sys
from collections.abc import Callable
from typing import Any

import click
import numpy as np

from ..errors import InputError, UserError, quote
from ..machine import MAX_TOOL_LENGTH
from ..output.atomic import check_writable


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


def check_outputs(source: str, *outputs: str | None) -> None:
    """Fail now, not after a long run: an output that cannot be written, that is the input, or
    two outputs that are one file (devices such as /dev/null excepted)."""
    given = [path for path in outputs if path]
    for k, path in enumerate(given):
        check_writable(path)
        for other, what in [(source, "the input file"), *((o, "another output") for o in given[:k])]:
            if same_file(path, other):
                raise InputError(f"the output would overwrite {what}", path)


def same_file(a: str, b: str) -> bool:
    if os.path.realpath(a) == os.path.realpath(b):
        return not os.path.exists(a) or os.path.isfile(a)
    try:
        return os.path.isfile(a) and os.path.samefile(a, b)
    except OSError:
        return False


def angle_scale(radians: bool) -> float:
    return 1.0 if radians else 180.0 / np.pi


def rounded(values: np.ndarray | float) -> Any:
    array = np.round(np.asarray(values, dtype=float), 9)
    return array.tolist()


def emit(payload: dict[str, Any]) -> None:
    click.echo(json.dumps(payload, indent=2, allow_nan=False))




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

def reader_option_group(function: Callable[..., Any]) -> Callable[..., Any]:
    for option in reversed(_reader_options):
        function = option(function)
    return function


def read_cl(cl_file: str, units: str | None, arc_tol: float, arc_direction: str | None, frame: str | None,
            feed: float | None) -> Any:
    """The CL file as the reader options say."""
    from ..cl import read_toolpath

    return read_toolpath(cl_file, units=units, chordal_tolerance=arc_tol, arc_direction=arc_direction, frame=frame,
                         feed=feed)


def decorated(function: Callable[..., Any], options: list[Callable[..., Any]]) -> Callable[..., Any]:
    for option in reversed(options):
        function = option(function)
    return function


def setup_file(setup_path: str | None) -> dict[str, Any]:
    """``--setup FILE`` as the PostOptions fields it sets: the file read (validated), and its path."""
    from ..machine import load_setup

    return {"setup": None if setup_path is None else load_setup(setup_path), "setup_source": setup_path}


# The stock and fixtures ('post', 'check', 'batch', 'place', 'verify').
setup_options = [
    click.option("--stock", multiple=True, metavar="SPEC",
                 help="The stock, in the part frame and the CL file's units: box:x0,y0,z0,x1,y1,z1, "
                      "cylinder:cx,cy,z0,z1,r or stl:PATH, optionally NAME=SPEC; repeatable (docs/collision.md)."),
    click.option("--fixture", "fixtures", multiple=True, metavar="SPEC",
                 help="A clamp, vice or pallet, as --stock; repeatable."),
    click.option("--setup", "setup_path", type=click.Path(dir_okay=False), default=None,
                 help="A setup YAML (units, stock, fixtures as the machine file's setup: section); --stock and "
                      "--fixture replace its stock or fixtures."),
]


# The choices of the pipeline ('post', 'check' and 'batch'), around the --report option.
choices_before_report = [
    machine_option,
    click.option("--tool-length", type=TOOL_LENGTH, default=None,
                 help="Tool length in mm for tools whose length neither the CL file nor the machine gives."),
    click.option("--work-offset", nargs=3, type=WORK_OFFSET, default=None,
                 help="Part zero X Y Z in the table frame, mm (default: the machine file's); 'auto': the "
                      "offset with the most room to every limit (see 'verne-post place')."),
    click.option("--auto-offset", is_flag=True, hidden=True),
    click.option("--room", "placement_room", is_flag=True,
                 help="With --work-offset auto: also find how far the part may move along each axis and still "
                      "run, for the header and the report (as 'verne-post place': certified by full checks, "
                      "about 40 s on the impeller example)."),
    click.option("--tol", type=TIP_TOL, default=0.005, show_default=True,
                 help="Tool tip deviation allowed between blocks, mm."),
    click.option("--axis-tol", type=AXIS_TOL, default=0.05, show_default=True,
                 help="Tool axis deviation allowed between blocks, degrees."),
    click.option("--rapid-tol", type=TIP_TOL, default=0.5, show_default=True,
                 help="Tool tip deviation allowed from a CL rapid's straight line, mm (never below it)."),
    click.option("--rapid-axis-tol", type=AXIS_TOL, default=0.5, show_default=True,
                 help="Tool axis deviation allowed in a CL rapid, degrees."),
    *_reader_options,
    *setup_options,
]
choices_after_report = [
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
output_options = [
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


def post_options(function: Callable[..., Any]) -> Callable[..., Any]:
    return decorated(function, [
        click.argument("cl_file", metavar="PART.cls", type=click.Path(dir_okay=False)),
        *choices_before_report,
        click.option("--report", "report_path", type=click.Path(dir_okay=False),
                     help="Write violations and statistics: JSON, or a self-contained HTML page when it ends "
                          "in .html."),
        *choices_after_report,
        click.option("--workers", type=Number(1, 1024, integer=True), default=os.cpu_count() or 1,
                     show_default="the cores", help="Processes: with 2 or more, the planning and the verification "
                                                    "run beside the other stages (and --room's full checks side by "
                                                    "side); 1 runs everything in this one."),
    ])
