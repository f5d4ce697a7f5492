"""The program's motion as the controller runs it: block ends and samples of the joint-space
lines between them through the forward kinematics."""

from __future__ import annotations

from dataclasses import dataclass, fields, is_dataclass
from typing import Any

import numpy as np

from ..api import classify, forward_kinematics, pose_margins
from ..kinematics import Margins
from ..kinematics.rows import finite_rows, norms, take_rows
from ..machine import Machine
from .gcode_reader import GcodeProgram
from .reference import FIRST_INTERVALS, MAX_INTERVALS, POSE_CHUNK, RAPID_INTERVALS, SAMPLING_SHARE

# --------------------------------------------------------------------------------------------
# sampling the motion


@dataclass(frozen=True)
class Poses:
    """FK and margins of joint sets (NaN and unreachable where not computed)."""

    joints: np.ndarray  # (n, 5) mm, rad
    tip: np.ndarray  # (n, 3) mm, table frame
    axis: np.ndarray  # (n, 3)
    alpha: np.ndarray  # (n,) rad
    reachable: np.ndarray
    margins: Margins
    status: np.ndarray

    @classmethod
    def at(cls, machine: Machine, joints: np.ndarray, lengths: np.ndarray, valid: np.ndarray | None = None,
           alpha_guess: np.ndarray | None = None) -> Poses:
        """Poses of joint sets (mm, rad) with tool lengths (mm), where ``valid`` (default all)."""
        n = len(joints)
        valid = np.ones(n, bool) if valid is None else valid
        tip, axis, platform = np.full((n, 3), np.nan), np.full((n, 3), np.nan), np.full((n, 3), np.nan)
        alpha, reachable = np.full(n, np.nan), np.zeros(n, bool)
        margin_parts = []
        for start in range(0, max(n, 1), POSE_CHUNK):  # chunks bound the kinematics' temporary arrays
            rows = slice(start, start + POSE_CHUNK)
            use = np.flatnonzero(valid[rows]) + start
            # the whole chunk (the rule) as a slice: its rows neither gathered nor scattered
            at = rows if len(use) == len(valid[rows]) else use
            if use.size:
                fk = forward_kinematics(machine, joints[at], tool_length=lengths[at],
                                        alpha_guess=None if alpha_guess is None else alpha_guess[at])
                tip[at], axis[at], alpha[at], platform[at] = fk.tip, fk.axis, fk.alpha, fk.platform
                reachable[at] = fk.reachable
            margin_parts.append(pose_margins(machine, joints[rows], platform[rows], alpha[rows], reachable[rows],
                                             np.nan_to_num(lengths[rows])))
        found = _joined(margin_parts)
        return cls(joints, tip, axis, alpha, reachable, found, classify(machine, joints, reachable, found))


def _rows(record: Any, index: np.ndarray) -> Any:
    """The rows ``index`` of a dataclass of arrays (nested dataclasses too)."""
    return type(record)(*(_rows(v, index) if is_dataclass(v) else v[index]
                          for v in (getattr(record, f.name) for f in fields(record))))


def _joined(records: list[Any]) -> Any:
    """Dataclasses of arrays, rows one after the other."""
    first = records[0]
    return type(first)(*(_joined([getattr(r, f.name) for r in records]) if is_dataclass(getattr(first, f.name))
                         else np.concatenate([getattr(r, f.name) for r in records]) for f in fields(first)))


