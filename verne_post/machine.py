"""Machine description: a frozen, validated model of the YAML machine file.

User-facing units are mm and degrees (YAML); :class:`Geometry` is what the kinematics use
(mm, and radians everywhere inside the kinematics).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
import yaml
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, PrivateAttr, ValidationError, model_validator

from .bodies.config import BodiesConfig, CylinderSize, SetupConfig
from .config_messages import collapse_alternatives, file_path, near_key, quoted_numbers, reason
from .errors import InputError
from .kinematics import reference_pose_problem
from .kinematics.geometry import Geometry
from .output.controller import (
    DIALECTS,
    JOINT_ORDER,
    PLACEHOLDERS,
    SAMPLES,
    Controller,
    g_codes,
    modal_words,
    placeholders,
    template_problem,
)

# Every number finite (YAML's .inf and .nan are refused), unknown keys refused.
_STRICT = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, use_attribute_docstrings=True)

#: Largest magnitude of a length or position in a machine file (mm; 100 m), and of a joint
#: position (mm or degrees): beyond any machine tool, and far from float overflow in the kinematics.
MAX_MM = 1e5
#: Longest tool (mm, spindle nose to tip) in a machine file or on the command line.
MAX_TOOL_LENGTH = 2000.0
Length = Annotated[float, Field(gt=0, le=MAX_MM)]
Finite = Annotated[float, Field(ge=-MAX_MM, le=MAX_MM)]
# Joint rates per s, per s^2, per s^3 (mm or degrees): slow enough to be a mistake, or beyond
# any drive. The floor keeps durations, and so the outputs, finite.
Velocity = Annotated[float, Field(ge=1e-3, le=1e6)]
Acceleration = Annotated[float, Field(ge=1e-3, le=1e8)]
Jerk = Annotated[float, Field(ge=1e-3, le=1e10)]


class GeometryConfig(BaseModel):
    model_config = _STRICT
    D1_minus_d1: Finite
    """mm: leg I, platform joint x minus slider joint x (paper D1 - d1)."""
    D2_minus_d2: Finite
    """mm: legs II and III, platform joint x minus slider joint x (paper D2 - d2)."""
    R1: Length
    """mm: half the spacing of leg I's rods on the platform."""
    r1: Length
    """mm: half the spacing of leg I's rods on the slider (smaller than R1: a trapezium)."""
    L1: Length
    """mm: length of leg I's rods."""
    R2: Length
    """mm: platform joints of legs II and III from the platform's centre line."""
    r4: Length
    """mm: slider joints of legs II and III from the base's centre line."""
    L2: Length
    """mm: length of leg II's rods."""
    L3: Length
    """mm: length of leg III's rods."""
    spindle_nose: Length
    """mm: platform centre P to the spindle nose; Delta = spindle_nose + tool length."""
    da: Finite
    """mm: base origin to the tilt axis of the table (paper Table IV)."""
    dt: Finite
    """mm: tilt axis to the rotary table's face (paper Table IV)."""

    @model_validator(mode="after")
    def _leg_one_is_a_trapezium(self) -> GeometryConfig:
        if self.r1 >= self.R1:
            raise ValueError("r1 must be smaller than R1 (leg I rods would always cross)")
        return self

    @model_validator(mode="after")
    def _reference_pose_is_reachable(self) -> GeometryConfig:
        """The reference pose (tool tip at the table origin, axis along the table normal, no
        tool: the spindle nose at the origin) must be reachable in the working mode; otherwise
        the numbers describe no working VERNE, whatever the joint limits."""
        problem = reference_pose_problem(Geometry(**self.model_dump()))
        if problem is not None:
            raise ValueError(problem)
        return self


#: Largest joint zero offset (mm for a slider, degrees for a rotary): a calibration corrects
#: assembly errors, not a misplaced axis.
MAX_OFFSET = 100.0


class JointLimits(BaseModel):
    """One joint: position range (mm or degrees) and its velocity/acceleration/jerk limits (per s).

    ``offset`` (mm or degrees, default 0): the true position is the controller's reading plus
    the offset (a slider's or rotary's zero error, found by ``verne-post calibrate``). The
    limits ``min``/``max`` are on the readings, as the controller's soft limits are.
    """

    model_config = _STRICT
    min: Finite | None = None
    """Lowest reading: mm for a slider, degrees for a rotary (absent for a continuous rotary)."""
    max: Finite | None = None
    """Highest reading: mm for a slider, degrees for a rotary."""
    continuous: bool = False
    """A rotary without end stops (theta2 only)."""
    offset: Annotated[float, Field(ge=-MAX_OFFSET, le=MAX_OFFSET)] = 0.0
    """mm or degrees: the true position is the reading plus this (verne-post calibrate)."""
    velocity: Velocity
    """mm/s or deg/s."""
    acceleration: Acceleration
    """mm/s^2 or deg/s^2."""
    jerk: Jerk
    """mm/s^3 or deg/s^3."""

    @model_validator(mode="after")
    def _range(self) -> JointLimits:
        if self.continuous:
            if self.min is not None or self.max is not None:
                raise ValueError("a continuous joint has no min/max")
        else:
            if self.min is None or self.max is None:
                raise ValueError("min and max are required unless continuous: true")
            if self.min >= self.max:
                raise ValueError(f"min ({self.min}) must be smaller than max ({self.max})")
        return self


