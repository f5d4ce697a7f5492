"""The main job: CL file -> checked, linearised joint-space program (the CLI is a thin layer).

parse CL -> machine poses -> IK and branch choice -> linearisation -> checks -> durations ->
writer. Each stage is its own module; this one wires them and keeps the statistics.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from . import __version__
from .api import JOINT_NAMES
from .branch import PathIK, solve_path
from .checks import Violation, check_program, theta2_rate_warnings
from .cl import read_toolpath
from .gcode import GcodeFormat, Program, program_text, with_header_line, write_program, write_text
from .linearise import Blocks, linearise
from .machine import Machine
from .poses import MachinePoses, machine_poses
from .toolpath import Dwell, ToolChange
from .topp import Engine
from .verify import Reference, Verification, verify_program

if TYPE_CHECKING:
    from .placement import Placement
    from .schedule import Schedule

# The planner (verne_post.schedule, verne_post.timing) is imported where it is used: with
# toppra it takes about a second to load, which 'place' (check_poses only) does not need.


@dataclass(frozen=True)
class PostOptions:
    """User choices (mm and degrees, as on the command line)."""

    # Part zero in the table frame, mm; None: the machine file's; "auto": found by verne_post.placement.
    work_offset: tuple[float, float, float] | Literal["auto"] | None = None
    tool_length: float | None = None  # mm, for tools whose length nothing else gives
    units: Literal["mm", "inch"] | None = None  # override the CL file's units
    tol: float = 0.005  # mm: tool tip deviation from the CL path between blocks
    axis_tol: float = 0.05  # deg: tool axis deviation from the CL path between blocks
    arc_tol: float = 0.001  # mm: chordal deviation of CIRCLE arcs expanded into CL points
    arc_direction: Literal["cw", "ccw"] | None = None  # override the CL dialect's arc direction
    frame: Literal["local", "world", "apply"] | None = None  # override the CL dialect's frame reading
    plan: bool = True  # time-parametrise (TOPP2, ruckig); False: feeds from the programmed feed only
    planner: Engine = "copp"  # TOPP2 engine of the feed moves (verne_post.topp): copp-py, or toppra the reference
    workers: int = field(default_factory=lambda: os.cpu_count() or 1)  # processes for the feed planning


@dataclass
class PostResult:
    """What the pipeline produced; ``program`` is None when there are violations."""

    poses: MachinePoses
    path: PathIK
    blocks: Blocks
    rapid: np.ndarray  # (M,) per block
    duration: np.ndarray  # (M,) s
    violations: list[Violation]
    warnings: list[str]
    program: Program | None
    schedule: Schedule | None
    seconds: dict[str, float] = field(default_factory=dict)
    placement: Placement | None = None  # how the work offset was chosen (work_offset "auto")

    def report(self, machine: Machine, options: PostOptions) -> dict[str, Any]:
        """Summary statistics and every violation, JSON-ready (mm, degrees, seconds)."""
        joints = self.blocks.joints
        finite = np.all(np.isfinite(joints), axis=1)
        ranges = {}
        for j, name in enumerate(JOINT_NAMES):
            values = joints[finite, j] * (1.0 if j < 3 else 180 / np.pi)
            ranges[name] = [float(values.min()), float(values.max())] if values.size else None
        margins = self.blocks.result.margins
        tips = self.blocks.tip
        feed_length = float(np.sum(np.linalg.norm(np.diff(tips, axis=0), axis=1)[~self.rapid[1:]]))
        return {
            "source": self.poses.source,
            "dialect": self.poses.dialect,
            "machine": machine.source,
            "verne_post": __version__,
            "ok": not self.violations,
            "violations": [{"line": v.line, "kind": v.kind, "message": v.message} for v in self.violations],
            "warnings": self.warnings,
            "points": {"cl": len(self.poses), "inserted": int(np.sum(self.blocks.fraction < 1)), "blocks": len(tips),
                       "in_pole_cone": int(self.path.in_cone.sum())},
            "largest_axis_deviation_in_pole_cone_deg": float(np.degrees(np.max(
                2 * np.arcsin(np.linalg.norm(self.path.axis - self.poses.axis, axis=1) / 2), initial=0.0))),
            "joint_ranges": ranges,
            "joint_units": {"rho1": "mm", "rho2": "mm", "rho3": "mm", "theta1": "deg", "theta2": "deg"},
            "smallest_margins": {name: _nanmin(getattr(margins, name)) for name in
                                 ("serial", "parallel", "machine", "rod_clearance")},
            "path_length_mm": {"feed": feed_length,
                               "rapid": float(np.sum(np.linalg.norm(np.diff(tips, axis=0), axis=1)[self.rapid[1:]]))},
            "estimated_time_s": float(np.sum(self.duration)),
            "tolerances": {"tip_mm": options.tol, "axis_deg": options.axis_tol, "arc_mm": options.arc_tol},
            "tools": [{"tool": t.number, "length_mm": t.length, "delta_mm": t.delta, "line": t.line,
                       "length_from": t.source} for t in self.poses.tools],
            "timing": self._timing(machine),
            "work_offset_mm": list(self.placement.offset if self.placement else _offset(machine, options)),
            "placement": None if self.placement is None else self.placement.to_dict(),
            "seconds": self.seconds,
        }

    def _timing(self, machine: Machine) -> dict[str, Any] | None:
        if self.schedule is None:
            return None
        from .schedule import limit_ratios, time_budget
        from .timing import Limits

        limits = Limits.from_machine(machine)
        tools = self.poses.tool[self.blocks.pose]
        ratios = limit_ratios(self.schedule, limits)
        speed = feed_speed(self.poses, self.blocks, self.duration)
        budget = time_budget(self.schedule, self.blocks.joints, self.blocks.tip, speed, limits,
                             np.radians(machine.timing.rotary_feed) / 60.0)
        dwell = sum(e.seconds for e in self.poses.events if isinstance(e, Dwell))
        return {
            "cycle_time_s": self.schedule.total + dwell,
            "dwell_time_s": dwell,
            "rapid_time_s": float(np.sum(self.duration[self.rapid])),
            **budget,
            "time_per_tool_s": {str(t): float(np.sum(self.duration[tools == t])) for t in np.unique(tools)},
            "largest_ratio_to_limit": {name: {"velocity": float(ratios[0, j]), "acceleration": float(ratios[1, j]),
                                              "jerk": float(ratios[2, j])} for j, name in enumerate(JOINT_NAMES)},
        }


def _nanmin(values: np.ndarray) -> float | None:
    finite = values[np.isfinite(values)]
    return float(finite.min()) if finite.size else None


def block_durations(machine: Machine, poses: MachinePoses, blocks: Blocks, rapid: np.ndarray) -> np.ndarray:
    """Seconds per block before time-parametrisation: programmed feed, never faster than a joint.

    Feed blocks take their Cartesian length over the programmed feed (inverse-time moves their
    share of 1/F), and at least the time the slowest joint needs at its velocity limit; so a
    rotary-only block is never of zero duration. Rapids: the joint-limit time.
    """
    from .timing import Limits

    step = np.abs(np.diff(blocks.joints, axis=0, prepend=blocks.joints[:1]))
    joint_time = np.max(step / Limits.from_machine(machine).velocity, axis=1)
    length = np.linalg.norm(np.diff(blocks.tip, axis=0, prepend=blocks.tip[:1]), axis=1)
    feed = poses.feed[blocks.pose]
    previous = np.r_[0.0, blocks.fraction[:-1]]
    share = np.where(blocks.pose == np.r_[-1, blocks.pose[:-1]], blocks.fraction - previous, blocks.fraction)
    with np.errstate(divide="ignore", invalid="ignore"):
        cartesian = np.where(poses.inverse_time[blocks.pose], 60.0 * share / feed, 60.0 * length / feed)
    return np.where(rapid, joint_time, np.fmax(np.nan_to_num(cartesian, nan=0.0), joint_time))


#: Tip speed limit (mm/s) given to the planner where the programmed one does not apply: a
#: rotary-only inverse-time block (no tip travel) is limited by timing.rotary_feed instead.
NO_TIP_LIMIT = 1e9


def feed_speed(poses: MachinePoses, blocks: Blocks, duration: np.ndarray) -> np.ndarray:
    """Programmed tip speed limit (mm/s) of the motion into each block; inverse-time moves give
    their length over their programmed duration."""
    speed = poses.feed[blocks.pose] / 60.0
    length = np.linalg.norm(np.diff(blocks.tip, axis=0, prepend=blocks.tip[:1]), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = np.where((duration > 0) & (length > 0), length / duration, NO_TIP_LIMIT)
    return np.where(poses.inverse_time[blocks.pose], inverse, speed)


@dataclass(frozen=True)
class Checked:
    """The program in joint space with everything the machine cannot do (stages 3 to 5)."""

    path: PathIK
    blocks: Blocks
    rapid: np.ndarray  # (M,) per block
    violations: tuple[Violation, ...]


def check_poses(machine: Machine, poses: MachinePoses, options: PostOptions,
                lap: Callable[[str], None] = lambda stage: None, first_failure: bool = False) -> Checked:
    """IK and branch, linearisation and every check of table-frame poses (no timing); violations
    sorted by line. Placement calls this for each candidate work offset. With ``first_failure``
    the linearisation stops once a block end fails: the violations then show that the program
    fails, not every way it does (placement's room only asks whether it runs)."""
    cone = np.radians(machine.pole.cone)
    solved = solve_path(machine, poses.tip, poses.axis, poses.sequence, tool_length=poses.tool_length, cone=cone)
    lap("ik")
    blocks = linearise(machine, poses, solved, tol=options.tol, axis_tol=np.radians(options.axis_tol), cone=cone,
                       until_failure=first_failure)
    lap("linearise")
    rapid = poses.rapid[blocks.pose].copy()  # rapids are never split, so each is one block
    rapid[0] = True  # where the machine stands before the program is unknown: position with G0
    violations = check_program(machine, blocks.result, rapid, poses.tool_length[blocks.pose], poses.line[blocks.pose])
    for k in blocks.unresolved:
        violations.append(Violation(int(poses.line[k]), "path", f"the move cannot be kept within {options.tol} mm / "
                                                                f"{options.axis_tol} deg of the CL path"))
    for k in np.flatnonzero(solved.pair_switch):
        violations.append(Violation(int(poses.line[k]), "branch", "no single tool-axis angle pair reaches this whole "
                                                                  "cut: the table would turn half a turn mid-cut"))
    violations.sort(key=lambda v: (v.line, v.kind))
    return Checked(solved, blocks, rapid, tuple(violations))


def postprocess(path: str | Path, machine: Machine, options: PostOptions,
                progress: Callable[[str], None] = lambda stage: None) -> PostResult:
    """Run every stage except writing. Raises InputError for bad input; violations are returned."""
    seconds: dict[str, float] = {}
    clock = time.perf_counter()

    def lap(stage: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        seconds[stage] = now - clock
        clock = now
        progress(stage)

    toolpath = read_toolpath(path, units=options.units, chordal_tolerance=options.arc_tol,
                             arc_direction=options.arc_direction, frame=options.frame)
    lap("parse")
    placement = None
    if options.work_offset == "auto":
        from .placement import place

        zero = machine_poses(toolpath, machine, work_offset=(0.0, 0.0, 0.0), tool_length=options.tool_length)
        placement = place(machine, zero, options, progress=progress)
        options = replace(options, work_offset=placement.offset)
        lap("placement")
    poses = machine_poses(toolpath, machine, work_offset=_offset(machine, options),
                          tool_length=options.tool_length)
    checked = check_poses(machine, poses, options, lap)
    solved, blocks, rapid, violations = checked.path, checked.blocks, checked.rapid, list(checked.violations)
    if placement is not None and not placement.feasible:
        violations.insert(0, Violation(placement.line, "placement", f"no work offset lets the whole program run: "
                                                                    f"{placement.reason}"))
    lines = poses.line[blocks.pose]
    source = poses.source
    warnings = list(poses.warnings) + theta2_rate_warnings(machine, blocks.joints, blocks.tip, rapid, lines, source)
    if solved.in_cone.any() and machine.pole.cone > options.axis_tol:
        warnings.append(f"{source}: the pole cone of the machine file ({machine.pole.cone:g} deg) is wider than the "
                        f"axis tolerance ({options.axis_tol:g} deg): near the table normal the tool axis may be off "
                        f"by up to {machine.pole.cone:g} deg")
    lap("checks")
    # Blocks that move no joint (repeated CL points) take no time and are left out.
    moving = np.flatnonzero(np.r_[True, np.any(np.diff(blocks.joints, axis=0) != 0, axis=1)])
    blocks, rapid = blocks.rows(moving), rapid[moving]
    duration = block_durations(machine, poses, blocks, rapid)
    schedule = None
    if not violations and options.plan:
        from .schedule import SequenceError, plan_program
        from .timing import Limits

        try:
            schedule = plan_program(blocks.joints, blocks.tip, rapid, feed_speed(poses, blocks, duration),
                                    poses.sequence[blocks.pose], Limits.from_machine(machine),
                                    rotary_feed=np.radians(machine.timing.rotary_feed) / 60.0,
                                    corner=np.radians(machine.timing.corner_angle), workers=options.workers,
                                    engine=options.planner)
            duration = schedule.duration
        except SequenceError as error:
            violations.append(Violation(int(poses.line[blocks.pose[error.block]]), "timing",
                                        f"cannot plan the feed motion: {error}"))
        lap("timing")
    program = None if violations else _program(machine, poses, blocks, rapid, duration, options, placement)
    return PostResult(poses, solved, blocks, rapid, duration, violations, warnings, program, schedule, seconds,
                      placement)


def _offset(machine: Machine, options: PostOptions) -> tuple[float, float, float]:
    """The work offset in force (mm): the option's, else the machine file's."""
    offset = machine.work_offset if options.work_offset is None else options.work_offset
    assert offset != "auto", "postprocess resolves the automatic work offset first"
    return offset


def _program(machine: Machine, poses: MachinePoses, blocks: Blocks, rapid: np.ndarray, duration: np.ndarray,
             options: PostOptions, placement: Placement | None) -> Program:
    events = [replace(e, index=int(np.searchsorted(blocks.pose, e.index, side="left"))) for e in poses.events]
    if poses.tools and poses.tools[0].source == "--tool-length" and poses.tools[0].number == 0:
        # motion before any tool change: the program still says which tool length its joints are for
        events.insert(0, ToolChange(0, poses.tools[0].line, 0, poses.tools[0].length))
    offset = _offset(machine, options)
    tools = {t.number: (t.length, t.delta) for t in poses.tools}
    header = (
        f"POSTPROCESSOR VERNE-POST {__version__}",
        f"MACHINE {machine.source} ({machine.name})",
        f"SOURCE {Path(poses.source).name}",
        f"CL DIALECT {poses.dialect}",
        "AXES X Y Z = SLIDERS RHO1 RHO2 RHO3 MM, A = TILT THETA1 DEG, C = ROTARY THETA2 DEG",
        "WORK OFFSET {:.4f} {:.4f} {:.4f} MM (PART ZERO IN THE TABLE FRAME)".format(*offset),
        *(placement.header() if placement is not None else (
            "WORK OFFSET FROM " + ("THE MACHINE FILE" if options.work_offset is None else "THE USER"),)),
        f"TOLERANCE {options.tol:g} MM {options.axis_tol:g} DEG; BLOCKS {len(blocks.joints)} "
        f"(CL POINTS {len(poses)}, INSERTED {int(np.sum(blocks.fraction < 1))})",
        f"CYCLE TIME {np.sum(duration):.1f} S ({_TIME_BASIS[options.plan]})",
    )
    if any(isinstance(e, ToolChange) and e.tool == 0 for e in events):
        header += ("TOOL 0: TOOL DATA WITHOUT A TOOL NUMBER IN THE CL FILE; LOAD THE TOOL BY HAND",)
    return Program(
        joints=blocks.joints, rapid=rapid, duration=duration, line=poses.line[blocks.pose], events=tuple(events),
        part_name=poses.part_name, header=header, tool_lengths=tools,
    )


_TIME_BASIS = {True: "PLANNED: FEEDS, JOINT VELOCITY, ACCELERATION AND JERK LIMITS",
               False: "PROGRAMMED FEEDS AND JOINT VELOCITY LIMITS ONLY"}


def write_gcode(result: PostResult, machine: Machine, options: PostOptions, path: str | os.PathLike[str],
                verify: bool = True) -> Verification | None:
    """Write the program of ``result`` as G-code to ``path`` (atomically).

    With ``verify`` the program text is first read back and verified against the CL path with
    the forward kinematics (:mod:`verne_post.verify`); only a program that passes is written,
    with the certified figures as a header line. Returns the verification (None without).
    """
    fmt = gcode_format(machine)
    if not verify:
        write_program(result.program, fmt, path)
        return None
    text = program_text(result.program, fmt)
    offset = result.placement.offset if result.placement is not None else _offset(machine, options)
    verification = verify_program(text, machine, source=str(path), against=Reference.of(result.poses),
                                  work_offset=offset, tol=options.tol, axis_tol=options.axis_tol)
    if verification.ok:
        write_text(with_header_line(text, verification.certificate()), path)
    return verification


def write_output(result: PostResult, machine: Machine, options: PostOptions, path: str | os.PathLike[str],
                 output_format: Literal["gcode", "csv"] = "gcode", period: float = 0.001, verify: bool = True,
                 decimals: int | None = None) -> Verification | None:
    """Write the program of ``result`` to ``path`` (atomically): G-code as :func:`write_gcode` does,
    or the timed joint trajectory as CSV, a row every ``period`` s (0: one per block end), t and
    positions with ``decimals`` (default: enough for third differences at the period)."""
    if output_format == "gcode":
        return write_gcode(result, machine, options, path, verify=verify)
    from .trajectory import write_timed_csv

    blocks = result.blocks
    write_timed_csv(path, machine, result.schedule, result.poses.tool_length[blocks.pose],
                    result.poses.line[blocks.pose], period, decimals)
    return None


def gcode_format(machine: Machine) -> GcodeFormat:
    g = machine.gcode
    return GcodeFormat(g.linear_decimals, g.angular_decimals, g.feed_decimals, g.block_numbers, g.block_number_step)


__all__ = ["Checked", "PostOptions", "PostResult", "block_durations", "check_poses", "feed_speed", "gcode_format",
           "postprocess", "write_gcode", "write_output"]
