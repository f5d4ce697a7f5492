"""Stage 5: when every block happens. Feed sequences with toppra, rapids with ruckig.

A feed sequence is a run of feed blocks between rapids, tool changes, feed-mode changes and
corners sharper than ``timing.corner_angle`` (in joint space weighted by the velocity limits);
each is planned from rest to rest with the programmed feed as the tool-tip speed limit, the
joint velocity, acceleration and jerk limits (``verne_post.timing.plan_feed``). Each rapid is a
jerk-limited, phase-synchronised ruckig move from rest to rest. Units: s, mm, rad.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .timing import FeedPlan, Limits, PlanningError, RapidPlan, plan_feed, plan_rapid


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


def feed_sequences(joints: np.ndarray, rapid: np.ndarray, group: np.ndarray, limits: Limits, corner: float
                   ) -> list[tuple[int, int]]:
    """(first, last) block ranges of feed sequences; ``group`` ids (tool, feed mode) split them too."""
    weighted = np.diff(joints, axis=0) / limits.velocity
    unit = weighted / np.maximum(np.linalg.norm(weighted, axis=1, keepdims=True), 1e-300)
    turn = np.r_[0.0, 0.0, np.arccos(np.clip(np.sum(unit[1:] * unit[:-1], axis=1), -1.0, 1.0))]  # at block m
    feed = np.r_[False, ~rapid[1:]]
    starts = feed & ~np.r_[False, feed[:-1]]
    starts[1:] |= feed[1:] & (group[1:] != group[:-1])
    starts |= feed & (turn > corner)
    rows = np.flatnonzero(feed)
    ids = np.cumsum(starts)[rows]
    first = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    last = np.r_[first[1:], len(rows)] - 1
    return [(int(rows[a]), int(rows[b])) for a, b in zip(first, last, strict=True)]


def plan_program(joints: np.ndarray, tip: np.ndarray, rapid: np.ndarray, feed: np.ndarray, group: np.ndarray,
                 limits: Limits, *, rotary_feed: float, corner: float) -> Schedule:
    """Durations of M blocks: joints (M, 5) mm/rad, tip (M, 3) mm relative to the part, feed
    (M,) mm/s (maximum tip speed of the motion into each block), rotary_feed rad/s, corner rad.

    Raises :class:`SequenceError` naming the block where a sequence cannot be planned.
    """
    duration = np.zeros(len(joints))
    planned: list[tuple[int, int, bool, FeedPlan | RapidPlan]] = []
    for first, last in feed_sequences(joints, rapid, group, limits, corner):
        rows = np.arange(first - 1, last + 1)
        try:
            plan = plan_feed(joints[rows], tip[rows], feed[first:last + 1], limits, angular_feed=rotary_feed,
                             max_turn=corner + 1e-9)
        except PlanningError as error:
            block = first if error.index is None else first - 1 + int(error.index)
            raise SequenceError(error.reason, block) from None
        duration[first:last + 1] = plan.durations
        planned.append((first, last, False, plan))
    for m in np.flatnonzero(rapid[1:]) + 1:
        plan = plan_rapid(joints[m - 1], joints[m], limits)
        duration[m] = plan.duration
        planned.append((int(m), int(m), True, plan))
    planned.sort(key=lambda p: p[0])
    start = np.r_[0.0, np.cumsum(duration)]
    return Schedule(duration, tuple(Segment(a, b, r, p, float(start[a])) for a, b, r, p in planned))