@dataclass(frozen=True)
class Curves:
    """Joint-space lines into blocks ``moves`` (K of them), each sampled at ``n`` intervals.

    ``tip``/``axis``: the points of each move, start, interior samples, end (n + 1 rows each),
    move after move; ``samples``: the interior samples (n - 1 rows each) with margins.
    ``d2_tip``/``d2_axis``: per move, the largest second difference of the points (mm; chord).
    """

    moves: np.ndarray
    n: np.ndarray
    d2_tip: np.ndarray
    d2_axis: np.ndarray
    tip: np.ndarray
    axis: np.ndarray
    samples: Poses

    @property
    def start(self) -> np.ndarray:
        return np.cumsum(self.n + 1) - (self.n + 1)

    @property
    def block(self) -> np.ndarray:
        """The block of each interior sample."""
        return np.repeat(self.moves, self.n - 1)

    def take(self, mask: np.ndarray) -> Curves:
        return Curves(self.moves[mask], self.n[mask], self.d2_tip[mask], self.d2_axis[mask],
                       self.tip[np.repeat(mask, self.n + 1)], self.axis[np.repeat(mask, self.n + 1)],
                       _rows(self.samples, np.repeat(mask, self.n - 1)))

    @classmethod
    def sample(cls, machine: Machine, joints: np.ndarray, lengths: np.ndarray, ends: Poses, moves: np.ndarray,
               n: np.ndarray) -> Curves:
        """Sample the lines from block end m - 1 to m (joints mm/rad) with block m's tool."""
        inner = n - 1
        owner = np.repeat(np.arange(len(moves)), inner)
        first = np.cumsum(inner) - inner
        f = (np.arange(int(inner.sum())) - first[owner] + 1) / n[owner]
        m = moves[owner]
        before = take_rows(joints, m - 1)
        q = before + f[:, None] * (take_rows(joints, m) - before)
        guess = ends.alpha[m - 1] + f * (ends.alpha[m] - ends.alpha[m - 1])
        samples = Poses.at(machine, q, lengths[m], alpha_guess=np.nan_to_num(guess))
        start_tip, start_axis = take_rows(ends.tip, moves - 1), take_rows(ends.axis, moves - 1)
        retooled = lengths[moves] != lengths[moves - 1]  # after a tool change: the start with the new tool
        if retooled.any():
            fk = forward_kinematics(machine, joints[moves[retooled] - 1], tool_length=lengths[moves[retooled]])
            start_tip[retooled], start_axis[retooled] = fk.tip, fk.axis
        start = np.cumsum(n + 1) - (n + 1)
        inside = start[owner] + np.arange(len(owner)) - first[owner] + 1
        tip, axis = np.empty((int((n + 1).sum()), 3)), np.empty((int((n + 1).sum()), 3))
        tip[start], axis[start] = start_tip, start_axis
        tip[inside], axis[inside] = samples.tip, samples.axis
        tip[start + n], axis[start + n] = take_rows(ends.tip, moves), take_rows(ends.axis, moves)
        d2_tip, d2_axis = np.zeros(len(moves)), np.zeros(len(moves))
        if len(owner):
            for d2, points in ((d2_tip, tip), (d2_axis, axis)):
                second = points[inside - 1] - 2 * points[inside] + points[inside + 1]
                d2[:] = np.nan_to_num(np.maximum.reduceat(norms(second), first), nan=np.inf)
        return cls(moves, n, d2_tip, d2_axis, tip, axis, samples)


@dataclass(frozen=True)
class Motion:
    """Poses at the M block ends and along the moves between them, for all the checks."""

    known: np.ndarray  # (M,) block end known (joints and tool length)
    ends: Poses  # (M,)
    curves: Curves

    @classmethod
    def of(cls, program: GcodeProgram, machine: Machine, lengths: np.ndarray, tol: float, axis_tol: float
           ) -> Motion:
        """Sample every move densely enough for the sampling error to stay below
        SAMPLING_SHARE of ``tol`` (mm) and ``axis_tol`` (rad); see the module docstring."""
        q = program.joints
        known = finite_rows(q) & np.isfinite(lengths)
        ends = Poses.at(machine, q, lengths, known)
        moves = np.flatnonzero(known[1:] & known[:-1]) + 1
        rapid = program.rapid[moves]
        n = np.where(rapid, RAPID_INTERVALS, FIRST_INTERVALS)
        todo = np.arange(len(moves))
        done = []
        for _ in range(4):
            curves = Curves.sample(machine, q, lengths, ends, moves[todo], n[todo])
            # max|t''| h^2 ~ largest second difference: n so that it / 8 <= SAMPLING_SHARE * tolerance
            need = np.ceil(n[todo] * np.sqrt(np.maximum(curves.d2_tip / (8 * SAMPLING_SHARE * tol),
                                                        curves.d2_axis / (8 * SAMPLING_SHARE * axis_tol))))
            more = ~rapid[todo] & (need > n[todo]) & (n[todo] < MAX_INTERVALS)
            done.append(curves.take(~more))
            if not more.any():
                break
            todo = todo[more]
            n[todo] = np.minimum(need[more], MAX_INTERVALS).astype(int)
        else:
            done.append(curves.take(more))
        return cls(known, ends, _joined(done))

    @property
    def bound_tip(self) -> np.ndarray:
        """(K,) mm: how far the tip may be beyond the largest sampled deviation, per move."""
        return self.curves.d2_tip / 8

    @property
    def bound_axis(self) -> np.ndarray:
        """(K,) rad, the same for the axis."""
        return self.curves.d2_axis / 8

    def all_samples(self) -> tuple[np.ndarray, np.ndarray, Poses]:
        """(block, interior, poses) of the block ends and the interior samples."""
        m = len(self.known)
        block = np.r_[np.arange(m), self.curves.block]
        interior = np.r_[np.zeros(m, bool), np.ones(len(self.curves.block), bool)]
        return block, interior, _joined([self.ends, self.curves.samples])
