"""The main job: CL file -> checked, linearised joint-space program (the CLI is a thin layer).

parse CL -> machine poses -> IK and branch choice -> linearisation -> checks -> durations ->
writer. Each stage is its own module; this one wires them and keeps the statistics.

A long program goes through the stages after parsing a *part* at a time (:func:`post`), so
that memory follows the largest part, not the program. A part ends where the machine stops
anyway: at a rapid, or where a feed sequence starts (the planner plans each from rest to rest),
so its timing is the same. What the other stages carry across is handed on explicitly: the
angle pair of each run is chosen over the whole program before the parts are solved (a
pre-pass keeping two angles and a status per pose), the rotary's continuity and the pole
cone's interpolation continue from the part before (:class:`~verne_post.motion.branch.BranchState`),
the feed move into a part is linearised from the part before's last pose, the checks and the
timing of the move into a part start from its last block, and the verification reads on from
where it stood. The program is the same however it is split (tests/test_parts.py). The
report's figures are gathered part by part (:class:`Figures`); the G-code waits in a
temporary file until the header's figures are known. :func:`postprocess` runs the whole
program as one part and keeps its arrays (the HTML report and the timed CSV use them).
"""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import IO, Any, Literal

import numpy as np

from .api import joint_bounds
from .checks.collision import check_collisions, program_bodies, world_of
from .checks.limits import Violation, check_program, theta2_rate_warnings
from .checks.stage import (
    Checked,
    between_violations,
    check_poses,
    linearise_poses,
    program_violations,
    rapid_blocks,
    safe_settings,
    solve_poses,
)
from .cl import read_toolpath
from .cl.toolpath import Event, ToolChange
from .errors import OutputError
from .linuxcnc.blending import blend_tolerance, corner_guards, split_durations, with_guards
from .machine import Machine
from .motion.branch import BranchState, PairAngles, Pairs, PathIK, both_pairs, choose_pairs, in_pole_cone
from .motion.linearise import Blocks
from .motion.poses import MachinePoses, machine_poses
from .motion.safe_motion import between_cuts
from .options import PostOptions, setup_of, work_offset_in_force
from .output.atomic import atomic_write
from .output.gcode import (
    GcodeFormat,
    GcodeWriter,
    Program,
    tool_spindles,
    write_files,
    write_program,
    write_text,
)
from .placement.search import Placement, place
from .planning.controller import MODELLED
from .planning.schedule import Schedule, feed_sequences
from .planning.stage import (
    Planner,
    Timing,
    TimingTask,
    block_durations,
    feed_speed,
    plan_timing,
    rapid_speed_limit,
)
from .planning.timing import Limits
from .processes.helpers import Helper, VerifierProcess, available, outcome
from .report.figures import Figures, report
from .verify.verifier import Reference, Verification, Verifier, feed_box, verify_program
from .version import __version__


@dataclass
class PostResult:
    """What the pipeline produced for the whole program; ``program`` is None when there are violations.
    ``blocks``, ``rapid`` and ``duration`` are the plan's (the schedule's, the timed CSV's); the
    program may hold guard blocks besides (:mod:`verne_post.linuxcnc.blending`)."""

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
        return report(machine, options, self.poses, self.violations, self.warnings, self.figures(machine),
                       self.placement, self.seconds)


#: Violations gathered over the parts at most (the checks of one part report at most 10,000
#: poses of a kind): memory stays bounded when a long program is wrong everywhere.
MAX_VIOLATIONS = 20_000