class Joints(BaseModel):
    model_config = _STRICT
    rho1: JointLimits
    rho2: JointLimits
    rho3: JointLimits
    theta1: JointLimits
    theta2: JointLimits

    @model_validator(mode="after")
    def _only_rotary_may_be_continuous(self) -> Joints:
        for name in ("rho1", "rho2", "rho3", "theta1"):
            if getattr(self, name).continuous:
                raise ValueError(f"{name} cannot be continuous")
        return self


class Singularity(BaseModel):
    """Thresholds below which a pose is reported (see kinematics.jacobian.Margins)."""

    model_config = _STRICT
    serial_min: Annotated[float, Field(ge=0, lt=1)]
    """Smallest |cos| of a rod's angle to its guideway (0: the rod perpendicular to it)."""
    parallel_min: Annotated[float, Field(ge=0, lt=1)]
    """Smallest inverse condition number of the parallel module's direct kinematics (0: singular)."""
    machine_min: Annotated[float, Field(ge=0, lt=1)]
    """Smallest inverse condition number of the tool Jacobian (0: two working solutions merge)."""
    rod_clearance_min: Annotated[float, Field(ge=0, le=MAX_MM)]
    """mm: smallest R1 cos(alpha) - r1 (leg I's rods cross at 0)."""


class Pole(BaseModel):
    model_config = _STRICT
    cone: Annotated[float, Field(gt=0, lt=90)]
    """deg: within this cone about the table normal theta2 is interpolated, not computed."""
    max_theta2_rate: Annotated[float, Field(gt=0, le=1e6)]
    """deg of theta2 per mm of tip travel near the pole above which a feed move is reported."""


class TimingConfig(BaseModel):
    """Time-parametrisation settings."""

    model_config = _STRICT
    # deg/min: rotary speed of blocks where the tip stands still
    rotary_feed: Annotated[float, Field(ge=1e-3, le=1e8)] = 3600.0
    """deg/min: rotary speed of feed blocks where the tip stands still."""
    corner_angle: Annotated[float, Field(gt=0, le=180)] = 30.0  # deg: sharper corners stop the motion
    """deg: a sharper corner (joint space, weighted by the velocity limits) stops the motion."""


class Tool(BaseModel):
    model_config = _STRICT
    length: Annotated[float, Field(ge=0, le=MAX_TOOL_LENGTH)]
    """mm: spindle nose to tool tip (gauge length)."""
    diameter: Annotated[float, Field(gt=0, le=MAX_TOOL_LENGTH)] | None = None
    """mm: the cutter's diameter, where the CL file's TLDATA gives none (else bodies.cutter_diameter)."""
    flute_length: Annotated[float, Field(gt=0, le=MAX_TOOL_LENGTH)] | None = None
    """mm: the cutting length from the tip; above it the shank (checked against the stock in cuts too)."""
    holder: tuple[CylinderSize, ...] | None = Field(default=None, max_length=16)
    """The tool's holder: cylinders from the spindle nose toward the tip (else bodies.holder)."""


class GcodeConfig(BaseModel):
    model_config = _STRICT
    linear_decimals: Annotated[int, Field(ge=0, le=8)] = 4
    """Decimals of the sliders' words (mm)."""
    angular_decimals: Annotated[int, Field(ge=0, le=8)] = 4
    """Decimals of the tilt's and rotary's words (degrees)."""
    feed_decimals: Annotated[int, Field(ge=0, le=8)] = 5
    """Decimals of F (inverse time, 1/min)."""


def _template(kind: str) -> object:
    """A line of ``controller.<kind>``: its placeholders checked when the file is read."""

    def check(text: str) -> str:
        problem = template_problem(text, PLACEHOLDERS[kind])
        if problem is not None:
            raise ValueError(problem)
        return text

    return Annotated[str, Field(max_length=1000), AfterValidator(check)]


StartLine = _template("program_start")
EndLine = _template("program_end")
ToolChangeLine = _template("tool_change")
AxisLetter = Literal["X", "Y", "Z", "U", "V", "W", "A", "B", "C"]
MCode = Annotated[int, Field(ge=0, le=999)]


class AxesConfig(BaseModel):
    """The address of each joint in the program (the dialect's where not given)."""

    model_config = _STRICT
    rho1: AxisLetter | None = None
    """Slider 1 (mm)."""
    rho2: AxisLetter | None = None
    """Slider 2 (mm)."""
    rho3: AxisLetter | None = None
    """Slider 3 (mm)."""
    theta1: AxisLetter | None = None
    """Table tilt (degrees)."""
    theta2: AxisLetter | None = None
    """Rotary table (degrees)."""


