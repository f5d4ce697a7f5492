"""IK along a toolpath: angle-pair (branch) choice, rotary continuity and the table's pole.

Every tool axis has two working-mode solutions, one per angle pair (theta1 ~ -phi1 with
theta2 = -phi2, or theta1 ~ +phi1 with theta2 turned by pi). Switching pair in the middle of
a cut would swing the table by 180 degrees, so one pair is kept along each *run* of a
sequence (a sequence is a stretch the caller says must be continuous, e.g. a feed sequence
between rapids). Near the pole (axis within ``cone`` of the table normal) theta2 is
ill-defined: there it is interpolated between the neighbouring well-defined values and the
axis is met as closely as that theta2 allows (error <= the cone angle); crossing the pole
the path continues on the other pair, which is the continuous motion (theta1 passes through
0 instead of the table whipping round). Angles in radians, tips in mm, table frame.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..api import IKResult, Status, assess, concatenate, inverse_kinematics_pair, joint_bounds
from ..kinematics import axis_from_angles, wrap_angle
from ..kinematics.rows import take_rows
from ..machine import Machine


@dataclass(frozen=True)
class BranchState:
    """What the IK of a path hands on to the poses after it, so that a long path solved a part
    at a time gets the joints it would get all at once: where theta2 was last defined (off the
    pole) and the tip distance along the path, for the rotary's continuity across the part
    boundary and the pole cone's interpolation. Angles in radians, mm."""

    wrapped: float | None = None  # theta2 as solved (wrapped) at the last pose with a defined theta2
    turns: float = 0.0  # what unwrapping added there: its theta2 is wrapped + turns
    held_sequence: int = -1  # that pose's sequence
    held_distance: float = 0.0  # and its tip distance along the path
    tip: np.ndarray | None = None  # the last pose's tip
    distance: float = 0.0  # and its tip distance along the path
    lead: float | None = None  # theta2 of the path's first defined pose, for the poses before it


@dataclass(frozen=True)
class Pairs:
    """The angle pair chosen along a path (see :func:`choose_pairs`)."""

    plus: np.ndarray  # (N,) bool: pair +1
    switch: np.ndarray  # (N,) bool: the pair changed into this pose inside a sequence off the pole
    lead: float | None  # theta2 (rad, as solved) of the first pose off the pole with a solution

    def part(self, first: int, end: int) -> Pairs:
        return Pairs(self.plus[first:end], self.switch[first:end], self.lead)


@dataclass(frozen=True)
class _Trace:
    """Per pose of a solved path: theta2 as solved, what unwrapping added (NaN where theta2 is
    not defined), tip distance along the path (mm), sequence; and the state it started from."""

    wrapped: np.ndarray
    added: np.ndarray
    distance: np.ndarray
    sequence: np.ndarray
    tip: np.ndarray
    start: BranchState


@dataclass(frozen=True)
class PathIK:
    """Joints along a path plus what the branch stage decided."""

    result: IKResult  # joints (theta2 unwrapped and continuous), status, margins per pose
    axis: np.ndarray  # (N, 3) axis the joints realise (differs from the programmed one in the pole cone)
    in_cone: np.ndarray  # (N,) bool: theta2 was interpolated (axis within the pole cone)
    pair_switch: np.ndarray  # (N,) bool: the pair changed into this pose inside a sequence off the pole
    trace: _Trace | None = None

    def state_at(self, k: int) -> BranchState:
        """The state after pose ``k``, to solve the poses after it."""
        t = self.trace
        assert t is not None
        defined = np.flatnonzero(np.isfinite(t.added[:k + 1]))
        held = t.start
        if defined.size:
            j = defined[-1]
            held = BranchState(float(t.wrapped[j]), float(t.added[j]), int(t.sequence[j]), float(t.distance[j]))
        return replace(held, tip=t.tip[k], distance=float(t.distance[k]), lead=t.start.lead)

    def rows(self, index: np.ndarray | slice) -> PathIK:
        """The poses ``index`` (without the trace)."""
        return PathIK(self.result.rows(index), take_rows(self.axis, index), self.in_cone[index],
                      self.pair_switch[index])

    def then(self, other: PathIK) -> PathIK:
        """These poses, then those of ``other`` (without the trace)."""
        return PathIK(concatenate([self.result, other.result]), np.concatenate([self.axis, other.axis]),
                      np.concatenate([self.in_cone, other.in_cone]),
                      np.concatenate([self.pair_switch, other.pair_switch]))


def _pole_angle(axis: np.ndarray) -> np.ndarray:
    """Angle (rad) between unit axes (N, 3) and the table normal."""
    return np.arctan2(np.hypot(axis[:, 0], axis[:, 1]), axis[:, 2])