#: CL poses per part of a program (:func:`post`): a part ends where the machine stops, at a
#: rapid or between feed sequences, at the last such place among this many poses.
PART_POSES = 10_000


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

    def guarded(self, machine: Machine, poses: MachinePoses, options: PostOptions, timed: Timing,
                following: Part | None = None, carried: float = 0.0) -> tuple[Part, Timing, float]:
        """This part and its timing with the guard blocks the controller's blending needs
        (:mod:`verne_post.linuxcnc.blending`; none on other controllers), laid after the timing, and
        the share of the next part's first block to guard at its start. ``following``: the next part
        (its first block decides the guards at this part's last block end); ``carried``: the share
        of this part's first block the part before decided."""
        profile = machine.controller.profile()
        blending = blend_tolerance(profile.program_start, options.tol) if profile.dialect == "linuxcnc" else None
        if blending is None:
            return self, timed, 0.0
        blocks, rapid, m = self.blocks, self.rapid, len(self.rapid)
        if following is not None and len(following.rapid) > following.context:
            ahead = slice(following.context, following.context + 1)
            blocks, rapid = blocks.then(following.blocks.rows(ahead)), np.r_[rapid, following.rapid[ahead]]
        before, after = corner_guards(machine, blocks, rapid, poses.tool_length[blocks.pose], tol=options.tol,
                                      rapid_tol=options.rapid_tol, blend_tolerance=blending)
        after = after[:m + 1] if len(after) > m else np.r_[after, 0.0]
        if self.context and m > 1:
            after[1] = carried
        guarded = with_guards(self.blocks, self.rapid, before[:m], after[:m])
        if len(guarded.owner) == m:
            return self, timed, float(after[m])
        duration = split_durations(machine, guarded, timed.duration, poses.tool_length[guarded.blocks.pose],
                                   profile.block_time)
        return (replace(self, blocks=guarded.blocks, rapid=guarded.rapid), replace(timed, duration=duration),
                float(after[m]))

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
    safe = safe_settings(machine, poses, options)
    world = world_of(machine, poses)
    first = 0
    while first < n:
        end = min(n, first + size)
        while True:
            solved = solve_poses(machine, poses.part(first, end), options, state,
                            None if pairs is None else pairs.part(first, end))
            lap("ik")
            context = int(last is not None and not poses.rapid[first])  # a feed move from the part before
            blocks = linearise_poses(machine, poses.part(first - context, end), options,
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
        between = between_cuts(machine, poses, blocks, safe, before=None if before is None else before[0])
        blocks = between.blocks
        rapid = rapid_blocks(poses, blocks)
        rapid[0] |= first == 0  # where the machine stands before the program is unknown: position with G0
        checks, others = program_violations(machine, poses, options, path.pair_switch, blocks, rapid, first)
        others += between_violations(poses, between.problems)
        context = 0
        if before is not None:  # the move into this part, from the last block of the part before
            blocks, rapid, context = before[0].then(blocks), np.r_[before[1], rapid], 1
            checks += check_program(machine, blocks.result.rows(slice(0, 2)), rapid[:2],
                                    poses.tool_length[blocks.pose[:2]], poses.line[blocks.pose[:2]], context=1)
        warnings = theta2_rate_warnings(machine, blocks.joints, blocks.tip, rapid, poses.line[blocks.pose],
                                        poses.source)
        lap("checks")
        collisions = check_collisions(machine, poses, blocks.joints, blocks.pose, rapid, blocks.tip, world,
                                      alpha=blocks.result.alpha)
        checks += collisions.violations
        warnings += collisions.warnings
        lap("collisions")
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
                options.planner, options.optimize, options.workers, figures, rapid_speed_limit(machine),
                machine.controller.profile().dialect, machine.controller.block_time))
            lap("timing")
        yield Part(first, cut, path, blocks, rapid, duration, planning, context, checks, others, warnings)
        state, last = solved.state_at(cut - first - 1), solved.rows(slice(cut - first - 1, cut - first))
        before = (blocks.rows(slice(-1, None)), bool(rapid[-1]))
        first = cut


def _order(v: Violation) -> tuple[int, bool, str]:
    """By line; on one line a collision after the joints' own faults (where a joint cannot go,
    where its bodies would be is moot)."""
    return v.line, v.kind == "collision", v.kind