class MCodesConfig(BaseModel):
    """M codes the program writes (the dialect's where not given): 3 is written M3."""

    model_config = _STRICT
    spindle_cw: MCode | None = None
    """Spindle on, clockwise."""
    spindle_ccw: MCode | None = None
    """Spindle on, counter-clockwise."""
    spindle_off: MCode | None = None
    """Spindle off."""
    coolant_flood: MCode | None = None
    """Flood coolant (the CL's COOLNT/ON and FLOOD)."""
    coolant_mist: MCode | None = None
    """Mist coolant."""
    coolant_through: MCode | None = None
    """Coolant through the spindle (the CL's THRU)."""
    coolant_off: MCode | None = None
    """Coolant off."""
    stop: MCode | None = None
    """Program stop (the CL's STOP)."""
    optional_stop: MCode | None = None
    """Optional stop (the CL's OPSTOP, and optional_stop)."""
    tool_change: MCode | None = None
    """Tool change: the reader changes the tool at it, so every tool_change list holds it."""
    end: MCode | None = None
    """Program end: the reader ends the program at it (and at M2 and M30)."""


class BlockNumbers(BaseModel):
    """N numbers on every block (comment lines and % excepted)."""

    model_config = _STRICT
    start: Annotated[int, Field(ge=0, le=10**8)] = 10
    """The first block's number."""
    step: Annotated[int, Field(ge=1, le=10**6)] = 10
    """The increment."""


