"""Stage 5: when every block happens. Feed sequences with toppra, rapids with ruckig.

A feed sequence is a run of feed blocks between rapids, tool changes, feed-mode changes and
corners sharper than ``timing.corner_angle`` (in joint space weighted by the velocity limits);
each is planned from rest to rest with the programmed feed as the tool-tip speed limit, the
joint velocity, acceleration and jerk limits (``verne_post.planning.feed_planner.plan_feeds``, all the
sequences at once). A move between cuts (:mod:`verne_post.motion.safe_motion`: a rapid kept on its
line, a retract, reorientation or approach) is split the same way into rapid sequences, planned
alike at the joint limits with only the optional rapid tip-speed cap (and no rotary feed on
turns with the tip still); a rapid sequence of one block is a jerk-limited, phase-synchronised
ruckig move from rest to rest. Units: s, mm, rad.
"""

from __future__ import annotations

import itertools
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

from .feed_planner import LP_MIN_BLOCKS, FeedPlan, plan_feeds
from .timing import Limits, PlanningError, RapidPlan, block_min_time, plan_rapid
from .topp import Engine


@dataclass(frozen=True)
class Segment:
    """One planned motion: blocks ``first..last`` (the motions into those block ends)."""

    first: int
    last: int
    rapid: bool
    plan: FeedPlan | RapidPlan
    start: float  # s from program start


@dataclass(frozen=True)
class Schedule:
    duration: np.ndarray  # (M,) s per block (block 0 is the unplanned positioning move: 0)
    segments: tuple[Segment, ...]

    @property
    def total(self) -> float:
        return float(np.sum(self.duration))


class SequenceError(Exception):
    """A feed sequence that could not be planned; ``block`` is where."""

    def __init__(self, message: str, block: int) -> None:
        super().__init__(message)
        self.block = block


#: Planning work, in blocks: a sequence counts as 32 more (its grid has about 32 intervals more
#: than it has blocks: measured, 15 us per block and 500 us per short sequence), a one-block
#: sequence as 10 in all (planned in closed form: 170 us). A helper process costs as much as
#: 10,000 (it starts later, by a fork, and sends its plans back: ~0.2 s), so this process plans
#: that much more than each helper, and work below two helpers' cost is planned here alone.
_SEQUENCE_WORK, _ONE_BLOCK_WORK, _PROCESS_WORK = 32, 10, 10_000
_LP_WORK = 30


def _split(items: list, work: np.ndarray, parts: int) -> list[list]:
    """``items`` in at most ``parts`` contiguous, non-empty runs: the first of ``_PROCESS_WORK``
    more ``work`` than each of the others."""
    if parts <= 1 or not items:
        return [items]
    done = np.cumsum(work)
    share = (done[-1] - _PROCESS_WORK) / parts
    # each cut after the item whose middle is nearest its target: off by at most half an item
    cuts = np.searchsorted(done - 0.5 * work, _PROCESS_WORK + share * np.arange(1, parts))
    bounds = np.unique(np.r_[0, cuts, len(items)])
    return [items[a:b] for a, b in itertools.pairwise(bounds)]


def feed_sequences(joints: np.ndarray, rapid: np.ndarray, group: np.ndarray, limits: Limits, corner: float,
                   of_rapids: bool = False) -> list[tuple[int, int]]:
    """(first, last) block ranges of feed sequences (``of_rapids``: of rapid sequences, block 0,
    the positioning move from where the machine stands, left out); ``group`` ids (tool, feed
    mode) split them too."""
    weighted = np.diff(joints, axis=0) / limits.velocity
    unit = weighted / np.maximum(np.linalg.norm(weighted, axis=1, keepdims=True), 1e-300)
    turn = np.zeros(len(joints))  # angle between the motion into block m and into block m - 1
    turn[2:] = np.arccos(np.clip(np.sum(unit[1:] * unit[:-1], axis=1), -1.0, 1.0))
    feed = np.r_[False, rapid[1:] if of_rapids else ~rapid[1:]]
    starts = feed & ~np.r_[False, feed[:-1]]
    starts[1:] |= feed[1:] & (group[1:] != group[:-1])
    starts |= feed & (turn > corner)
    rows = np.flatnonzero(feed)
    if rows.size == 0:
        return []
    ids = np.cumsum(starts)[rows]
    first = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    last = np.r_[first[1:], len(rows)] - 1
    return [(int(rows[a]), int(rows[b])) for a, b in zip(first, last, strict=True)]