def _violations(checks: list[Violation], others: list[Violation], timing: list[Violation],
                placement: Placement | None) -> list[Violation]:
    """The violations of the parts as the whole program's checks give them: one per line and kind
    from the checks, sorted by line, the infeasible placement first, timing last."""
    unique: dict[tuple[int, str], Violation] = {}
    for v in checks:
        unique.setdefault((v.line, v.kind), v)
    violations = sorted([*unique.values(), *others], key=_order)
    if placement is not None and placement.collisions:  # no offset avoids them: they are the reason
        violations = sorted({(v.line, v.message): v for v in [*placement.collisions, *violations]}.values(),
                            key=_order)
    elif placement is not None and not placement.feasible:
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
    setup = setup_of(machine, options, toolpath.units)
    if options.work_offset == "auto":
        zero = machine_poses(toolpath, machine, work_offset=(0.0, 0.0, 0.0), tool_length=options.tool_length,
                             setup=setup)
        placement = place(machine, zero, options, progress=clock.progress, room=options.placement_room)
        options = replace(options, work_offset=placement.offset)
        clock.lap("placement")
    poses = machine_poses(toolpath, machine, work_offset=work_offset_in_force(machine, options),
                          tool_length=options.tool_length, setup=setup)
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
    # the result keeps the plan's blocks (its schedule's, the timed CSV's); the program, the controller's
    written, written_timing, _ = part.guarded(machine, poses, options, timing)
    violations = _violations(part.checks, part.others, list(timing.violations), placement)
    warnings = [*machine.warnings, *poses.warnings, *part.warnings]
    if part.path.in_cone.any() and machine.pole.cone > options.axis_tol:
        warnings.append(_cone_warning(machine, options, poses.source))
    program = None
    if not violations:
        figures = Figures(blocks=len(written.blocks.joints), inserted=int(np.sum(written.blocks.fraction != 1)),
                          time=float(np.sum(written_timing.duration)))
        program = _frame(machine, poses, options, placement, figures, written.blocks, written.rapid,
                         written_timing.duration, _at_blocks(_events(poses), written.blocks))
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
    files: tuple[Path, ...] = ()  # the program's files, split by tool (controller.split: tool)

    def report(self, machine: Machine, options: PostOptions) -> dict[str, Any]:
        """Summary statistics and every violation, JSON-ready (mm, degrees, seconds)."""
        return report(machine, options, self.poses, self.violations, self.warnings, self.figures, self.placement,
                       self.seconds)


