"""The timing stage (stage 6) of a part of the program, as the pipeline runs it: the durations
from the programmed feeds, the planning of the feed sequences and rapids (:func:`plan_timing`,
here or in a helper process) and its result (:class:`Timing`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass, replace

import numpy as np

from ..api import forward_kinematics
from ..checks.limits import Violation
from ..machine import Machine
from ..motion.linearise import Blocks
from ..motion.poses import MachinePoses
from .controller import MODELLED, rotary_block_floor
from .schedule import Schedule, SequenceError, limit_ratios, plan_program, time_budget
from .timing import Limits
from .topp import Engine


def tip_path_length(machine: Machine, poses: MachinePoses, blocks: Blocks, rows: np.ndarray) -> np.ndarray:
    """mm: the length of the tool tip's path relative to the part (table frame) along the
    joint-space line of each block ``rows`` (from the block before), as the controller runs it.

    That path is not the chord of the block's ends: linear joints bend the tip off it (within the
    tolerance), and the bend adds length, most on short blocks: near the rotary pole a 0.015 mm
    block whose middle is 1.4 um off its chord is 2.3 % longer than it. To leading order the bend
    is a parabola along the block (the forward kinematics' second-order term), for which the two
    chords through the middle miss a quarter of the added length: ``(4 L2 - L1) / 3`` (Richardson,
    as Simpson's rule) has no error of that order. One forward kinematics per block, at its middle.
    """
    rows = np.asarray(rows, dtype=int)
    lengths = np.zeros(len(rows))
    rows_after = rows[rows > 0]
    if rows_after.size == 0:
        return lengths
    before, result = rows_after - 1, blocks.result
    middle = forward_kinematics(machine, 0.5 * (result.joints[before] + result.joints[rows_after]),
                                tool_length=poses.tool_length[blocks.pose[rows_after]],
                                alpha_guess=0.5 * (result.alpha[before] + result.alpha[rows_after]))
    t0, t1 = blocks.tip[before], blocks.tip[rows_after]
    chord = np.linalg.norm(t1 - t0, axis=1)
    halves = np.linalg.norm(middle.tip - t0, axis=1) + np.linalg.norm(t1 - middle.tip, axis=1)
    lengths[rows > 0] = np.where(middle.reachable, halves + (halves - chord) / 3.0, chord)
    return lengths


def block_durations(machine: Machine, poses: MachinePoses, blocks: Blocks, rapid: np.ndarray) -> np.ndarray:
    """Seconds per block before time-parametrisation: programmed feed, never faster than a joint.

    Feed blocks take the length of their tip path (:func:`tip_path_length`, not the chord of
    their ends) over the programmed feed (inverse-time moves their share of 1/F), and at least the
    time the slowest joint needs at its velocity limit; so a rotary-only block is never of zero
    duration. Rapids: the joint-limit time.
    """
    step = np.abs(np.diff(blocks.joints, axis=0, prepend=blocks.joints[:1]))
    joint_time = np.max(step / Limits.from_machine(machine).velocity, axis=1)
    per_minute = np.flatnonzero(~rapid & ~poses.inverse_time[blocks.pose])
    length = np.zeros(len(rapid))
    length[per_minute] = tip_path_length(machine, poses, blocks, per_minute)
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
    return tip_limit(poses.feed[blocks.pose], poses.inverse_time[blocks.pose], blocks.tip, duration)


def tip_limit(feed: np.ndarray, inverse_time: np.ndarray, tip: np.ndarray, duration: np.ndarray) -> np.ndarray:
    """:func:`feed_speed` of blocks with programmed ``feed`` (mm/min, or 1/min where
    ``inverse_time``), tips (mm) and durations (s)."""
    length = np.linalg.norm(np.diff(tip, axis=0, prepend=tip[:1]), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = np.where((duration > 0) & (length > 0), length / duration, NO_TIP_LIMIT)
    return np.where(inverse_time, inverse, feed / 60.0)


def rapid_speed_limit(machine: Machine) -> float:
    """mm/s: the tip speed limit of rapids (the machine file's ``safe.rapid_feed``, else none)."""
    return NO_TIP_LIMIT if machine.safe.rapid_feed is None else machine.safe.rapid_feed / 60.0


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
    controller: str | None = None  # a dialect whose planner's floor the durations keep (planning.controller)
    block_time: float = 0.0  # s: the controller's least time per block (its block processing time)


def plan_timing(task: TimingTask) -> Timing:
    """Stage 6 of a part (feed sequences and rapids, :func:`~verne_post.planning.schedule.plan_program`)."""
    start = time.perf_counter()
    try:
        speed = np.where(task.rapid, task.rapid_speed, tip_limit(task.feed, task.inverse_time, task.tip,
                                                                  task.unplanned))
        schedule = plan_program(task.joints, task.tip, task.rapid, speed, task.group,
                                task.limits, rotary_feed=task.rotary_feed, corner=task.corner, workers=task.workers,
                                engine=task.engine, optimize=task.optimize)
    except SequenceError as error:
        violation = Violation(int(task.line[error.block]), "timing", f"cannot plan the feed motion: {error}")
        return Timing(task.unplanned, violations=(violation,), seconds=time.perf_counter() - start)
    duration = schedule.duration
    if task.controller in MODELLED:  # the controller's own planner cannot run a block faster
        duration = np.maximum(duration, rotary_block_floor(task.joints, task.limits))
    if task.block_time > 0:  # nor can it read blocks faster (the first, positioning, block is not timed)
        duration = np.r_[duration[:1], np.maximum(duration[1:], task.block_time)]
    timed = Timing(duration, schedule, planned=True)
    if task.figures:  # of the planned durations, as the HTML report's
        timed = timed.with_figures(task.joints, task.tip, tip_limit(task.feed, task.inverse_time, task.tip,
                                                                    duration),
                                   task.limits, task.rotary_feed)
    return replace(timed, seconds=time.perf_counter() - start)


#: Plans a part's timing: here (:func:`plan_timing`), or in a helper process (a future of it).
Planner = Callable[[TimingTask], "Timing | Future[Timing]"]
