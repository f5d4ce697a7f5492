"""The sequences of one planning call, their geometry and caps (:class:`Batch`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..timing import DOF, TIP_EPS, Limits, PlanningError, checked_sequence
from .plan import Cubics
from .segments import Pieces, not_a_knot, ranges, segment_cumsum

_JERK_CAP_MARGIN = 0.7  # share of the jerk limits for the centripetal-jerk velocity cap


# --------------------------------------------------------------------------------------------
# The sequences' geometry and caps
# --------------------------------------------------------------------------------------------


def concatenate(sequences: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]]
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Checked (:func:`timing.checked_sequence`), concatenated (joints, tip, feed) and the
    waypoint offsets (R + 1,)."""
    checked = []
    for r, sequence in enumerate(sequences):
        try:
            checked.append(checked_sequence(*sequence))
        except ValueError as error:
            raise ValueError(f"{error} (sequence {r})" if len(sequences) > 1 else str(error)) from None
    joints, tips, feeds = zip(*checked, strict=True)
    first = np.r_[0, np.cumsum([len(q) for q in joints])]
    return np.concatenate(joints), np.concatenate(tips), np.concatenate(feeds), first


def select(joints: np.ndarray, tip: np.ndarray, feed: np.ndarray, first: np.ndarray, which: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The sequences ``which`` of concatenated (joints, tip, feed) with waypoint offsets ``first``."""
    rows = ranges(first[which], first[which + 1])
    blocks = ranges(first[which] - which, first[which + 1] - which - 1)
    return joints[rows], tip[rows], feed[blocks], np.r_[0, np.cumsum(np.diff(first)[which])]


def refusals(joints: np.ndarray, first: np.ndarray, limits: Limits, max_turn: float) -> dict[int, PlanningError]:
    """Sequences that cannot be planned at all: a block without joint motion, a sharp corner."""
    bfirst = first - np.arange(len(first))
    bseq = np.repeat(np.arange(len(first) - 1), np.diff(bfirst))
    left = np.arange(len(bseq)) + bseq
    step = (joints[left + 1] - joints[left]) / limits.velocity
    weighted = np.linalg.norm(step, axis=1)
    total = np.add.reduceat(weighted, bfirst[:-1])
    errors: dict[int, PlanningError] = {}
    for b in np.flatnonzero(weighted <= 1e-12 * np.maximum(total[bseq], 1e-300)):
        r, k = int(bseq[b]), int(b - bfirst[bseq[b]])
        errors.setdefault(r, PlanningError(f"feed block {k} (waypoints {k} to {k + 1}) has no joint motion: drop "
                                           f"repeated waypoints", k))
    direction = step / np.maximum(weighted, 1e-300)[:, None]
    turn = np.arccos(np.clip(np.sum(direction[:-1] * direction[1:], axis=1), -1.0, 1.0))
    for b in np.flatnonzero((turn > max_turn) & (bseq[:-1] == bseq[1:])):
        r, i = int(bseq[b]), int(b - bfirst[bseq[b]]) + 1
        errors.setdefault(r, PlanningError(f"corner of {math.degrees(turn[b]):.1f} deg at waypoint {i} is sharper "
                                           f"than {math.degrees(max_turn):.1f} deg: split the feed sequence there", i))
    return errors


@dataclass(frozen=True, eq=False)
class Batch:
    """Sequences to plan, concatenated: R sequences, W waypoints, B = W - R blocks."""

    limits: Limits
    jerk: bool
    wfirst: np.ndarray  # (R + 1,) waypoint offsets
    bfirst: np.ndarray  # (R + 1,) block offsets
    s: np.ndarray  # (W,) local path parameter of the waypoints
    path: Pieces  # q(s), a cubic per block, (4, 5, B)
    tip: Pieces  # tip(s), the same parameter, (4, 3, B)
    tip_feed: np.ndarray  # (B,) mm/s, inf on rotary-only blocks
    block_cap: np.ndarray  # (B,) sdot cap of each block (feed, angular feed, minimum duration)

    @property
    def count(self) -> int:
        return len(self.wfirst) - 1

    @classmethod
    def of(cls, joints: np.ndarray, tip: np.ndarray, feed: np.ndarray, first: np.ndarray, limits: Limits,
           angular_feed: float, min_duration: float, jerk: bool) -> Batch:
        count = len(first) - 1
        bfirst = first - np.arange(count + 1)
        bseq = np.repeat(np.arange(count), np.diff(bfirst))
        left = np.arange(len(bseq)) + bseq
        dq = joints[left + 1] - joints[left]
        weighted = np.linalg.norm(dq / limits.velocity, axis=1)
        s = np.zeros(len(joints))
        running = segment_cumsum(weighted, bfirst)
        s[left + 1] = running / running[bfirst[1:] - 1][bseq]
        s[first[1:] - 1] = 1.0
        ds = s[left + 1] - s[left]
        coef = np.ascontiguousarray(not_a_knot(s, np.hstack([joints, tip]), first).transpose(0, 2, 1))
        length = np.linalg.norm(tip[left + 1] - tip[left], axis=1)
        rotary_only = length < TIP_EPS
        rotary = np.linalg.norm(dq[:, 3:], axis=1)
        with np.errstate(divide="ignore", over="ignore"):  # a rapid's cap (1e9 mm/s) over a tiny length
            tip_cap = np.where(rotary_only, np.inf, feed * ds / np.maximum(length, 1e-300))
            rot_cap = np.where(rotary_only & (rotary > 0), angular_feed * ds / np.maximum(rotary, 1e-300), np.inf)
            dur_cap = ds / min_duration if min_duration > 0 else np.full(len(ds), np.inf)
        return cls(limits, jerk, first, bfirst, s, Pieces(s[left], bfirst, coef[:, :DOF]),
                   Pieces(s[left], bfirst, coef[:, DOF:]), np.where(rotary_only, np.inf, feed),
                   np.minimum(np.minimum(tip_cap, rot_cap), dur_cap))

    def point_cap(self, seq: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Squared path-speed caps at local path parameters c: joint velocity, tip feed,
        centripetal jerk, and the caps of the block(s) c lies in; and |q'(c)| (5, n)."""
        lim = self.limits
        right = self.path.locate(seq, c, "right")
        # c on a waypoint lies in both its blocks: the one before is the one searching left finds
        left = right - ((self.path.start[right] == c) & (right > self.path.first[seq]))
        q = self.path.derivatives(right, c, (1, 3) if self.jerk else (1,))
        q1 = np.abs(q[0])
        feed = np.minimum(self.tip_feed[left], self.tip_feed[right])
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.min((lim.velocity[:, None] / q1) ** 2, axis=0)
            x = np.minimum(x, np.nan_to_num((feed / np.linalg.norm(self.tip(right, c, 1), axis=0)) ** 2, nan=np.inf))
            if self.jerk:
                x = np.minimum(x, np.min((_JERK_CAP_MARGIN * lim.jerk[:, None] / np.abs(q[1])) ** (2.0 / 3.0), axis=0))
        return np.minimum(np.minimum(x, np.minimum(self.block_cap[left], self.block_cap[right]) ** 2), 1e300), q1

    def sequence_path(self, r: int) -> tuple[np.ndarray, Cubics]:
        """Sequence r's waypoint parameters (K + 1,) and its spline q(s), standalone copies."""
        w = slice(self.wfirst[r], self.wfirst[r + 1])
        blocks = self.path.coef[..., self.bfirst[r]:self.bfirst[r + 1]]
        return self.s[w].copy(), Cubics(self.s[w].copy(), np.ascontiguousarray(blocks.transpose(0, 2, 1)))

    def waypoint_at(self, seq: int, c: float) -> int:
        """Index (within its sequence) of the first waypoint at or after local path parameter c."""
        s = self.s[self.wfirst[seq]:self.wfirst[seq + 1]]
        return int(np.clip(np.searchsorted(s, c - 1e-12, side="left"), 0, len(s) - 1))