def _plan_sequences(task: tuple[list[tuple[np.ndarray, np.ndarray, np.ndarray]], Limits, float, float, bool, Engine,
                                bool]) -> list[FeedPlan | tuple[str, int | None]]:
    """plan_feeds for some sequences; a PlanningError comes back as (reason, waypoint) to cross processes."""
    sequences, limits, rotary_feed, corner, jerk, engine, optimize = task
    plans = plan_feeds(sequences, limits, angular_feed=rotary_feed, max_turn=corner + 1e-9, jerk=jerk, engine=engine,
                       optimize=optimize)
    return [(p.reason, p.index) if isinstance(p, PlanningError) else p for p in plans]


#: rad/s: the rotary speed limit of rapid sequences' turns on the spot: only the joint limits.
RAPID_ANGULAR_FEED = 1e9
#: mm/s: a rapid's tip speed cap at or above this is no cap (the pipeline's NO_TIP_LIMIT is 1e9).
UNCAPPED = 1e8


def plan_program(joints: np.ndarray, tip: np.ndarray, rapid: np.ndarray, feed: np.ndarray, group: np.ndarray,
                 limits: Limits, *, rotary_feed: float, corner: float, workers: int = 1, jerk: bool = True,
                 engine: Engine = "copp", optimize: bool = False) -> Schedule:
    """Durations of M blocks: joints (M, 5) mm/rad, tip (M, 3) mm relative to the part, feed
    (M,) mm/s (maximum tip speed of the motion into each block; on rapids their cap),
    rotary_feed rad/s, corner rad.

    Feed sequences are independent problems: with ``workers`` > 1 they are planned in that many
    processes (same results). ``jerk=False`` leaves out the jerk limits of feed moves (for
    comparisons; rapids are always jerk-limited). ``engine`` is the TOPP2 engine (see
    :mod:`verne_post.planning.topp`); ``optimize`` adds the third-order programme on long sequences
    (:func:`~verne_post.planning.feed_planner.plan_feeds`). Raises :class:`SequenceError` naming the
    block where a sequence cannot be planned.
    """
    duration = np.zeros(len(joints))
    ranges = feed_sequences(joints, rapid, group, limits, corner)
    sequences = [(joints[a - 1:b + 1], tip[a - 1:b + 1], feed[a:b + 1]) for a, b in ranges]
    # Split by work, not by count: a row of 400 blocks and a one-block plunge are both a sequence.
    work = np.array([_ONE_BLOCK_WORK if a == b else b - a + 1 + _SEQUENCE_WORK for a, b in ranges])
    if optimize:  # the third-order programme costs a long sequence about 30 times its filtered plan
        work = np.where(work > LP_MIN_BLOCKS + _SEQUENCE_WORK, _LP_WORK * work, work)
    parts = max(1, min(workers, int(work.sum()) // (2 * _PROCESS_WORK)))
    tasks = [(chunk, limits, rotary_feed, corner, jerk, engine, optimize) for chunk in _split(sequences, work, parts)]
    if len(tasks) > 1:  # this process plans the first share while the others are planned beside it
        context = multiprocessing.get_context("fork")
        with ProcessPoolExecutor(max_workers=len(tasks) - 1, mp_context=context) as pool:
            others = pool.map(_plan_sequences, tasks[1:])
            plans = [plan for chunk in (_plan_sequences(tasks[0]), *others) for plan in chunk]
    else:
        plans = [plan for task in tasks for plan in _plan_sequences(task)]
    planned: list[tuple[int, int, bool, FeedPlan | RapidPlan]] = []
    for (first, last), plan in zip(ranges, plans, strict=True):
        if not isinstance(plan, FeedPlan):
            reason, index = plan
            raise SequenceError(reason, first if index is None else first - 1 + int(index))
        duration[first:last + 1] = plan.durations
        planned.append((first, last, False, plan))
    rapid_ranges = feed_sequences(joints, rapid, group, limits, corner, of_rapids=True)
    # ruckig's phase-synchronised move knows no tip speed: a capped one-block rapid is planned as a feed is
    single = [a for a, b in rapid_ranges if b == a and feed[a] >= UNCAPPED]
    runs = [(a, b) for a, b in rapid_ranges if not (b == a and feed[a] >= UNCAPPED)]
    rapid_plans = plan_feeds([(joints[a - 1:b + 1], tip[a - 1:b + 1], feed[a:b + 1]) for a, b in runs], limits,
                             angular_feed=RAPID_ANGULAR_FEED, max_turn=corner + 1e-9, jerk=True, engine=engine)
    for (first, last), plan in zip(runs, rapid_plans, strict=True):
        if not isinstance(plan, FeedPlan):
            raise SequenceError(plan.reason, first if plan.index is None else first - 1 + int(plan.index))
        duration[first:last + 1] = plan.durations
        planned.append((first, last, True, plan))
    for m in single:
        plan = plan_rapid(joints[m - 1], joints[m], limits)
        duration[m] = plan.duration
        planned.append((int(m), int(m), True, plan))
    planned.sort(key=lambda p: p[0])
    start = np.r_[0.0, np.cumsum(duration)]
    return Schedule(duration, tuple(Segment(a, b, r, p, float(start[a])) for a, b, r, p in planned))


#: Samples per rapid in limit_ratios, at most.
_RAPID_SAMPLES = 20_000


def limit_ratios(schedule: Schedule, limits: Limits, period: float = 0.002) -> np.ndarray:
    """Largest |velocity|, |acceleration|, |jerk| over their limits, (3, 5) per joint.

    Feed moves: the figures the planner certified (its verification of each exact time law at
    every piece and on both sides of every waypoint). Rapids: sampled every ``period`` s (at
    most 20,000 times), the jerk by differences of the acceleration.
    """
    worst = np.zeros((3, 5))
    for segment in schedule.segments:
        plan = segment.plan
        if isinstance(plan, FeedPlan):
            worst = np.maximum(worst, plan.peak_ratios)
            continue
        t = np.linspace(0.0, plan.total, int(np.clip(np.ceil(plan.total / period) + 1, 2, _RAPID_SAMPLES)))
        _, qd, qdd = plan.sample(t)
        jerk = np.diff(qdd, axis=0) / max(t[1] - t[0], 1e-12)
        for k, (values, limit) in enumerate(zip((qd, qdd, jerk), (limits.velocity, limits.acceleration, limits.jerk),
                                                strict=True)):
            if len(values):
                worst[k] = np.maximum(worst[k], np.max(np.abs(values), axis=0) / limit)
    return worst


def time_budget(schedule: Schedule, joints: np.ndarray, tip: np.ndarray, feed: np.ndarray, limits: Limits,
                rotary_feed: float) -> dict[str, float]:
    """Feed time split into: at the programmed feed, lost to joint velocity limits (the bound
    of ``timing.lower_bound_time`` over the feed alone), lost to acceleration and jerk (s)."""
    moves = [s for s in schedule.segments if not s.rapid]
    rows = np.concatenate([np.arange(s.first, s.last + 1) for s in moves]) if moves else np.zeros(0, int)
    huge = Limits(limits.velocity * 1e9, limits.acceleration, limits.jerk)
    dq, dtip = joints[rows] - joints[rows - 1], tip[rows] - tip[rows - 1]
    at_feed, lower = (float(np.sum(block_min_time(dq, dtip, feed[rows], lim, angular_feed=rotary_feed)))
                      for lim in (huge, limits))
    planned = float(sum(s.plan.total for s in moves))
    return {"feed_time_s": planned, "at_programmed_feed_s": at_feed, "lost_to_joint_velocity_s": lower - at_feed,
            "lost_to_acceleration_and_jerk_s": planned - lower}