def _by_length(lengths: np.ndarray, n: int, solve: Callable[[np.ndarray | slice, float], IKResult]) -> IKResult:
    """Run ``solve(rows, tool_length)`` per tool length (mm) and gather the rows back in order."""
    out: IKResult | None = None
    each = np.unique(lengths)
    if len(each) == 1:  # one tool: all rows as they are, none gathered and scattered
        return solve(slice(None), float(each[0]))
    for length in each:
        rows = np.flatnonzero(lengths == length)
        part = solve(rows, float(length))
        out = part.rows(np.zeros(n, int)) if out is None else out  # allocate full length once
        out = out.scatter(rows, part)
    assert out is not None
    return out


def _pair_results(machine: Machine, tip: np.ndarray, axis: np.ndarray, lengths: np.ndarray, pair: np.ndarray,
                  theta2_at_pole: np.ndarray, with_margins: bool) -> IKResult:
    return _by_length(lengths, len(tip), lambda rows, length: inverse_kinematics_pair(
        machine, tip[rows], axis[rows], pair[rows], tool_length=length, theta2_at_pole=theta2_at_pole[rows],
        with_margins=with_margins))


def solve_with_theta2(machine: Machine, tip: np.ndarray, axis: np.ndarray, lengths: np.ndarray,
                      theta2: np.ndarray, cone: float) -> tuple[IKResult, np.ndarray]:
    """Working-mode joints with theta2 near a reference (rad); returns (result, realised axis).

    Off the pole cone the angle pair whose theta2 is nearest ``theta2`` (mod 2 pi) is used and
    theta2 is unwrapped next to it. Inside the cone theta2 is imposed and the axis becomes its
    projection on the plane that theta2 allows (phi1 signed: its sign picks the pair).
    """
    axis = axis.copy()
    in_cone = _pole_angle(axis) < cone
    phi2 = -theta2[in_cone]
    along = np.stack([np.sin(phi2), -np.cos(phi2)], axis=-1)
    phi1 = np.arctan2(np.sum(axis[in_cone, :2] * along, axis=-1), axis[in_cone, 2])
    axis[in_cone] = axis_from_angles(phi1, phi2)
    theta2_plus = -np.arctan2(axis[:, 0], -axis[:, 1])  # theta2 of pair +1 (pair -1: turned by pi)
    pair = np.where(np.abs(wrap_angle(theta2_plus - theta2)) <= np.pi / 2, 1, -1)
    pair[in_cone] = np.where(phi1 >= 0, 1, -1)
    chosen = _pair_results(machine, tip, axis, lengths, pair, theta2, with_margins=True)
    joints = chosen.joints.copy()
    joints[:, 4] = theta2 + wrap_angle(joints[:, 4] - theta2)
    return chosen.with_joints(joints), axis


@dataclass(frozen=True)
class PairAngles:
    """One angle pair's solutions along a path, as much as the choice of pair needs: status and
    (theta1, theta2) in rad as solved (theta2 wrapped)."""

    status: np.ndarray  # (N,)
    angles: np.ndarray  # (N, 2)

    @classmethod
    def of(cls, result: IKResult) -> PairAngles:
        return cls(result.status, result.joints[:, 3:])


def _travel(result: PairAngles, rows: np.ndarray, previous: np.ndarray | None) -> tuple[float, float]:
    """Rotary travel (rad) along the rows, from the previous pose's (theta1, theta2) if given,
    then mean |theta1| to break ties."""
    angles = result.angles[rows]
    travel = float(np.sum(np.abs(np.diff(angles[:, 0]))) + np.sum(np.abs(np.diff(np.unwrap(angles[:, 1])))))
    if previous is not None:
        travel += abs(angles[0, 0] - previous[0]) + abs(float(wrap_angle(angles[0, 1] - previous[1])))
    return round(travel, 9), float(np.mean(np.abs(angles[:, 0])))


def _run_choice(plus: PairAngles, minus: PairAngles, rows: np.ndarray, previous: np.ndarray | None, fresh: bool
                ) -> np.ndarray:
    """Pair per pose of one run: one pair usable throughout if any.

    A run that starts a sequence takes the pair with the least rotary travel (counting the
    way from the previous pose); a run that continues a sequence across the pole takes the
    pair that continues theta2.
    """
    ok_plus, ok_minus = plus.status[rows] == Status.OK, minus.status[rows] == Status.OK
    if ok_plus.all() and ok_minus.all():
        if fresh or previous is None:
            choice = _travel(plus, rows, previous) <= _travel(minus, rows, previous)
        else:
            choice = (abs(wrap_angle(plus.angles[rows[0], 1] - previous[1]))
                      <= abs(wrap_angle(minus.angles[rows[0], 1] - previous[1])))
        return np.full(len(rows), choice)
    if ok_plus.all() or ok_minus.all():
        return np.full(len(rows), bool(ok_plus.all()))
    # Neither pair works throughout: each pose takes the pair it can use; poses that could use
    # both keep the pair of the nearest constrained pose before them.
    forced = ok_plus != ok_minus
    choice = np.where(forced, ok_plus, True)
    if forced.any():
        last = np.maximum.accumulate(np.where(forced, np.arange(len(rows)), -1))
        last[last < 0] = np.flatnonzero(forced)[0]
        choice = choice[last]
    return choice