def post(path: str | Path, machine: Machine, options: PostOptions, output: str | os.PathLike[str] | None = None,
         *, verify: bool = True, timing_figures: bool = False, part_poses: int = PART_POSES,
         progress: Callable[[str], None] = lambda stage: None,
         before_writing: Callable[[Posted], None] = lambda posted: None) -> Posted:
    """Every stage, a part of the program at a time (see the module docstring), writing the
    G-code to ``output`` (atomically; None: only check).

    The blocks of each part are formatted, verified (with ``verify``: read back from their text
    and checked against the part's CL poses, :class:`~verne_post.verify.verifier.Verifier`) and set
    aside in a temporary file; the output is written only when no part has a violation and the
    verification passes, with the header's figures (block count, cycle time, the certified
    deviations) known from all the parts. ``timing_figures``: gather the planner's figures for
    the report (time budget, ratios to the limits), which cost time. After a violation the
    remaining parts are still checked (every violation is reported) but no longer planned.
    ``before_writing`` gets the outcome before the output is written (and may stop it, raising).

    With ``options.workers`` > 1 the planning and the verification run in helper processes
    (:mod:`verne_post.processes.helpers`), a part behind the main process, which solves the next part
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
            offset = work_offset_in_force(machine, options)
            settings = {"source": str(output), "tol": options.tol, "axis_tol": options.axis_tol,
                        "work_offset": offset, "rapid_tol": options.rapid_tol,
                        "box": feed_box(Reference.of(poses)), "bodies": program_bodies(poses, offset)}
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


def _with_next(parts: Iterator[Part]) -> Iterator[tuple[Part, Part | None]]:
    """Each part with the next (None after the last), handed on once the next has been made (its
    planning under way in a helper; its first block decides the guards at the part's end)."""
    current = next(parts, None)
    for following in parts:
        yield current, following  # type: ignore[misc]
        current = following
    if current is not None:
        yield current, None


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
    spindles = tool_spindles(events)
    figures = Figures()
    checks: list[Violation] = []
    others: list[Violation] = []
    timing: list[Violation] = []
    warnings = [*machine.warnings, *poses.warnings]
    in_cone = False
    failed = placement is not None and not placement.feasible
    # No work offset runs the program: the placement's one-line reason is the answer, as 'place'
    # gives it; checking every part at an offset known to fail took minutes and printed
    # thousands of violations that say the same.
    parts = iter(()) if failed else _parts(machine, poses, options, part_poses, clock.lap, options.plan, planner,
                                          timing_figures)
    k = -1
    with _spool(output) as spool:
        carried = 0.0
        for k, (part, following) in enumerate(_with_next(parts)):
            # a part after a failed one: as if not planned
            part, timed, carried = part.guarded(machine, poses, options, part.timed(wanted=not failed), following,
                                                carried)
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
                                                   tool_lengths=tools, between=part.rapid[own] & ~positioning,
                                                   tool_spindle=spindles)))
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
            head = GcodeWriter(fmt).head(_certified(_frame(machine, poses, options, placement, figures), verification))
            spool.seek(0)
            if fmt.controller.split == "tool":
                posted = replace(posted, files=tuple(write_files(head, spool, writer.tail(), writer.files, output)))
            else:
                with atomic_write(output) as handle:
                    handle.write(head)
                    shutil.copyfileobj(spool, handle, 1 << 20)
                    handle.write(writer.tail())
            clock.lap("write")
    return posted


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
    offset = work_offset_in_force(machine, options)
    header = (
        f"POSTPROCESSOR VERNE-POST {__version__}",
        f"MACHINE {machine.source} ({machine.name})",
        f"SOURCE {Path(poses.source).name}",
        f"CL DIALECT {poses.dialect}",
        *(f"CL READING {note}" for note in poses.notes),
        "AXES {} {} {} = SLIDERS RHO1 RHO2 RHO3 MM, {} = TILT THETA1 DEG, {} = ROTARY THETA2 DEG".format(
            *machine.controller.profile().axes),
        "WORK OFFSET {:.4f} {:.4f} {:.4f} MM (PART ZERO IN THE TABLE FRAME)".format(*offset),
        *(placement.header() if placement is not None else (
            "WORK OFFSET FROM " + ("THE MACHINE FILE" if options.work_offset is None else "THE USER"),)),
        f"TOLERANCE {options.tol:g} MM {options.axis_tol:g} DEG; RAPIDS {options.rapid_tol:g} MM "
        f"{options.rapid_axis_tol:g} DEG; BLOCKS {figures.blocks} "
        f"(CL POINTS {len(poses)}, INSERTED {figures.inserted})",
        f"CYCLE TIME {figures.time:.1f} S ({_TIME_BASIS[options.plan]}"
        + ("; LINUXCNC 2.9 FLOOR ON BLOCKS THAT TURN A OR C" if options.plan
           and machine.controller.profile().dialect in MODELLED else "") + ")",
        _controller_model(machine, options),
    )
    if any(isinstance(e, ToolChange) and e.tool == 0 for e in _events(poses)):
        header += ("TOOL 0: TOOL DATA WITHOUT A TOOL NUMBER IN THE CL FILE; LOAD THE TOOL BY HAND",)
    tools = {t.number: (t.length, t.delta) for t in poses.tools}
    if blocks is None:
        return Program(np.zeros((0, 5)), np.zeros(0, bool), np.zeros(0), np.zeros(0, np.int64),
                       part_name=poses.part_name, header=header, tool_lengths=tools, name=_name(poses),
                       tolerance=options.tol)
    positioning = _positioning(len(blocks.pose), True)
    return Program(joints=blocks.joints, rapid=positioning, duration=duration, line=poses.line[blocks.pose],
                   events=events, part_name=poses.part_name, header=header, tool_lengths=tools, name=_name(poses),
                   between=None if rapid is None else rapid & ~positioning)