class ControllerConfig(BaseModel):
    """The controller the program is written for: a dialect preset, and settings over it
    (docs/controllers.md; the presets' sources in verne_post/output/controller.py)."""

    model_config = _STRICT
    dialect: Literal["linuxcnc", "fanuc", "sinumerik"] = "linuxcnc"
    """Preset: linuxcnc (today's output), fanuc or sinumerik."""
    axes: AxesConfig = AxesConfig()
    """Address letter of each joint (default X Y Z A C)."""
    comment: Literal["parentheses", "semicolon"] | None = None
    """Comments as ( ) or after ; (default: the dialect's)."""
    percent: bool | None = None
    """% on the first and last lines (default: the dialect's)."""
    program_number: Annotated[int, Field(ge=0, le=99_999_999)] | None = None
    """The program's number: FANUC's O line, and {program} in the lines below."""
    program_start: list[StartLine] | None = Field(default=None, max_length=100)
    """Lines after the header comments, before the first tool change; placeholders {name} {program}."""
    program_end: list[EndLine] | None = Field(default=None, max_length=100)
    """Lines after the last move; placeholders {name} {program}. Must end the program (m_codes.end)."""
    tool_change: list[ToolChangeLine] | None = Field(default=None, max_length=100)
    """Lines of a tool change, at the tool-change position; placeholders {tool} {length} (mm) {delta} (mm)
    {spindle} (rpm) {name} {program}. Must hold {tool} and the tool-change M code."""
    block_numbers: BlockNumbers | bool = False
    """N numbers: false, true (from 10 by 10), or {start, step}."""
    optional_stop: bool = False
    """An optional stop (M1) before every tool change but the first."""
    max_line_length: Annotated[int, Field(ge=60, le=100_000)] | None = None
    """Characters per line (default: the dialect's; 252 for LinuxCNC). Comments are shortened to fit."""
    tool_number: Annotated[int, Field(ge=1, le=10**9)] | None = None
    """The number of a CL tool without one (NX's TLDATA without LOAD/TOOL): its tool change is written
    with it (absent: the tool is loaded by hand; the tool_change lines are written without T and M6)."""
    block_time: Annotated[float, Field(ge=0.0, le=1.0)] = 0.0
    """Seconds: the least time the controller takes for a block (its block processing time, from the
    control's data sheet; e.g. 0.001): the timing gives every block at least this, so that F asks for
    what the control can do and the header's cycle time is its. 0: not modelled."""
    split: Literal["tool"] | None = None
    """tool: one program file per tool, part_1_T2.nc, part_2_T5.nc, ... (each starts where the one before ends)."""
    m_codes: MCodesConfig = MCodesConfig()
    """M codes of spindle, coolant, stops, tool change and end (default: the dialect's)."""

    def profile(self) -> Controller:
        """The profile this section describes: the dialect's, with these settings over it."""
        base = DIALECTS[self.dialect]
        given = {k: v for k, v in self.axes.model_dump().items() if v is not None}
        numbers = self.block_numbers
        if numbers is True:
            numbers = BlockNumbers()
        return replace(
            base,
            axes=tuple(given.get(joint, letter) for joint, letter in zip(JOINT_ORDER, base.axes, strict=True)),
            comment=self.comment or base.comment,
            percent=base.percent if self.percent is None else self.percent,
            program_number=self.program_number,
            program_start=base.program_start if self.program_start is None else tuple(self.program_start),
            program_end=base.program_end if self.program_end is None else tuple(self.program_end),
            tool_change=base.tool_change if self.tool_change is None else tuple(self.tool_change),
            block_numbers=(numbers.start, numbers.step) if isinstance(numbers, BlockNumbers) else None,
            optional_stop=self.optional_stop,
            max_line_length=self.max_line_length or base.max_line_length,
            block_time=self.block_time,
            split=self.split,
            m_codes=replace(base.m_codes, **{k: v for k, v in self.m_codes.model_dump().items() if v is not None}),
        )

    @model_validator(mode="after")
    def _fits_the_reader(self) -> ControllerConfig:
        """Every problem of :meth:`problems`, one a line (``machine_problems`` lists each at its key)."""
        problems = self.problems()
        if problems:
            raise ValueError("\n".join(problems))
        return self

    def problems(self) -> list[str]:
        """What verify needs to read the program back, and what is the post's alone to do: each
        problem as ``controller.key: reason``."""
        profile = self.profile()
        problems = []
        for k, (joint, letter) in enumerate(zip(JOINT_ORDER, profile.axes, strict=True)):
            if letter in profile.axes[:k]:
                other = JOINT_ORDER[profile.axes.index(letter)]
                problems.append(f"controller.axes.{joint}: {letter} is the letter of {other} too; two joints "
                                f"cannot share a letter ({' '.join(profile.axes)})")
        reader = profile.reader
        if (profile.comment == "parentheses" and not reader.parenthesis_comments) or (
                profile.comment == "semicolon" and not reader.semicolon_comments):
            read = "semicolon" if reader.semicolon_comments else "parentheses"
            problems.append(f"controller.comment: {profile.dialect} does not read {profile.comment} as a comment "
                            f"(write comment: {read})")
        numbers, allowed = profile.block_numbers, profile.max_block_number
        if numbers is not None and allowed is not None and not 1 <= numbers[0] <= allowed:
            problems.append(f"controller.block_numbers.start: {profile.dialect} numbers blocks from N1 to "
                            f"N{allowed}, not N{numbers[0]}")
        if profile.program_numbers is not None and profile.program_number is not None:
            low, high = profile.program_numbers
            if not low <= profile.program_number <= high:
                problems.append(f"controller.program_number: {profile.dialect} takes O{low} to O{high}, not "
                                f"{profile.program_number}")
        m = profile.m_codes
        lists = {"program_start": profile.program_start, "program_end": profile.end_lines,
                 "tool_change": profile.tool_change_lines}
        for kind, lines in lists.items():
            given = getattr(self, kind) is not None
            for k, line in enumerate(lines):
                where = f"controller.{kind}.{k}" if given else f"controller.{kind} (the dialect's)"
                if "program" in placeholders(line) and profile.program_number is None:
                    problems.append(f"{where}: {{program}} needs controller.program_number")
                    continue
                inch = [g for g in g_codes(line) if g in profile.reader.inch]
                if inch:
                    metric = " or ".join(f"G{g / 10:g}" for g in sorted(profile.reader.metric))
                    problems.append(f"{where}: G{inch[0] / 10:g} selects inch input, and the program's words are mm "
                                    f"({metric} on {profile.dialect})")
                    continue
                numbered = f"N{profile.block_numbers[0]} " if profile.block_numbers else ""
                problem = _read_back(line, numbered + line.format(**SAMPLES), profile)
                if problem is not None:
                    problems.append(f"{where}: {problem}")
        words = " ".join(line.upper() for line in profile.tool_change_lines)
        if not re.search(rf"\bM0*{m.tool_change}\b", words) or not any(
                "tool" in placeholders(line) for line in profile.tool_change_lines):
            problems.append(f"controller.tool_change: the lines must hold {{tool}} and M{m.tool_change} "
                            f"(m_codes.tool_change), where the reader changes the tool")
        ends = " ".join(line.upper() for line in profile.end_lines)
        if not re.search(rf"\bM0*{m.end}\b", ends):
            problems.append(f"controller.program_end: no line ends the program with M{m.end} (m_codes.end)")
        return problems

    def start_warning(self) -> str | None:
        """What the dialect's start lines set that a ``program_start`` of the file leaves out
        (None if nothing): the controller keeps whatever mode it was left in."""
        if self.program_start is None:
            return None
        profile = self.profile()
        given = modal_words(self.program_start, profile.reader)
        missing = [word for key, word in modal_words(DIALECTS[self.dialect].program_start, profile.reader).items()
                   if key not in given]
        if not missing:
            return None
        return (f"leaves out {' '.join(missing)} of the {self.dialect} start lines: the controller keeps the "
                f"mode it was left in (add them, unless the machine always starts so)")


