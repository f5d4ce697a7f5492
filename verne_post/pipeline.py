"""The main job: CL file -> checked, linearised joint-space program (the CLI is a thin layer).

parse CL -> machine poses -> IK and branch choice -> linearisation -> checks -> durations ->
writer. Each stage is its own module; this one wires them and keeps the statistics.

A long program goes through the stages after parsing a *part* at a time (:func:`post`), so
that memory follows the largest part, not the program. A part ends where the machine stops
anyway: at a rapid, or where a feed sequence starts (the planner plans each from rest to rest),
so its timing is the same. What the other stages carry across is handed on explicitly: the
angle pair of each run is chosen over the whole program before the parts are solved (a
pre-pass keeping two angles and a status per pose), the rotary's continuity and the pole
cone's interpolation continue from the part before (:class:`~verne_post.branch.BranchState`),
the feed move into a part is linearised from the part before's last pose, the checks and the
timing of the move into a part start from its last block, and the verification reads on from
where it stood. The program is the same however it is split (tests/test_parts.py). The
report's figures are gathered part by part (:class:`Figures`); the G-code waits in a
temporary file until the header's figures are known. :func:`postprocess` runs the whole
program as one part and keeps its arrays (the HTML report and the timed CSV use them).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Literal

import numpy as np

from . import __version__
from .api import JOINT_NAMES, joint_bounds
from .atomic import atomic_write
from .branch import BranchState, PairAngles, Pairs, PathIK, both_pairs, choose_pairs, in_pole_cone, solve_path
from .checks import Violation, check_program, theta2_rate_warnings
from .cl import read_toolpath
from .errors import OutputError
from .gcode import GcodeFormat, GcodeWriter, Program, program_text, with_header_line, write_program, write_text
from .helpers import Helper, VerifierProcess, available, outcome
from .linearise import Blocks, linearise
from .machine import Machine
from .poses import MachinePoses, machine_poses
from .safe_motion import SafeSettings, between_cuts
from .schedule import Schedule, SequenceError, feed_sequences, limit_ratios, plan_program, time_budget
from .timing import Limits
from .toolpath import Dwell, Event, ToolChange
from .topp import Engine
from .verify import Reference, Verification, Verifier, feed_top, verify_program

if TYPE_CHECKING:
    from .placement import Placement


@dataclass(frozen=True)
class PostOptions:
    """User choices (mm and degrees, as on the command line)."""

    # Part zero in the table frame, mm; None: the machine file's; "auto": found by verne_post.placement.
    work_offset: tuple[float, float, float] | Literal["auto"] | None = None
    tool_length: float | None = None  # mm, for tools whose length nothing else gives
    units: Literal["mm", "inch"] | None = None  # override the CL file's units
    tol: float = 0.005  # mm: tool tip deviation from the CL path between blocks
    axis_tol: float = 0.05  # deg: tool axis deviation from the CL path between blocks
    rapid_tol: float = 0.5  # mm: tool tip deviation from a CL rapid's straight line (never below it)
    rapid_axis_tol: float = 0.5  # deg: tool axis deviation from a CL rapid's interpolated axis
    arc_tol: float = 0.001  # mm: chordal deviation of CIRCLE arcs expanded into CL points
    arc_direction: Literal["cw", "ccw"] | None = None  # override the CL dialect's arc direction
    frame: Literal["local", "world", "apply"] | None = None  # override the CL dialect's frame reading
    feed: float | None = None  # mm/min: the feed of feed moves before the CL file's first FEDRAT
    plan: bool = True  # time-parametrise (TOPP2, ruckig); False: feeds from the programmed feed only
    planner: Engine = "copp"  # TOPP2 engine of the feed moves (verne_post.topp): copp-py, or toppra the reference
    optimize: bool = False  # also the third-order programme on long feed sequences (verne_post.third_order)
    workers: int = field(default_factory=lambda: os.cpu_count() or 1)  # processes for the feed planning


_MARGINS = ("serial", "parallel", "machine", "rod_clearance")


@dataclass
class Figures:
    """The report's figures of a program's blocks, gathered a part at a time (:meth:`add`): mm,
    rad inside, seconds. The timing figures only where every part was planned."""

    blocks: int = 0
    inserted: int = 0
    in_pole_cone: int = 0
    cone_deviation: float = 0.0  # rad: largest axis deviation in the pole cone
    low: np.ndarray = field(default_factory=lambda: np.full(5, np.inf))  # joint ranges (finite blocks)
    high: np.ndarray = field(default_factory=lambda: np.full(5, -np.inf))
    margins: dict[str, float] = field(default_factory=lambda: dict.fromkeys(_MARGINS, np.inf))
    feed_length: float = 0.0
    rapid_length: float = 0.0
    time: float = 0.0  # s: sum of the block durations
    rapid_time: float = 0.0
    time_per_tool: dict[int, float] = field(default_factory=dict)
    planned: bool = True  # every part has a schedule
    budget: dict[str, float] = field(default_factory=dict)
    ratios: np.ndarray = field(default_factory=lambda: np.zeros((3, 5)))  # velocity, acceleration, jerk / limit

    def add(self, poses: MachinePoses, path: PathIK, first: int, blocks: Blocks, rapid: np.ndarray, timed: Timing,
            context: int = 0) -> None:
        """Add the figures of a part: the path of poses ``first``... and its blocks, their timing
        (with the planner's figures, if gathered); the first ``context`` blocks belong to the part
        before (the motion from there counts)."""
        own = slice(context, None)
        joints = blocks.joints[own]
        finite = joints[np.all(np.isfinite(joints), axis=1)]
        if len(finite):
            self.low, self.high = np.fmin(self.low, finite.min(axis=0)), np.fmax(self.high, finite.max(axis=0))
        self.blocks += len(joints)
        self.inserted += int(np.sum(blocks.fraction[own] != 1))
        self.in_pole_cone += int(path.in_cone.sum())
        axis = poses.axis[first:first + len(path.axis)]
        self.cone_deviation = max(self.cone_deviation, float(np.max(
            2 * np.arcsin(np.linalg.norm(path.axis - axis, axis=1) / 2), initial=0.0)))
        for name in _MARGINS:
            self.margins[name] = float(np.fmin(self.margins[name], np.nanmin(
                getattr(blocks.result.margins, name)[own], initial=np.inf)))
        step = np.linalg.norm(np.diff(blocks.tip, axis=0), axis=1)
        self.feed_length += float(np.sum(step[~rapid[1:]]))
        self.rapid_length += float(np.sum(step[rapid[1:]]))
        own_duration, own_rapid = timed.duration[own], rapid[own]
        self.time += float(np.sum(own_duration))
        self.rapid_time += float(np.sum(own_duration[own_rapid]))
        tools = poses.tool[blocks.pose[own]]
        for tool in np.unique(tools):
            self.time_per_tool[int(tool)] = self.time_per_tool.get(int(tool), 0.0) + float(
                np.sum(own_duration[tools == tool]))
        self.planned &= timed.planned
        if timed.ratios is not None and timed.budget is not None:
            self.ratios = np.maximum(self.ratios, timed.ratios)
            for name, value in timed.budget.items():
                self.budget[name] = self.budget.get(name, 0.0) + value


def _finite(value: float) -> float | None:
    return value if np.isfinite(value) else None


def _report(machine: Machine, options: PostOptions, poses: MachinePoses, violations: list[Violation],
            warnings: list[str], figures: Figures, placement: Placement | None, seconds: dict[str, float]
            ) -> dict[str, Any]:
    """Summary statistics and every violation, JSON-ready (mm, degrees, seconds)."""
    scale = np.array([1.0, 1.0, 1.0, 180 / np.pi, 180 / np.pi])
    ranges = {name: [float(figures.low[j] * scale[j]), float(figures.high[j] * scale[j])]
              if figures.low[j] <= figures.high[j] else None for j, name in enumerate(JOINT_NAMES)}
    timing = None
    if figures.planned and figures.blocks:
        dwell = sum(e.seconds for e in poses.events if isinstance(e, Dwell))
        timing = {
            "cycle_time_s": figures.time + dwell,
            "dwell_time_s": dwell,
            "rapid_time_s": figures.rapid_time,
            **figures.budget,
            "time_per_tool_s": {str(t): figures.time_per_tool[t] for t in sorted(figures.time_per_tool)},
            "largest_ratio_to_limit": {name: dict(zip(("velocity", "acceleration", "jerk"),
                                                      map(float, figures.ratios[:, j]), strict=True))
                                       for j, name in enumerate(JOINT_NAMES)},
        }
    return {
        "source": poses.source,
        "dialect": poses.dialect,
        "machine": machine.source,
        "verne_post": __version__,
        "ok": not violations,
        "violations": [{"line": v.line, "kind": v.kind, "message": v.message} for v in violations],
        "warnings": warnings,
        "points": {"cl": len(poses), "inserted": figures.inserted, "blocks": figures.blocks,
                   "in_pole_cone": figures.in_pole_cone},
        "largest_axis_deviation_in_pole_cone_deg": float(np.degrees(figures.cone_deviation)),
        "joint_ranges": ranges,
        "joint_units": {"rho1": "mm", "rho2": "mm", "rho3": "mm", "theta1": "deg", "theta2": "deg"},
        "smallest_margins": {name: _finite(figures.margins[name]) for name in _MARGINS},
        "path_length_mm": {"feed": figures.feed_length, "rapid": figures.rapid_length},
        "estimated_time_s": figures.time,
        "tolerances": {"tip_mm": options.tol, "axis_deg": options.axis_tol, "arc_mm": options.arc_tol},
        "tools": [{"tool": t.number, "length_mm": t.length, "delta_mm": t.delta, "line": t.line,
                   "length_from": t.source} for t in poses.tools],
        "timing": timing,
        "work_offset_mm": list(placement.offset if placement else _offset(machine, options)),
        "placement": None if placement is None else placement.to_dict(),
        "seconds": seconds,
    }


@dataclass
class PostResult:
    """What the pipeline produced for the whole program; ``program`` is None when there are violations."""

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

    def figures(self, machine: Machine, timing: bool = True) -> Figures:
        """The report's figures; ``timing``: with the planner's (time budget, ratios to the limits)."""
        timed = Timing(self.duration, self.schedule, planned=self.schedule is not None)
        if timing and self.schedule is not None:
            timed = timed.with_figures(self.blocks.joints, self.blocks.tip, feed_speed(self.poses, self.blocks,
                                                                                        self.duration),
                                       Limits.from_machine(machine), np.radians(machine.timing.rotary_feed) / 60.0)
        figures = Figures()
        figures.add(self.poses, self.path, 0, self.blocks, self.rapid, timed)
        return figures

    def report(self, machine: Machine, options: PostOptions) -> dict[str, Any]:
        """Summary statistics and every violation, JSON-ready (mm, degrees, seconds)."""
        return _report(machine, options, self.poses, self.violations, self.warnings, self.figures(machine),
                       self.placement, self.seconds)


def block_durations(machine: Machine, poses: MachinePoses, blocks: Blocks, rapid: np.ndarray) -> np.ndarray:
    """Seconds per block before time-parametrisation: programmed feed, never faster than a joint.

    Feed blocks take their Cartesian length over the programmed feed (inverse-time moves their
    share of 1/F), and at least the time the slowest joint needs at its velocity limit; so a
    rotary-only block is never of zero duration. Rapids: the joint-limit time.
    """
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
    return _tip_speed(poses.feed[blocks.pose], poses.inverse_time[blocks.pose], blocks.tip, duration)


def _tip_speed(feed: np.ndarray, inverse_time: np.ndarray, tip: np.ndarray, duration: np.ndarray) -> np.ndarray:
    """:func:`feed_speed` of blocks with programmed ``feed`` (mm/min, or 1/min where
    ``inverse_time``), tips (mm) and durations (s)."""
    length = np.linalg.norm(np.diff(tip, axis=0, prepend=tip[:1]), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = np.where((duration > 0) & (length > 0), length / duration, NO_TIP_LIMIT)
    return np.where(inverse_time, inverse, feed / 60.0)


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
    solved = _solve(machine, poses, options)
    lap("ik")
    blocks = _linearise(machine, poses, options, solved, until_failure=first_failure)
    lap("linearise")
    between = between_cuts(machine, poses, blocks, _safe_settings(machine, poses, options), before=None,
                           end=len(poses))
    blocks = between.blocks
    rapid = _rapid(poses, blocks)
    rapid[0] = True  # where the machine stands before the program is unknown: position with G0
    checks, others = _checks(machine, poses, options, solved.pair_switch, blocks, rapid)
    others += _between_violations(poses, between.problems)
    return Checked(solved, blocks, rapid, tuple(sorted(checks + others, key=lambda v: (v.line, v.kind))))


def _rapid_speed(machine: Machine) -> float:
    """mm/s: the tip speed limit of rapids (the machine file's ``safe.rapid_feed``, else none)."""
    return NO_TIP_LIMIT if machine.safe.rapid_feed is None else machine.safe.rapid_feed / 60.0


def _safe_settings(machine: Machine, poses: MachinePoses, options: PostOptions) -> SafeSettings:
    return SafeSettings.of(machine, poses.tip, poses.rapid, rapid_tol=options.rapid_tol,
                           rapid_axis_tol=np.radians(options.rapid_axis_tol), tol=options.tol,
                           axis_tol=np.radians(options.axis_tol))


def _rapid(poses: MachinePoses, blocks: Blocks) -> np.ndarray:
    """Per block: a move between cuts (a CL rapid's, or one the safe-motion stage made)."""
    return poses.rapid[blocks.pose] | blocks.between


def _between_violations(poses: MachinePoses, problems: tuple[tuple[int, str], ...]) -> list[Violation]:
    return [Violation(int(poses.line[pose]), "rapid", reason) for pose, reason in problems]


def _solve(machine: Machine, poses: MachinePoses, options: PostOptions, state: BranchState | None = None,
           pairs: Pairs | None = None) -> PathIK:
    return solve_path(machine, poses.tip, poses.axis, poses.sequence, tool_length=poses.tool_length,
                      cone=np.radians(machine.pole.cone), state=state, pairs=pairs)


def _linearise(machine: Machine, poses: MachinePoses, options: PostOptions, solved: PathIK,
               until_failure: bool = False) -> Blocks:
    return linearise(machine, poses, solved, tol=options.tol, axis_tol=np.radians(options.axis_tol),
                     cone=np.radians(machine.pole.cone), until_failure=until_failure)


def _checks(machine: Machine, poses: MachinePoses, options: PostOptions, switch: np.ndarray, blocks: Blocks,
            rapid: np.ndarray, first: int = 0) -> tuple[list[Violation], list[Violation]]:
    """The violations of blocks (poses indexing ``poses``) and of the angle pair switches of poses
    ``first``...: those of the checks (one per line and kind) and the others."""
    checks = check_program(machine, blocks.result, rapid, poses.tool_length[blocks.pose], poses.line[blocks.pose])
    others = [Violation(int(poses.line[k]), "path", f"the move cannot be kept within {options.tol} mm / "
                                                    f"{options.axis_tol} deg of the CL path")
              for k in blocks.unresolved]
    others += [Violation(int(poses.line[first + k]), "branch", "no single tool-axis angle pair reaches this whole "
                                                               "cut: the table would turn half a turn mid-cut")
               for k in np.flatnonzero(switch)]
    return checks, others


#: Violations gathered over the parts at most (the checks of one part report at most 10,000
#: poses of a kind): memory stays bounded when a long program is wrong everywhere.
MAX_VIOLATIONS = 20_000

#: CL poses per part of a program (:func:`post`): a part ends where the machine stops, at a
#: rapid or between feed sequences, at the last such place among this many poses.
PART_POSES = 10_000


@dataclass(frozen=True)
class Timing:
    """Stage 6 of a part: the block durations (s), the schedule they come from (None: not
    planned, the durations then from the programmed feeds, or not kept), whether they were
    planned, what could not be planned, the seconds the planning took, and the planner's figures
    for the report when gathered (ratios to the limits (3, 5), the time budget in s)."""

    duration: np.ndarray
    schedule: Schedule | None = None
    planned: bool = False
    violations: tuple[Violation, ...] = ()
    seconds: float = 0.0
    ratios: np.ndarray | None = None
    budget: dict[str, float] | None = None

    def with_figures(self, joints: np.ndarray, tip: np.ndarray, speed: np.ndarray, limits: Limits,
                     rotary_feed: float) -> Timing:
        """With the planner's figures of the blocks (mm, rad; programmed tip speed mm/s; rad/s)."""
        assert self.schedule is not None
        return replace(self, ratios=limit_ratios(self.schedule, limits),
                       budget=time_budget(self.schedule, joints, tip, speed, limits, rotary_feed))


@dataclass(frozen=True)
class TimingTask:
    """What the planning of a part needs (:func:`plan_timing`), small enough to send to a
    helper process: the part's moving blocks (mm, rad), their feeds (mm/s) and CL lines."""

    joints: np.ndarray
    tip: np.ndarray
    rapid: np.ndarray
    feed: np.ndarray  # as programmed: mm/min, or 1/min where inverse_time
    inverse_time: np.ndarray
    group: np.ndarray
    line: np.ndarray
    unplanned: np.ndarray  # s: the durations from the programmed feeds, where planning fails
    limits: Limits
    rotary_feed: float  # rad/s
    corner: float  # rad
    engine: Engine
    optimize: bool  # also the third-order programme (plan_feeds)
    workers: int
    figures: bool  # also the planner's figures for the report (:meth:`Timing.with_figures`)
    rapid_speed: float = NO_TIP_LIMIT  # mm/s: the tip speed limit of rapids (machine's safe.rapid_feed)


def plan_timing(task: TimingTask) -> Timing:
    """Stage 6 of a part (feed sequences and rapids, :func:`~verne_post.schedule.plan_program`)."""
    start = time.perf_counter()
    try:
        speed = np.where(task.rapid, task.rapid_speed, _tip_speed(task.feed, task.inverse_time, task.tip,
                                                                   task.unplanned))
        schedule = plan_program(task.joints, task.tip, task.rapid, speed, task.group,
                                task.limits, rotary_feed=task.rotary_feed, corner=task.corner, workers=task.workers,
                                engine=task.engine, optimize=task.optimize)
    except SequenceError as error:
        violation = Violation(int(task.line[error.block]), "timing", f"cannot plan the feed motion: {error}")
        return Timing(task.unplanned, violations=(violation,), seconds=time.perf_counter() - start)
    timed = Timing(schedule.duration, schedule, planned=True)
    if task.figures:  # of the planned durations, as the HTML report's
        timed = timed.with_figures(task.joints, task.tip, _tip_speed(task.feed, task.inverse_time, task.tip,
                                                                     schedule.duration),
                                   task.limits, task.rotary_feed)
    return replace(timed, seconds=time.perf_counter() - start)


#: Plans a part's timing: here (:func:`plan_timing`), or in a helper process (a future of it).
Planner = Callable[[TimingTask], "Timing | Future[Timing]"]


@dataclass(frozen=True)
class Part:
    """Poses ``first`` to ``end - 1`` through stages 3 to 5; ``blocks`` (pose indices of the whole
    program) without those that move no joint, ``context`` of them (0 or 1) being the last block
    of the part before, there for the motion from it (the schedule counts it too). Its timing
    may still be under way in a helper process: :meth:`timed`."""

    first: int
    end: int
    path: PathIK
    blocks: Blocks
    rapid: np.ndarray
    unplanned: np.ndarray  # s: block durations from the programmed feeds
    planning: Timing | Future[Timing] | None  # None: not planned
    context: int
    checks: list[Violation]  # stage 3 checks, one per line and kind
    others: list[Violation]  # paths out of tolerance, angle pair switches
    warnings: list[str]

    @property
    def own(self) -> slice:
        return slice(self.context, None)

    def timed(self, wanted: bool = True) -> Timing:
        """The part's timing (waits for the helper); not ``wanted``: as if it had not been planned."""
        if self.planning is None or not wanted:
            if isinstance(self.planning, Future):
                self.planning.cancel()
            return Timing(self.unplanned)
        return outcome(self.planning) if isinstance(self.planning, Future) else self.planning


def _choose_pairs(machine: Machine, poses: MachinePoses, size: int) -> Pairs:
    """The angle pairs along the whole program, from both pairs' IK solved ``size`` poses at a
    time (the choice weighs whole runs: it is made before the parts are solved)."""
    n = len(poses)
    plus, minus = (PairAngles(np.empty(n, np.int8), np.empty((n, 2))) for _ in range(2))
    for first in range(0, n, size):
        part = poses.part(first, first + size)
        for out, result in zip((plus, minus), both_pairs(machine, part.tip, part.axis, part.tool_length),
                               strict=True):
            out.status[first:first + size], out.angles[first:first + size] = result.status, result.joints[:, 3:]
    return choose_pairs(plus, minus, poses.sequence, in_pole_cone(poses.axis, np.radians(machine.pole.cone)))


def _cut(machine: Machine, poses: MachinePoses, first: int, end: int, solved: PathIK, ext: Blocks,
         rapid: np.ndarray) -> int | None:
    """Where the part of poses ``first``... solved up to ``end`` ends: the last place before
    ``end`` where the machine stops whatever comes after (None: none). ``ext``: the moving
    blocks from the part before's last, ``rapid`` theirs.

    A rapid, or the first block of a pose that starts a feed sequence (the planner plans each
    from rest to rest) with its CL line not the pose before's (a record's points, an arc's,
    stay together) and the pose before off the pole cone with a solution (the cone's theta2 is
    interpolated between such poses), on a continuous rotary (a limited one is fitted into its
    range a sequence at a time).
    """
    candidates = first + 1 + np.flatnonzero(poses.rapid[first + 1:end])
    if not np.isfinite(joint_bounds(machine)[0][4]):
        starts = np.array([a for a, _ in feed_sequences(ext.joints, rapid, poses.sequence[ext.pose],
                                                        Limits.from_machine(machine),
                                                        np.radians(machine.timing.corner_angle))], int)
        starts = starts[starts >= 2]  # the turn into a block weighs the two blocks before it
        pose = ext.pose[starts]
        pose = pose[(pose > first) & (pose < end) & (ext.pose[starts - 1] == pose - 1)]  # a pose's first block
        pose = pose[(poses.line[pose] != poses.line[pose - 1]) & np.isfinite(solved.trace.added[pose - 1 - first])]
        candidates = np.r_[candidates, pose]
    return int(candidates.max()) if candidates.size else None


def _parts(machine: Machine, poses: MachinePoses, options: PostOptions, size: int, lap: Callable[[str], None],
           plan: bool, planner: Planner = plan_timing, figures: bool = False) -> Iterator[Part]:
    """Stages 3 to 5 of each part in turn (one part when ``size`` covers the program), and the
    timing of each handed to ``planner``; ``plan``: plan the timing of the parts, up to the
    first with a violation of stages 3 to 5; ``figures``: with the planner's figures."""
    n = len(poses)
    pairs = None if size >= n else _choose_pairs(machine, poses, size)
    state = BranchState()
    last: PathIK | None = None  # the part before's last pose, to linearise a feed move into this part
    before: tuple[Blocks, bool] | None = None  # the part before's last moving block, and whether a rapid
    safe = _safe_settings(machine, poses, options)
    first = 0
    while first < n:
        end = min(n, first + size)
        while True:
            solved = _solve(machine, poses.part(first, end), options, state,
                            None if pairs is None else pairs.part(first, end))
            lap("ik")
            context = int(last is not None and not poses.rapid[first])  # a feed move from the part before
            blocks = _linearise(machine, poses.part(first - context, end), options,
                                last.then(solved) if context else solved).shifted(first - context)
            blocks = blocks.rows(slice(np.searchsorted(blocks.pose, first), None))
            lap("linearise")
            rapid = poses.rapid[blocks.pose].copy()
            rapid[0] |= first == 0  # where the machine stands before the program is unknown: position with G0
            ext, ext_rapid = (blocks, rapid) if before is None else (before[0].then(blocks), np.r_[before[1], rapid])
            # Blocks that move no joint (repeated CL points) take no time and are left out.
            moving = np.flatnonzero(np.r_[True, np.any(np.diff(ext.joints, axis=0) != 0, axis=1)])
            cut = n if end == n else _cut(machine, poses, first, end, solved, ext.rows(moving), ext_rapid[moving])
            if cut is not None:
                break
            end = min(n, first + 2 * (end - first))
        k = int(np.searchsorted(blocks.pose, cut))
        blocks, rapid = blocks.rows(slice(0, k)), rapid[:k]
        blocks = replace(blocks, unresolved=blocks.unresolved[blocks.unresolved < cut])
        path = solved.rows(slice(0, cut - first))
        between = between_cuts(machine, poses, blocks, safe, before=None if before is None else before[0], end=cut)
        blocks = between.blocks
        rapid = _rapid(poses, blocks)
        rapid[0] |= first == 0  # where the machine stands before the program is unknown: position with G0
        checks, others = _checks(machine, poses, options, path.pair_switch, blocks, rapid, first)
        others += _between_violations(poses, between.problems)
        context = 0
        if before is not None:  # the move into this part, from the last block of the part before
            blocks, rapid, context = before[0].then(blocks), np.r_[before[1], rapid], 1
            checks += check_program(machine, blocks.result.rows(slice(0, 2)), rapid[:2],
                                    poses.tool_length[blocks.pose[:2]], poses.line[blocks.pose[:2]], context=1)
        warnings = theta2_rate_warnings(machine, blocks.joints, blocks.tip, rapid, poses.line[blocks.pose],
                                        poses.source)
        lap("checks")
        moving = np.flatnonzero(np.r_[True, np.any(np.diff(blocks.joints, axis=0) != 0, axis=1)])
        blocks, rapid = blocks.rows(moving), rapid[moving]
        duration = block_durations(machine, poses, blocks, rapid)
        plan = plan and not (checks or others)
        planning = None
        if plan:
            planning = planner(TimingTask(
                blocks.joints, blocks.tip, rapid, poses.feed[blocks.pose], poses.inverse_time[blocks.pose],
                poses.sequence[blocks.pose], poses.line[blocks.pose], duration, Limits.from_machine(machine),
                np.radians(machine.timing.rotary_feed) / 60.0, np.radians(machine.timing.corner_angle),
                options.planner, options.optimize, options.workers, figures, _rapid_speed(machine)))
            lap("timing")
        yield Part(first, cut, path, blocks, rapid, duration, planning, context, checks, others, warnings)
        state, last = solved.state_at(cut - first - 1), solved.rows(slice(cut - first - 1, cut - first))
        before = (blocks.rows(slice(-1, None)), bool(rapid[-1]))
        first = cut


def _violations(checks: list[Violation], others: list[Violation], timing: list[Violation],
                placement: Placement | None) -> list[Violation]:
    """The violations of the parts as the whole program's checks give them: one per line and kind
    from the checks, sorted by line, the infeasible placement first, timing last."""
    unique: dict[tuple[int, str], Violation] = {}
    for v in checks:
        unique.setdefault((v.line, v.kind), v)
    violations = sorted([*unique.values(), *others], key=lambda v: (v.line, v.kind))
    if placement is not None and not placement.feasible:
        violations.insert(0, Violation(placement.line, "placement", f"no work offset lets the whole program run: "
                                                                    f"{placement.reason}"))
    return violations + timing


def _cone_warning(machine: Machine, options: PostOptions, source: str) -> str:
    return (f"{source}: the pole cone of the machine file ({machine.pole.cone:g} deg) is wider than the axis "
            f"tolerance ({options.axis_tol:g} deg): near the table normal the tool axis may be off by up to "
            f"{machine.pole.cone:g} deg")


@contextlib.contextmanager
def _spool(output: str | os.PathLike[str] | None) -> Iterator[IO[str]]:
    """A nameless temporary file for the program's blocks until the header is known: beside a
    regular output (on its disk, which needs the room anyway), else in the temporary folder.
    Its write errors are the output's."""
    target = None if output is None else os.path.realpath(output)
    folder = os.path.dirname(target) if target and (os.path.isfile(target) or not os.path.exists(target)) else None
    if folder is not None and not os.access(folder, os.W_OK | os.X_OK):
        folder = None
    try:
        with tempfile.TemporaryFile("w+", encoding="ascii", newline="\n", dir=folder) as handle:
            yield handle
    except OSError as error:
        raise OutputError(f"cannot write: {error.strerror or error}", str(output)) from None


class _Clock:
    """Seconds per stage, summed over the parts; each lap is reported to ``progress``."""

    def __init__(self, progress: Callable[[str], None]) -> None:
        self.seconds: dict[str, float] = {}
        self.progress = progress
        self.clock = time.perf_counter()

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        self.seconds[stage] = self.seconds.get(stage, 0.0) + now - self.clock
        self.clock = now
        self.progress(stage)


def _machine_poses(path: str | Path, machine: Machine, options: PostOptions, clock: _Clock
                   ) -> tuple[MachinePoses, PostOptions, Placement | None]:
    """Stages 1 and 2: the CL file read, the work offset placed, the poses in the table frame."""
    toolpath = read_toolpath(path, units=options.units, chordal_tolerance=options.arc_tol,
                             arc_direction=options.arc_direction, frame=options.frame, feed=options.feed)
    clock.lap("parse")
    placement = None
    if options.work_offset == "auto":
        from .placement import place

        zero = machine_poses(toolpath, machine, work_offset=(0.0, 0.0, 0.0), tool_length=options.tool_length)
        placement = place(machine, zero, options, progress=clock.progress)
        options = replace(options, work_offset=placement.offset)
        clock.lap("placement")
    poses = machine_poses(toolpath, machine, work_offset=_offset(machine, options), tool_length=options.tool_length)
    return poses, options, placement


def postprocess(path: str | Path, machine: Machine, options: PostOptions,
                progress: Callable[[str], None] = lambda stage: None) -> PostResult:
    """Run every stage except writing, on the whole program at once (its arrays are kept: for a
    long program, :func:`post`). Raises InputError for bad input; violations are returned."""
    clock = _Clock(progress)
    poses, options, placement = _machine_poses(path, machine, options, clock)
    feasible = placement is None or placement.feasible
    part = next(_parts(machine, poses, options, len(poses), clock.lap, plan=options.plan and feasible))
    timing = part.timed()
    violations = _violations(part.checks, part.others, list(timing.violations), placement)
    warnings = list(poses.warnings) + part.warnings
    if part.path.in_cone.any() and machine.pole.cone > options.axis_tol:
        warnings.append(_cone_warning(machine, options, poses.source))
    program = None
    if not violations:
        figures = Figures(blocks=len(part.blocks.joints), inserted=int(np.sum(part.blocks.fraction != 1)),
                          time=float(np.sum(timing.duration)))
        program = _frame(machine, poses, options, placement, figures, part.blocks, part.rapid, timing.duration,
                         _at_blocks(_events(poses), part.blocks))
    return PostResult(poses, part.path, part.blocks, part.rapid, timing.duration, violations, warnings, program,
                      timing.schedule, clock.seconds, placement)


@dataclass
class Posted:
    """What :func:`post` did: the violations (then nothing was written), the verification of the
    program (None without), and the report's figures gathered over the parts."""

    poses: MachinePoses
    violations: list[Violation]
    warnings: list[str]
    figures: Figures
    verification: Verification | None
    parts: int
    seconds: dict[str, float] = field(default_factory=dict)
    placement: Placement | None = None

    def report(self, machine: Machine, options: PostOptions) -> dict[str, Any]:
        """Summary statistics and every violation, JSON-ready (mm, degrees, seconds)."""
        return _report(machine, options, self.poses, self.violations, self.warnings, self.figures, self.placement,
                       self.seconds)


def post(path: str | Path, machine: Machine, options: PostOptions, output: str | os.PathLike[str] | None = None,
         *, verify: bool = True, timing_figures: bool = False, part_poses: int = PART_POSES,
         progress: Callable[[str], None] = lambda stage: None,
         before_writing: Callable[[Posted], None] = lambda posted: None) -> Posted:
    """Every stage, a part of the program at a time (see the module docstring), writing the
    G-code to ``output`` (atomically; None: only check).

    The blocks of each part are formatted, verified (with ``verify``: read back from their text
    and checked against the part's CL poses, :class:`~verne_post.verify.Verifier`) and set
    aside in a temporary file; the output is written only when no part has a violation and the
    verification passes, with the header's figures (block count, cycle time, the certified
    deviations) known from all the parts. ``timing_figures``: gather the planner's figures for
    the report (time budget, ratios to the limits), which cost time. After a violation the
    remaining parts are still checked (every violation is reported) but no longer planned.
    ``before_writing`` gets the outcome before the output is written (and may stop it, raising).

    With ``options.workers`` > 1 the planning and the verification run in helper processes
    (:mod:`verne_post.helpers`), a part behind the main process, which solves the next part
    meanwhile: the same program, sooner. The seconds of ``timing`` and ``verify`` are then the
    helpers' (overlapping the others), ``waiting`` the main process's wait for them.
    """
    verify = verify and output is not None
    with contextlib.ExitStack() as helpers:
        planner: Planner = plan_timing
        if available(options.workers) and options.plan:
            planning = Helper()
            helpers.callback(planning.close)
            planner = partial(_plan_in, planning)
        verifying = None
        if available(options.workers) and verify:
            verifying = VerifierProcess(machine)
            helpers.callback(verifying.close)
        clock = _Clock(progress)
        poses, options, placement = _machine_poses(path, machine, options, clock)
        verifier: Verifier | VerifierProcess | None = None
        if verify:
            settings = {"source": str(output), "tol": options.tol, "axis_tol": options.axis_tol,
                        "work_offset": _offset(machine, options), "rapid_tol": options.rapid_tol,
                        "top": feed_top(Reference.of(poses))}
            verifier = Verifier(machine, **settings) if verifying is None else verifying.start(**settings)
        return _post(machine, poses, options, placement, output, clock, planner, verifier, timing_figures, part_poses,
                     before_writing)


def _plan_in(helper: Helper, task: TimingTask) -> Future[Timing]:
    # The helper is one process; with the third-order programme, whose planning outweighs every
    # other stage several times, it shares each part's planning with processes of its own.
    return helper.submit(_plan_for_posting, task if task.optimize else replace(task, workers=1))


def _plan_for_posting(task: TimingTask) -> Timing:
    """:func:`plan_timing` without the schedule, which posting does not use: its curves were most
    of what a helper sent back (35 MB and 0.3 s of pickling on the 105k job)."""
    return replace(plan_timing(task), schedule=None)


def _one_ahead(parts: Iterator[Part]) -> Iterator[Part]:
    """The parts, each handed on once the next has been made (its planning under way)."""
    current = next(parts, None)
    for following in parts:
        yield current  # type: ignore[misc]
        current = following
    if current is not None:
        yield current


def _post(machine: Machine, poses: MachinePoses, options: PostOptions, placement: Placement | None,
          output: str | os.PathLike[str] | None, clock: _Clock, planner: Planner,
          verifier: Verifier | VerifierProcess | None, timing_figures: bool, part_poses: int,
          before_writing: Callable[[Posted], None]) -> Posted:
    """:func:`post` once the poses are known."""
    fmt = gcode_format(machine)
    writer = GcodeWriter(fmt)
    # the header's figures are known at the end: the head is verified with those of an empty program
    head = writer.head(_frame(machine, poses, options, placement, Figures()))
    events, tools = _events(poses), {t.number: (t.length, t.delta) for t in poses.tools}
    figures = Figures()
    checks: list[Violation] = []
    others: list[Violation] = []
    timing: list[Violation] = []
    warnings = list(poses.warnings)
    in_cone = False
    failed = placement is not None and not placement.feasible
    helped = planner is not plan_timing
    # No work offset runs the program: the placement's one-line reason is the answer, as 'place'
    # gives it; checking every part at an offset known to fail took minutes and printed
    # thousands of violations that say the same.
    parts = iter(()) if failed else _parts(machine, poses, options, part_poses, clock.lap, options.plan, planner,
                                          timing_figures)
    k = -1
    with _spool(output) as spool:
        for k, part in enumerate(_one_ahead(parts) if helped else parts):
            timed = part.timed(wanted=not failed)  # a part after a failed one: as if not planned
            if isinstance(part.planning, Future):  # planned in the helper
                clock.seconds["timing"] = clock.seconds.get("timing", 0.0) + timed.seconds
                clock.lap("waiting")
            failed = failed or bool(part.checks or part.others or timed.violations)
            if len(checks) + len(others) < MAX_VIOLATIONS:  # a program wrong everywhere: enough to say so
                checks += part.checks
                others += part.others
            timing += timed.violations
            figures.add(poses, part.path, part.first, part.blocks, part.rapid, timed, part.context)
            warnings += part.warnings
            in_cone = in_cone or bool(part.path.in_cone.any())
            if output is not None and not failed:
                own, last = part.own, part.end == len(poses)
                blocks = part.blocks.rows(own)
                mine = [e for e in events if part.first <= e.index < part.end or (last and e.index >= part.end)]
                positioning = _positioning(len(blocks.pose), part.first == 0)
                text = "".join(writer.body(Program(blocks.joints, positioning, timed.duration[own],
                                                   poses.line[blocks.pose], _at_blocks(mine, blocks),
                                                   tool_lengths=tools, between=part.rapid[own] & ~positioning)))
                spool.write(text)
                clock.lap("write")
                if verifier is not None:
                    reference = Reference.of(poses.part(part.first, part.end))
                    verifier.read((head if k == 0 else "") + text + (writer.tail() if last else ""), reference,
                                  final=last)
                    clock.lap("verify")
            clock.progress(f"pose {part.end} of {len(poses)}")
        if in_cone and machine.pole.cone > options.axis_tol:
            warnings.append(_cone_warning(machine, options, poses.source))
        violations = _violations(checks, others, timing, placement)
        verification = verifier.result() if verifier is not None and not violations else None
        if isinstance(verifier, VerifierProcess) and verification is not None:
            clock.lap("waiting")
            clock.seconds["verify"] = clock.seconds.get("verify", 0.0) + verifier.seconds
        posted = Posted(poses, violations, warnings, figures, verification, k + 1, clock.seconds, placement)
        before_writing(posted)
        if output is not None and not violations and (verification is None or verification.ok):
            head = GcodeWriter(fmt).head(_frame(machine, poses, options, placement, figures))
            if verification is not None:
                head = with_header_line(head, verification.certificate())
            spool.seek(0)
            with atomic_write(output) as handle:
                handle.write(head)
                shutil.copyfileobj(spool, handle, 1 << 20)
                handle.write(writer.tail())
            clock.lap("write")
    return posted


def _offset(machine: Machine, options: PostOptions) -> tuple[float, float, float]:
    """The work offset in force (mm): the option's, else the machine file's."""
    offset = machine.work_offset if options.work_offset is None else options.work_offset
    assert offset != "auto", "postprocess resolves the automatic work offset first"
    return offset


def _events(poses: MachinePoses) -> list[Event]:
    """The program's events, before the pose of their index."""
    events = list(poses.events)
    if poses.tools and poses.tools[0].source == "--tool-length" and poses.tools[0].number == 0:
        # motion before any tool change: the program still says which tool length its joints are for
        events.insert(0, ToolChange(0, poses.tools[0].line, 0, poses.tools[0].length))
    return events


def _at_blocks(events: list[Event], blocks: Blocks) -> tuple[Event, ...]:
    """The events with the index of the block they come before (len(blocks.pose): after the last)."""
    return tuple(replace(e, index=int(np.searchsorted(blocks.pose, e.index, side="left"))) for e in events)


def _frame(machine: Machine, poses: MachinePoses, options: PostOptions, placement: Placement | None,
           figures: Figures, blocks: Blocks | None = None, rapid: np.ndarray | None = None,
           duration: np.ndarray | None = None, events: tuple[Event, ...] = ()) -> Program:
    """The program with its header (block counts and cycle time from ``figures``); its blocks
    (mm, rad, s), if given, and their ``events``."""
    offset = _offset(machine, options)
    header = (
        f"POSTPROCESSOR VERNE-POST {__version__}",
        f"MACHINE {machine.source} ({machine.name})",
        f"SOURCE {Path(poses.source).name}",
        f"CL DIALECT {poses.dialect}",
        *(f"CL READING {note}" for note in poses.notes),
        "AXES X Y Z = SLIDERS RHO1 RHO2 RHO3 MM, A = TILT THETA1 DEG, C = ROTARY THETA2 DEG",
        "WORK OFFSET {:.4f} {:.4f} {:.4f} MM (PART ZERO IN THE TABLE FRAME)".format(*offset),
        *(placement.header() if placement is not None else (
            "WORK OFFSET FROM " + ("THE MACHINE FILE" if options.work_offset is None else "THE USER"),)),
        f"TOLERANCE {options.tol:g} MM {options.axis_tol:g} DEG; RAPIDS {options.rapid_tol:g} MM "
        f"{options.rapid_axis_tol:g} DEG; BLOCKS {figures.blocks} "
        f"(CL POINTS {len(poses)}, INSERTED {figures.inserted})",
        f"CYCLE TIME {figures.time:.1f} S ({_TIME_BASIS[options.plan]})",
    )
    if any(isinstance(e, ToolChange) and e.tool == 0 for e in _events(poses)):
        header += ("TOOL 0: TOOL DATA WITHOUT A TOOL NUMBER IN THE CL FILE; LOAD THE TOOL BY HAND",)
    tools = {t.number: (t.length, t.delta) for t in poses.tools}
    if blocks is None:
        return Program(np.zeros((0, 5)), np.zeros(0, bool), np.zeros(0), np.zeros(0, np.int64),
                       part_name=poses.part_name, header=header, tool_lengths=tools)
    positioning = _positioning(len(blocks.pose), True)
    return Program(joints=blocks.joints, rapid=positioning, duration=duration, line=poses.line[blocks.pose],
                   events=events, part_name=poses.part_name, header=header, tool_lengths=tools,
                   between=None if rapid is None else rapid & ~positioning)


def _positioning(blocks: int, start: bool) -> np.ndarray:
    """Which blocks are G0: the program's first (``start``), the move from wherever the machine
    stands; every other move is planned and certified, between cuts too."""
    positioning = np.zeros(blocks, bool)
    positioning[:1] = start
    return positioning


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
                                  work_offset=offset, tol=options.tol, axis_tol=options.axis_tol,
                                  rapid_tol=options.rapid_tol)
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


__all__ = ["Checked", "Figures", "PostOptions", "PostResult", "Posted", "block_durations", "check_poses", "feed_speed",
           "gcode_format", "post", "postprocess", "write_gcode", "write_output"]