def choose_pairs(plus: PairAngles, minus: PairAngles, sequence: np.ndarray, in_cone: np.ndarray) -> Pairs:
    """The angle pair along a whole path, run by run (:func:`_run_choice`), from both pairs'
    solutions, the sequence ids and the pole cone mask."""
    use_plus = np.ones(len(sequence), bool)
    previous: np.ndarray | None = None
    for rows, fresh in _runs(sequence, in_cone):
        use_plus[rows] = _run_choice(plus, minus, rows, previous, fresh)
        previous = (plus if use_plus[rows[-1]] else minus).angles[rows[-1]]
    switch = np.r_[False, (use_plus[1:] != use_plus[:-1]) & (sequence[1:] == sequence[:-1])
                   & ~in_cone[1:] & ~in_cone[:-1]]
    theta2 = np.where(use_plus, plus.angles[:, 1], minus.angles[:, 1])
    defined = np.flatnonzero(~in_cone & np.isfinite(theta2))
    return Pairs(use_plus, switch, float(theta2[defined[0]]) if defined.size else None)


def in_pole_cone(axis: np.ndarray, cone: float) -> np.ndarray:
    """Unit axes (N, 3) within ``cone`` (rad) of the table normal (an axis along it always)."""
    return _pole_angle(axis) < max(cone, 1e-12)


def both_pairs(machine: Machine, tip: np.ndarray, axis: np.ndarray, lengths: np.ndarray) -> tuple[IKResult, IKResult]:
    """Working-mode IK of N poses with each angle pair (+1, -1), without margins (reach, travel
    and rod clearance decide the status): what the choice of pair weighs."""
    n = len(tip)
    plus, minus = (_pair_results(machine, tip, axis, lengths, np.full(n, p), np.zeros(n), with_margins=False)
                   for p in (1, -1))
    return plus, minus


def _runs(sequence: np.ndarray, in_cone: np.ndarray) -> list[tuple[np.ndarray, bool]]:
    """(rows, starts a sequence) for each run of off-cone poses."""
    boundary = np.r_[True, (sequence[1:] != sequence[:-1]) | (in_cone[1:] != in_cone[:-1])]
    starts = np.flatnonzero(boundary)
    ends = np.r_[starts[1:], len(sequence)]
    new_sequence = np.r_[True, sequence[1:] != sequence[:-1]]
    runs, fresh = [], False
    for start, end in zip(starts, ends, strict=True):
        fresh = fresh or bool(new_sequence[start])
        if not in_cone[start]:
            runs.append((np.arange(start, end), fresh))
            fresh = False
    return runs


def _fit_rotary(machine: Machine, theta2: np.ndarray, sequence: np.ndarray) -> np.ndarray:
    """Shift each sequence by whole turns into a limited rotary's range where that fits."""
    lower, upper = joint_bounds(machine)
    if not np.isfinite(lower[4]):
        return theta2
    out = theta2.copy()
    for seq in np.unique(sequence):
        rows = sequence == seq
        low, high = out[rows].min(), out[rows].max()
        turns = np.arange(np.ceil((lower[4] - low) / (2 * np.pi)), np.floor((upper[4] - high) / (2 * np.pi)) + 1)
        if turns.size:
            out[rows] += 2 * np.pi * turns[np.argmin(np.abs(turns))]
    return out