def _read_back(line: str, written: str, profile: Controller) -> str | None:
    """What is wrong with the profile's ``line`` (None if nothing), as the reader of programs
    reads it as ``written`` (placeholders filled, block number): a move (the post's to plan and
    verify), or a word it cannot read."""
    from .verify.gcode_reader import read_gcode

    try:
        program = read_gcode(written + "\n", controller=profile)
    except InputError as error:
        return f"verify could not read '{line}' back: {error.reason}"
    given = np.flatnonzero(np.any(~np.isnan(program.joints), axis=0))
    if given.size:
        return (f"'{line}' moves the {JOINT_ORDER[int(given[0])]} axis: the moves between cuts are the post's to "
                f"plan and verify (positions.tool_change, positions.home)")
    return f"verify could not read '{line}' back: {program.problems[0][1]}" if program.problems else None


class JointPosition(BaseModel):
    """A position of the machine in joint space: sliders rho1..3 in mm, theta1 and theta2 in degrees."""

    model_config = _STRICT
    rho1: Finite
    """mm: slider 1."""
    rho2: Finite
    """mm: slider 2."""
    rho3: Finite
    """mm: slider 3."""
    theta1: Finite
    """deg: table tilt."""
    theta2: Finite
    """deg: rotary table."""

    def joints(self) -> np.ndarray:
        """(5,) rho1..3 mm, theta1 and theta2 rad."""
        return np.array([self.rho1, self.rho2, self.rho3, math.radians(self.theta1), math.radians(self.theta2)])


class Positions(BaseModel):
    """Where the machine starts and ends a program (``home``) and changes tools (``tool_change``)."""

    model_config = _STRICT
    home: JointPosition | None = None
    """Where every program starts and ends (joint space)."""
    tool_change: JointPosition | None = None
    """Where every tool change happens (joint space)."""


class SafeConfig(BaseModel):
    """How the machine moves between cuts (rapids, retracts, tool changes)."""

    model_config = _STRICT
    max_turn_in_rapid: Annotated[float, Field(ge=0, le=180)] = 30.0
    """deg: a rapid that turns the tool axis by more retracts, reorients at the safe level, approaches."""
    clearance: Annotated[float, Field(ge=0, le=MAX_MM)] = 10.0
    """mm: the feed points' box grown by this on all sides but the bottom (table frame): the clearance envelope."""
    rapid_feed: Annotated[float, Field(ge=1.0, le=1e8)] | None = None
    """mm/min: a cap on the tool-tip speed relative to the part in rapids (absent: the joint limits only)."""


class CalibrationRecord(BaseModel):
    """Provenance of a calibrated machine file, written by ``verne-post calibrate`` (no date:
    the same measurements give the same file). Residuals in mm, table frame."""

    model_config = _STRICT
    method: Annotated[str, Field(min_length=1, max_length=200)]
    measurements: Annotated[str, Field(min_length=1, max_length=400)]
    poses: Annotated[int, Field(ge=1)]
    rejected: Annotated[int, Field(ge=0)] = 0
    rms_before: Annotated[float, Field(ge=0)]
    max_before: Annotated[float, Field(ge=0)]
    rms_after: Annotated[float, Field(ge=0)]
    max_after: Annotated[float, Field(ge=0)]
    fitted: list[Annotated[str, Field(max_length=40)]] = Field(default_factory=list, max_length=64)
    held: list[Annotated[str, Field(max_length=40)]] = Field(default_factory=list, max_length=64)


class Machine(BaseModel):
    """A whole machine file. Lengths mm, angles degrees (as written in the YAML)."""

    model_config = _STRICT
    name: Annotated[str, Field(min_length=1, max_length=200)]
    """The machine's name, written in the program header."""
    geometry: GeometryConfig
    """The kinematic dimensions (mm), identified or calibrated."""
    joints: Joints
    """Travel, zero offsets and velocity, acceleration and jerk limits per joint."""
    singularity: Singularity
    """Margins below which a pose is too close to a singularity."""
    pole: Pole
    """The rotary table's pole (tool axis along the table normal)."""
    tools: dict[Annotated[int, Field(ge=0, le=10**9)], Tool] = Field(default_factory=dict)
    """Tool table: tool number to gauge length (mm), used where the CL file gives none."""
    work_offset: tuple[Finite, Finite, Finite] = (0.0, 0.0, 0.0)
    """mm: part zero in the table frame (x, y, z), unless --work-offset gives one."""
    gcode: GcodeConfig = GcodeConfig()
    """Number formats of the program."""
    controller: ControllerConfig = ControllerConfig()
    """The controller the program is written for: dialect, axis letters, program structure."""
    timing: TimingConfig = TimingConfig()
    """Time-parametrisation settings."""
    safe: SafeConfig = SafeConfig()
    """Moves between cuts: rapids, retracts, tool changes."""
    positions: Positions = Positions()
    """Joint-space positions of the start, end and tool changes."""
    bodies: BodiesConfig = BodiesConfig()
    """The machine's bodies for the collision checks (mm), and their near-miss margin."""
    setup: SetupConfig = SetupConfig()
    """Stock and fixtures on the table, unless --stock, --fixture or --setup give them."""
    calibration: CalibrationRecord | None = None
    """Provenance of a calibrated file (written by verne-post calibrate)."""
    _source: str = PrivateAttr(default="verne.yaml")
    _warnings: tuple[str, ...] = PrivateAttr(default=())

    @model_validator(mode="after")
    def _positions_within_travel(self) -> Machine:
        for which in ("home", "tool_change"):
            position = getattr(self.positions, which)
            if position is None:
                continue
            for name in ("rho1", "rho2", "rho3", "theta1", "theta2"):
                limits, value = getattr(self.joints, name), getattr(position, name)
                if not limits.continuous and not limits.min <= value <= limits.max:
                    raise ValueError(f"positions.{which}.{name} = {value:g} is outside the travel of {name} "
                                     f"({limits.min:g} to {limits.max:g})")
        return self

    @property
    def warnings(self) -> tuple[str, ...]:
        """What in the file is allowed but likely a mistake, each ``FILE:LINE: key: reason``."""
        return self._warnings

    @property
    def source(self) -> str:
        """Name of the machine file (set by :func:`load_machine`, not a key of the file)."""
        return self._source

    def kinematic_geometry(self, tool_length: float = 0.0) -> Geometry:
        """The :class:`Geometry` for the kinematics with the given tool length (mm), joint offsets in mm and rad."""
        j = self.joints
        return Geometry(**self.geometry.model_dump(), tool_length=float(tool_length),
                        rho_offset=(j.rho1.offset, j.rho2.offset, j.rho3.offset),
                        theta_offset=(math.radians(j.theta1.offset), math.radians(j.theta2.offset)))

    @property
    def geom(self) -> Geometry:
        """Geometry with tool length 0 (Delta = spindle nose distance, the paper's tables)."""
        return self.kinematic_geometry(0.0)