def _controller_model(machine: Machine, options: PostOptions) -> str:
    """The header line that says how the controller is taken to run the program: what the
    certificate and the cycle time assume (docs/linuxcnc.md, docs/controllers.md)."""
    profile = machine.controller.profile()
    model = "CONTROLLER MODEL: EACH BLOCK ON ITS STRAIGHT JOINT-SPACE LINE"
    if profile.block_time > 0:
        model += f", AT LEAST {1000 * profile.block_time:g} MS A BLOCK"
    if profile.dialect != "linuxcnc":
        return f"{model}; {profile.dialect.upper()} BLENDING NOT MODELLED" + (
            "" if profile.block_time > 0 else ", NOR ITS BLOCK RATE")
    blending = blend_tolerance(profile.program_start, options.tol)
    if blending is None:
        return f"{model}; LINUXCNC 2.9 EXACT PATH (G61)"
    return (f"{model}; LINUXCNC 2.9 BLENDS (G64 P{blending:.4f}) KEPT WITHIN THE TOLERANCE BY GUARD BLOCKS AT "
            "ROTARY CORNERS")


def _name(poses: MachinePoses) -> str:
    """``{name}`` of the controller's lines: the CL file's part name, else its file name without extension."""
    return poses.part_name or Path(poses.source).stem


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
    the forward kinematics (:mod:`verne_post.verify.verifier`); only a program that passes is written,
    with the certified figures as a header line. Returns the verification (None without).
    """
    fmt = gcode_format(machine)
    if not verify and fmt.controller.split is None:
        write_program(result.program, fmt, path)
        return None
    writer = GcodeWriter(fmt)
    head = writer.head(result.program)
    body = "".join(writer.body(result.program))
    tail = writer.tail()
    verification = None
    if verify:
        offset = result.placement.offset if result.placement is not None else work_offset_in_force(machine, options)
        verification = verify_program(head + body + tail, machine, source=str(path),
                                      against=Reference.of(result.poses), work_offset=offset, tol=options.tol,
                                      axis_tol=options.axis_tol, rapid_tol=options.rapid_tol,
                                      bodies=program_bodies(result.poses, offset))
        if not verification.ok:
            return verification
        head = GcodeWriter(fmt).head(_certified(result.program, verification))
    if fmt.controller.split == "tool":
        write_files(head, io.StringIO(body), tail, writer.files, path)
    else:
        write_text(head + body + tail, path)
    return verification


def _certified(program: Program, verification: Verification | None) -> Program:
    """``program`` with the verification's certificate as the last line of its header."""
    return program if verification is None else replace(program, header=(*program.header, verification.certificate()))


def write_output(result: PostResult, machine: Machine, options: PostOptions, path: str | os.PathLike[str],
                 output_format: Literal["gcode", "csv"] = "gcode", period: float = 0.001, verify: bool = True,
                 decimals: int | None = None) -> Verification | None:
    """Write the program of ``result`` to ``path`` (atomically): G-code as :func:`write_gcode` does,
    or the timed joint trajectory as CSV, a row every ``period`` s (0: one per block end), t and
    positions with ``decimals`` (default: enough for third differences at the period)."""
    if output_format == "gcode":
        return write_gcode(result, machine, options, path, verify=verify)
    from .output.trajectory import write_timed_csv

    blocks = result.blocks
    write_timed_csv(path, machine, result.schedule, result.poses.tool_length[blocks.pose],
                    result.poses.line[blocks.pose], period, decimals)
    return None


def gcode_format(machine: Machine) -> GcodeFormat:
    """The number formats and the controller profile of ``machine``'s programs."""
    g, controller = machine.gcode, machine.controller.profile()
    cap = controller.max_feed_decimals
    feed_decimals = g.feed_decimals if cap is None else min(g.feed_decimals, cap)
    return GcodeFormat(g.linear_decimals, g.angular_decimals, feed_decimals, controller)


__all__ = ["Checked", "Figures", "PostOptions", "PostResult", "Posted", "block_durations", "check_poses", "feed_speed",
           "gcode_format", "post", "postprocess", "write_gcode", "write_output"]