def solve_path(machine: Machine, tip: np.ndarray, axis: np.ndarray, sequence: np.ndarray | None = None, *,
               tool_length: float | np.ndarray = 0.0, cone: float = 0.0, state: BranchState | None = None,
               pairs: Pairs | None = None) -> PathIK:
    """Working-mode joints along N poses (tip mm, unit axis, table frame), continuous in theta.

    ``sequence`` ids mark stretches that must be continuous (default: one); ``tool_length``
    (mm) may vary per pose; ``cone`` (rad) is the pole cone. theta2 is unwrapped along the
    whole path (shortest way across rapids) and fitted into a limited rotary's range.

    A long path may be solved a part at a time: ``pairs`` the angle pairs chosen along the
    whole path (:func:`choose_pairs`, here the part's), ``state`` the :meth:`PathIK.state_at`
    the last pose of the part before. A part must not end within a sequence before a pose
    in the pole cone (its theta2 is interpolated to the next pose off the pole), nor within a
    sequence of a limited rotary (fitted into the range whole).
    """
    state = state or BranchState()
    n = len(tip)
    sequence = np.zeros(n, int) if sequence is None else np.asarray(sequence)
    lengths = np.broadcast_to(np.asarray(tool_length, dtype=float), (n,))
    in_cone = in_pole_cone(axis, cone)
    # Pair choice on reach, travel and rod clearance; margins only for the chosen solutions.
    if pairs is None:
        plus, minus = both_pairs(machine, tip, axis, lengths)
        pairs = choose_pairs(PairAngles.of(plus), PairAngles.of(minus), sequence, in_cone)
        chosen = plus.take(pairs.plus, minus)
    else:  # only the chosen pair's IK (elementwise: the same numbers as taking them from both)
        chosen = _pair_results(machine, tip, axis, lengths, np.where(pairs.plus, 1, -1), np.zeros(n),
                               with_margins=False)
    defined = np.flatnonzero(~in_cone & np.isfinite(chosen.joints[:, 4]))
    theta2, added = np.zeros(n), np.full(n, np.nan)
    if defined.size:
        theta2[defined], added[defined] = _unwrap(chosen.joints[defined, 4], state.wrapped, state.turns)
    steps = np.linalg.norm(np.diff(tip if state.tip is None else np.r_[state.tip[None], tip], axis=0), axis=1)
    distance = np.cumsum(np.r_[state.distance, steps])[len(steps) - n + 1:]
    if defined.size < n:
        theta2 = _interpolate_cone(theta2, defined, distance, sequence, state, pairs.lead)
    theta2 = _fit_rotary(machine, theta2, sequence)
    result = assess(machine, chosen.with_joints(np.column_stack([chosen.joints[:, :4], theta2])), lengths)
    realised = axis.copy()
    if in_cone.any():
        rows = np.flatnonzero(in_cone)
        redo, realised[rows] = solve_with_theta2(machine, tip[rows], axis[rows], lengths[rows], theta2[rows], cone)
        result = result.scatter(rows, redo)
    trace = _Trace(chosen.joints[:, 4], added, distance, sequence, tip, replace(state, lead=pairs.lead))
    return PathIK(result, realised, in_cone, pairs.switch, trace)


def _unwrap(wrapped: np.ndarray, last: float | None, turns: float) -> tuple[np.ndarray, np.ndarray]:
    """``np.unwrap(wrapped)`` (rad) continued from the angle ``last`` that unwrapping moved by
    ``turns``: the same numbers, bit for bit, as unwrapping everything at once (numpy's steps,
    the corrections summed in order). Returns the angles and what unwrapping added to each."""
    p = wrapped if last is None else np.r_[last, wrapped]
    step = np.diff(p)
    wrapped_step = np.mod(step + np.pi, 2 * np.pi) - np.pi
    np.copyto(wrapped_step, np.pi, where=(wrapped_step == -np.pi) & (step > 0))
    correction = wrapped_step - step
    np.copyto(correction, 0, where=np.abs(step) < np.pi)
    if last is None:
        correction = np.r_[0.0, correction]
    added = np.cumsum(np.r_[turns, correction])[1:]
    return wrapped + added, added


def _interpolate_cone(theta2: np.ndarray, defined: np.ndarray, distance: np.ndarray, sequence: np.ndarray,
                      before: BranchState, lead: float | None) -> np.ndarray:
    """theta2 at the undefined poses: linear in tip distance (mm along the path) between the
    defined neighbours of the same sequence, else held from the nearest defined pose (``before``:
    the last one before these poses, if any; ``lead``: the first one of the path, where none
    before or among these is defined)."""
    if before.wrapped is not None:  # the last defined pose before these comes first
        held = before.wrapped + before.turns
        out = _interpolate_cone(np.r_[held, theta2], np.r_[0, defined + 1], np.r_[before.held_distance, distance],
                                np.r_[before.held_sequence, sequence], BranchState(), lead)
        return out[1:]
    n = len(theta2)
    is_defined = np.zeros(n, bool)
    is_defined[defined] = True
    before_k = np.maximum.accumulate(np.where(is_defined, np.arange(n), -1))
    after_k = np.minimum.accumulate(np.where(is_defined, np.arange(n), n)[::-1])[::-1]
    out = theta2.copy()
    for k in np.flatnonzero(~is_defined):
        b, a = before_k[k], after_k[k]
        b_ok = b >= 0 and sequence[b] == sequence[k]
        a_ok = a < n and sequence[a] == sequence[k]
        if b_ok and a_ok and distance[a] > distance[b]:
            target = theta2[b] + wrap_angle(theta2[a] - theta2[b])
            out[k] = theta2[b] + (target - theta2[b]) * (distance[k] - distance[b]) / (distance[a] - distance[b])
        elif b >= 0:
            out[k] = theta2[b]
        elif a < n:
            out[k] = theta2[a]
        elif lead is not None:
            out[k] = lead
    return out