DEFAULT_MACHINE = "verne.yaml"


@dataclass(frozen=True)
class MachineProblem:
    """One thing wrong in a machine file: the YAML line of the key or value at fault (None where
    none is known), the key path (``joints.rho1.max``) and the reason."""

    line: int | None
    path: str
    reason: str

    def error(self, source: str) -> InputError:
        return InputError(f"{self.path}: {self.reason}", source, self.line)


#: Keys that have moved, and where to (the machine files of earlier versions).
_MOVED = {("gcode", "block_numbers"): "controller.block_numbers (false, true or {start, step})",
          ("gcode", "block_number_step"): "controller.block_numbers.step"}

#: A machine-wide check names the key at fault at the start of its message (``positions.home.rho1 = ...``).
_PATH_IN_MESSAGE = re.compile(r"^([A-Za-z_][\w]*(?:\.[\w]+)+)\b")


def _problems(error: ValidationError, lines: dict[tuple[str, ...], int], data: object,
              within: tuple[str, ...] = (), model: type[BaseModel] | None = None) -> list[MachineProblem]:
    """Every error of a validation of ``data`` (of its section at key path ``within``), each at the
    line of the deepest key of its path in the file, in the file's terms (:mod:`config_messages`);
    a check's message of several lines is a problem a line."""
    found = []
    for item in error.errors():
        loc = within + tuple(str(p) for p in item["loc"])
        path, alternative = file_path(data, loc, item["type"] == "missing")
        if item["type"] == "extra_forbidden":
            near = near_key(model or Machine, path)
            reasons = [f"moved to {_MOVED[path]}" if path in _MOVED else
                       "unknown key" + (f" (did you mean {near}?)" if near else "")]
        elif item["type"] == "missing":
            reasons = ["missing (required)"]
        else:
            reasons = reason(item).split("\n")
        found += [(path, alternative, text) for text in reasons]
    return [_problem(path, text, lines) for path, text in collapse_alternatives(found)]


def _problem(loc: tuple[str, ...], reason: str, lines: dict[tuple[str, ...], int]) -> MachineProblem:
    named = _PATH_IN_MESSAGE.match(reason)
    if named and tuple(named.group(1).split("."))[:len(loc)] == loc:  # a deeper key than the check's own
        loc = tuple(named.group(1).split("."))
        reason = reason.removeprefix(f"{named.group(1)}: ")
    if reason == "missing (required)" and len(loc) > 1:  # a missing key: the line of the mapping that lacks it
        line = next((lines[loc[:k]] for k in range(len(loc) - 1, 0, -1) if loc[:k] in lines), None)
    else:
        line = next((lines[loc[:k]] for k in range(len(loc), 0, -1) if loc[:k] in lines), None)
    return MachineProblem(line, ".".join(loc) or "(top level)", reason)


def _quoted(model: BaseModel, document: _Document) -> list[MachineProblem]:
    """A number written in quotes, which pydantic reads as the number and the schema refuses
    (an editor would flag it): refused, so that the two agree."""
    at = dict(document.quoted)
    return [MachineProblem(at[path], ".".join(path), "a number in quotes: write it without them")
            for path in quoted_numbers(model, document.quoted)]


def _controller_checks(data: dict, error: ValidationError, lines: dict[tuple[str, ...], int]) -> list[MachineProblem]:
    """The controller section's own checks (axis letters, lines read back), which pydantic does
    not run on a section with a wrong key: run on the section without its wrong keys."""
    section = data.get("controller")
    locs = [tuple(map(str, item["loc"])) for item in error.errors()]
    wrong = {loc[1] for loc in locs if len(loc) > 1 and loc[0] == "controller"}
    if not isinstance(section, dict) or not wrong or ("controller",) in locs:
        return []
    try:
        ControllerConfig.model_validate({k: v for k, v in section.items() if str(k) not in wrong})
    except ValidationError as exc:
        return [p for p in _problems(exc, lines, data, ("controller",), Machine) if p.path.split(".")[1] not in wrong]
    return []


@dataclass(frozen=True)
class _Document:
    """A YAML document as read: its data, the 1-based line of every key (and sequence item) by
    its key path, and the values written in quotes that read as numbers."""

    data: object
    lines: dict[tuple[str, ...], int]
    quoted: tuple[tuple[tuple[str, ...], int], ...] = ()


def _document(root: yaml.Node, data: object) -> _Document:
    """The :class:`_Document` of the node tree ``root`` and the ``data`` constructed from it."""
    lines: dict[tuple[str, ...], int] = {}
    quoted = []
    stack: list[tuple[tuple[str, ...], yaml.Node]] = [((), root)]
    while stack:
        path, node = stack.pop()
        if isinstance(node, yaml.MappingNode):
            for key, value in node.value:
                if isinstance(key, yaml.ScalarNode):
                    child = (*path, str(key.value))
                    lines.setdefault(child, key.start_mark.line + 1)
                    stack.append((child, value))
        elif isinstance(node, yaml.SequenceNode):
            for k, value in enumerate(node.value):
                child = (*path, str(k))
                lines.setdefault(child, value.start_mark.line + 1)
                stack.append((child, value))
        elif node.style in ("'", '"') and _NUMBER_TEXT.fullmatch(node.value.strip()):
            quoted.append((path, node.start_mark.line + 1))
    return _Document(data, lines, tuple(sorted(quoted, key=lambda q: q[1])))


_NUMBER_TEXT = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")


#: Bounds on a machine file: bytes, nesting depth, and values (aliases expanded).
MAX_FILE_BYTES = 1 << 20
MAX_DEPTH = 16
MAX_VALUES = 100_000
#: Characters of one number: far more than any float's 17 significant digits and exponent. A
#: longer one is a mistake (and an integer of more than 4,300 digits would make Python's int()
#: raise its own ValueError).
MAX_NUMBER_CHARS = 100
_NUMBER_TAGS = frozenset({"tag:yaml.org,2002:int", "tag:yaml.org,2002:float"})


class _MachineLoader(yaml.SafeLoader):
    """YAML's safe loader that refuses a key given twice in one mapping (YAML would silently
    keep the last one: a machine file with two ``L1:`` is a mistake, not a choice)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        first: dict[object, int] = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                line = first.setdefault(key, key_node.start_mark.line + 1)
            except TypeError:  # an unhashable key: the safe loader reports it
                continue
            if line != key_node.start_mark.line + 1:
                raise yaml.constructor.ConstructorError(None, None, f"duplicate key {key!r} (first at line {line})",
                                                        key_node.start_mark)
        return super().construct_mapping(node, deep)


def _parse_yaml(text: str, source: str) -> _Document:
    """The document of ``text``, within :data:`MAX_DEPTH` and :data:`MAX_VALUES`."""
    try:
        depth = 0
        for event in yaml.parse(text, Loader=_MachineLoader):  # the event stream: no recursion yet
            if isinstance(event, yaml.CollectionStartEvent):
                depth += 1
                if depth > MAX_DEPTH:
                    raise InputError(f"nested deeper than {MAX_DEPTH} levels", source, event.start_mark.line + 1)
            elif isinstance(event, yaml.CollectionEndEvent):
                depth -= 1
        loader = _MachineLoader(text)
        try:
            node = loader.get_single_node()
            if node is None:
                return _Document(None, {})
            _count_values(node, source)
            return _document(node, loader.construct_document(node))
        finally:
            loader.dispose()
    except yaml.YAMLError as exc:
        line, reason = _yaml_problem(exc)
        raise InputError(f"invalid YAML: {reason}", source, line) from None


def _yaml_problem(exc: yaml.YAMLError) -> tuple[int | None, str]:
    """The line (1-based) and reason of a YAML error, in the user's terms: a key without a
    space after its colon and an unclosed ``{`` or ``[`` at the line where they are written
    (YAML notices them a line later), a tab named as such."""
    mark, context = getattr(exc, "problem_mark", None), getattr(exc, "context_mark", None)
    problem, while_ = str(getattr(exc, "problem", None) or exc), str(getattr(exc, "context", None) or "")
    line = None if mark is None else mark.line + 1
    if "'\\t'" in problem:
        return line, "a tab character: indent with spaces"
    if context is None or mark is None or context.line >= mark.line:
        return line, problem
    if while_ == "while scanning a simple key":
        return context.line + 1, f"{problem}: write a key as 'key: value', with a space after the colon"
    if while_ in ("while parsing a flow mapping", "while parsing a flow sequence"):
        bracket = "{}" if "mapping" in while_ else "[]"
        return context.line + 1, f"the '{bracket[0]}' of this line is not closed by a '{bracket[1]}' ({problem})"
    return line, problem


def _count_values(root: yaml.Node, source: str) -> None:
    """Refuse more than :data:`MAX_VALUES` values counting every alias use (an alias bomb), and
    numbers longer than :data:`MAX_NUMBER_CHARS` characters."""
    stack, count = [root], 0
    while stack:
        node = stack.pop()
        count += 1
        if count > MAX_VALUES:
            raise InputError(f"more than {MAX_VALUES} values (aliases expanded)", source, node.start_mark.line + 1)
        if isinstance(node, yaml.ScalarNode) and node.tag in _NUMBER_TAGS and len(node.value) > MAX_NUMBER_CHARS:
            raise InputError(f"a number of {len(node.value)} characters (at most {MAX_NUMBER_CHARS})", source,
                             node.start_mark.line + 1)
        if isinstance(node, yaml.MappingNode):
            stack.extend(child for pair in node.value for child in pair)
        elif isinstance(node, yaml.SequenceNode):
            stack.extend(node.value)


def load_machine(path: str | Path | None = None) -> Machine:
    """Read and validate a machine YAML file; ``None`` gives the VERNE shipped with the package."""
    return machine_from_text(machine_text(path), DEFAULT_MACHINE if path is None else str(path))


def machine_text(path: str | Path | None = None) -> str:
    """The text of a machine file as written (``None``: the shipped VERNE), at most
    :data:`MAX_FILE_BYTES`, UTF-8: what :func:`load_machine` validates and tools that edit it keep."""
    if path is None:
        raw = (resources.files("verne_post") / "machines" / DEFAULT_MACHINE).read_bytes()
        return _decoded(raw, "machine file", DEFAULT_MACHINE)
    return _bounded_text(path, "machine file", "machine file")


def _bounded_text(path: str | Path, noun: str, read_noun: str) -> str:
    """A YAML file's text, at most :data:`MAX_FILE_BYTES`, UTF-8; ``noun`` names it in errors
    (``read_noun`` where it cannot be read)."""
    source = str(path)
    try:
        with open(path, "rb") as handle:
            raw = handle.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise InputError(f"cannot read {read_noun}: {exc.strerror or exc}", source) from None
    return _decoded(raw, noun, source)


def _decoded(raw: bytes, noun: str, source: str) -> str:
    if len(raw) > MAX_FILE_BYTES:
        raise InputError(f"{noun} larger than {MAX_FILE_BYTES} bytes", source)
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{noun} is not UTF-8 text", source) from None


def load_setup(path: str | Path) -> SetupConfig:
    """A setup file (``--setup``): the keys of a machine file's ``setup:`` section (units, stock,
    fixtures) at its top level, read and validated as a machine file is (the first problem at its line)."""
    source = str(path)
    text = _bounded_text(path, "setup file", "the setup file")
    document = _parse_yaml(text, source)
    if not isinstance(document.data, dict):
        raise InputError("a setup file must be a YAML mapping of units, stock and fixtures", source)
    try:
        setup = SetupConfig.model_validate(document.data)
    except ValidationError as exc:
        raise _problems(exc, document.lines, document.data, model=SetupConfig)[0].error(source) from None
    quoted = _quoted(setup, document)
    if quoted:
        raise quoted[0].error(source)
    return setup


def machine_from_text(text: str, source: str) -> Machine:
    """Parse and validate the text of a machine file (``source`` names it in messages); the first
    problem is an :class:`InputError` at its line (:func:`machine_problems` gives them all)."""
    machine, problems = machine_problems(text, source)
    if problems:
        raise problems[0].error(source)
    assert machine is not None
    return machine


def machine_problems(text: str, source: str) -> tuple[Machine | None, list[MachineProblem]]:
    """The machine of a machine file's text and, if it has any, every problem in it in the order
    of the file (then None): YAML errors end the reading at the first; the model's checks are
    all reported, each at the line of its key. ``source`` names the file."""
    document = _parse_yaml(text, source)
    data, lines = document.data, document.lines
    if not isinstance(data, dict):
        raise InputError("machine file must be a YAML mapping", source)
    try:
        machine = Machine.model_validate(data)
    except ValidationError as exc:
        problems = _problems(exc, lines, data) + _controller_checks(data, exc, lines)
        return None, sorted(problems, key=lambda p: (p.line is None, p.line or 0))
    quoted = _quoted(machine, document)
    if quoted:
        return None, quoted
    machine._source = Path(source).name
    start = machine.controller.start_warning()
    if start is not None:
        where = ("controller", "program_start")
        machine._warnings = (str(MachineProblem(lines.get(where), ".".join(where), start).error(source)),)
    return machine, []
