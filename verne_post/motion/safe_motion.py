"""Stage 4b: the moves between cuts, kept safe as the tool tip moves relative to the part.

The controller interpolates the joints linearly. On the VERNE a straight line in joint space is
a curve at the tool tip: a joint-space rapid between two clearance points at the same height
sags below them (19 mm on a 3-axis z-level job), and one that turns the tool axis swings it
through the part. So no move between cuts is left to the joint interpolation:

- **A CL rapid** whose tool axis turns by at most ``safe.max_turn_in_rapid`` (and on the same
  angle pair) runs on the CAM's straight line: the tip linear, the axis by spherical
  interpolation, split in joint space until the tip stays within ``rapid_tol`` (mm) and the
  axis within ``rapid_axis_tol``, like a feed move. It never leaves the line downward (toward
  the part): its interior block ends are lifted by half the tolerance above the line (along
  the line's upward normal in its vertical plane, reached within a short ramp at each end),
  and a block whose joint interpolation dips below the line is split further. A rapid with both
  ends above the envelope's top (not vertical) is free up there, as a turn is: one joint-space
  line, split only where it would dip below the top.
- **Retract, reorient, approach** where the axis turns more, the angle pair changes, or the
  straight line leaves the machine's limits, by way of the clearance envelope
  (:attr:`SafeSettings.envelope`): the bounding box of the program's feed points (and a setup
  box, if given) grown by ``safe.clearance`` on every side, open below (the table is under the
  part); its top is the safe level, ``safe.clearance`` above the highest feed point. Up to six
  legs: retract along the current tool axis until the tip leaves the envelope (the box is
  convex: from there on up its axis the whole tool is out too); if it left through a side (a
  nearly horizontal axis, in side work), rise vertically, the axis held, to the top; turn the
  tool axis there in one joint-space line, the tip free to swing above the top (the whole move
  raised above the top by as much as the line would dip below it, :func:`_free_turns`; where no
  raise keeps it up there, or the raised points are out of reach, the tip is held still at the
  top as the rotary joints move about linearly: the table turns about the tip, crossing the pole
  where the angle pair changes); travel at the top; descend vertically above the new pose's exit
  point, if it has a side exit; approach along the new tool axis. Retract and approach keep the
  feed tolerances (``tol``, ``axis_tol``): the tool leaves or enters the cut's surroundings; the
  rise, turn, travel and descent, outside the envelope, the rapid ones. A tool axis that would have to lower
  the tool to leave the envelope (pointing down) is a problem.
- **Start, tool changes, end** go through the same logic from and to the machine file's
  joint-space ``positions.home`` and ``positions.tool_change``, reached exactly. Without a
  ``tool_change`` position the tool is changed where the retract (and rise) leaves it, high
  enough that the new tool's tip is at the safe level too; without ``home`` the program starts
  over its first pose's exit from the envelope at the safe level.

Blocks of a rapid into CL pose k have ``pose`` k and fractions in (0, 1); the retract and move
to the tool-change position (with the old tool) or home after the program's last pose belong
to the pose they leave, with fractions in (1, 2]. Units: mm and rad, table frame.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..api import IKResult, Status, concatenate, forward_kinematics
from ..cl.toolpath import ToolChange
from ..kinematics import axis_from_angles, wrap_angle
from ..machine import Machine
from .branch import solve_with_theta2
from .linearise import Blocks, angle_to_arc, distance_to_segment, slerp
from .poses import MachinePoses

#: Splitting aims at this share of each tolerance (as the feed moves' linearisation does).
MARGIN = 0.8
#: mm: the dip below its line that splits a rapid block further (the joint chords of the block
#: ends, lifted half the tolerance above the line, otherwise sag toward it near the ends).
DIP_SPLIT = 1e-4
MAX_LEVELS = 24
#: Inserted points at most per leg: past it the leg is unresolved (a rapid line then falls back
#: to retract / reorient / approach; an unresolved leg of that is a violation).
MAX_POINTS_PER_LEG = 2000
#: The sag of a block at a ramp counts this much more than measured (it is sampled, and not
#: exactly parabolic).
SAG_FACTOR = 1.25
#: Fractions of a block where its deviation is measured while splitting.
MEASURE = np.array([0.25, 0.5, 0.75])
#: ... and of a free turn, where the tip swings above the envelope's top between its ends.
MEASURE_TURN = np.linspace(0.0, 1.0, 33)[1:-1]
#: mm: legs shorter than this, and turns below 1e-9 rad, are left out.
SHORT = 1e-6


@dataclass(frozen=True)
class SafeSettings:
    """What the moves between cuts must keep to: mm and rad, table frame."""

    rapid_tol: float  # mm: tip from the CL rapid's line
    rapid_axis_tol: float  # rad
    tol: float  # mm: retract and approach (the feed tolerance)
    axis_tol: float  # rad
    max_turn: float  # rad: a larger axis turn in a rapid retracts, reorients, approaches
    #: (2, 3) mm, table frame: the clearance envelope's lo and hi corners, an axis-aligned box
    #: the moves between cuts leave before they travel; lo z is -inf (see :meth:`of`)
    envelope: np.ndarray
    cone: float  # rad: the pole cone of the branch stage
    home: np.ndarray | None  # (5,) mm, rad
    tool_change: np.ndarray | None  # (5,) mm, rad

    @property
    def level(self) -> float:
        """mm, table-frame z: the safe level, the envelope's top, where the moves between cuts travel."""
        return float(self.envelope[1, 2])

    @classmethod
    def of(cls, machine: Machine, tip: np.ndarray, rapid: np.ndarray, *, rapid_tol: float, rapid_axis_tol: float,
           tol: float, axis_tol: float, setup_box: np.ndarray | None = None, tool_radius: float = 0.0
           ) -> SafeSettings:
        """Settings of a program with CL tips (N, 3) mm, table frame, and rapid flags (N,);
        tolerances in mm and rad.

        The clearance envelope is the bounding box of the feed points (of every point, when the
        program has no feed move) united with ``setup_box`` ((2, 3) mm, table frame: the stock and
        fixtures, if known), grown on every side by ``safe.clearance`` + ``tool_radius`` (mm) but
        the bottom: that one is -inf. Below the part stands the table, so no move between cuts
        may leave the envelope downward; a ray along a tool axis (which points up, away from the
        part) leaves it through the top or a side, and one that would lower the tool is refused
        (:func:`detour_legs`). Without a setup box and with no tool radius the top is today's safe
        level, ``safe.clearance`` above the highest feed point."""
        feed = tip[~rapid] if (~rapid).any() else tip
        lo, hi = (feed.min(axis=0), feed.max(axis=0)) if len(feed) else (np.zeros(3), np.zeros(3))
        if setup_box is not None:
            lo, hi = np.minimum(lo, setup_box[0]), np.maximum(hi, setup_box[1])
        grow = machine.safe.clearance + tool_radius
        envelope = np.array([[lo[0] - grow, lo[1] - grow, -np.inf], hi + grow])
        positions = machine.positions
        return cls(rapid_tol, rapid_axis_tol, tol, axis_tol, np.radians(machine.safe.max_turn_in_rapid),
                   envelope, np.radians(machine.pole.cone),
                   None if positions.home is None else positions.home.joints(),
                   None if positions.tool_change is None else positions.tool_change.joints())


def upward_normal(tip0: np.ndarray, tip1: np.ndarray) -> np.ndarray:
    """(L, 3): the unit normal of each segment (mm) in its vertical plane pointing up (+z), zero
    for a vertical or zero-length segment."""
    span = tip1 - tip0
    size = np.linalg.norm(span, axis=1, keepdims=True)
    d = span / np.where(size > 0, size, 1.0)
    n = np.array([0.0, 0.0, 1.0]) - d[:, 2:3] * d
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where((norm > 1e-6) & (size > SHORT), n / np.where(norm > 0, norm, 1.0), 0.0)


def dip_below(point: np.ndarray, tip0: np.ndarray, tip1: np.ndarray, up: np.ndarray) -> np.ndarray:
    """How far (mm, >= 0) each point lies below its segment tip0 -> tip1 (table frame): under
    the line along its upward normal ``up`` (:func:`upward_normal`; 0 for a vertical segment),
    or below the segment's lower end."""
    under_line = -np.sum((point - tip0) * up, axis=1)
    under_end = np.minimum(tip0[:, 2], tip1[:, 2]) - point[:, 2]
    return np.maximum(np.maximum(under_line, under_end), 0.0)


@dataclass(frozen=True)
class State:
    """Where a leg starts or ends, one row per leg: the IK result (joints mm and rad, tilt alpha,
    status, margins), the tip (mm) and the axis (table frame) for the leg's tool."""

    result: IKResult
    tip: np.ndarray
    axis: np.ndarray

    @property
    def joints(self) -> np.ndarray:
        return self.result.joints

    def rows(self, index: np.ndarray) -> State:
        return State(self.result.rows(index), self.tip[index], self.axis[index])

    def scatter(self, rows: np.ndarray, part: State) -> State:
        """A copy with ``rows`` replaced by ``part``."""
        tip, axis = self.tip.copy(), self.axis.copy()
        tip[rows], axis[rows] = part.tip, part.axis
        return State(self.result.scatter(rows, part.result), tip, axis)

    def where(self, mask: np.ndarray, other: State) -> State:
        """Rows of ``self`` where ``mask``, of ``other`` elsewhere."""
        return State(self.result.take(mask, other.result), np.where(mask[:, None], self.tip, other.tip),
                     np.where(mask[:, None], self.axis, other.axis))

    @staticmethod
    def join(states: list[State]) -> State:
        return State(concatenate([s.result for s in states]), np.concatenate([s.tip for s in states]),
                     np.concatenate([s.axis for s in states]))


def _solve(machine: Machine, tip: np.ndarray, axis: np.ndarray, lengths: np.ndarray, theta2: np.ndarray,
           cone: float) -> State:
    """Working-mode IK with theta2 near ``theta2`` (rad): the state at each pose (mm, table frame)."""
    known = np.all(np.isfinite(tip), axis=1) & np.all(np.isfinite(axis), axis=1) & np.isfinite(theta2)
    if not known.all():  # a pose of nowhere (a position out of reach): unreachable, not an error
        tip, axis = np.where(known[:, None], tip, 0.0), np.where(known[:, None], axis, [0.0, 0.0, 1.0])
        theta2 = np.where(known, theta2, 0.0)
    result, realised = solve_with_theta2(machine, tip, axis, lengths, theta2, cone)
    if not known.all():
        nowhere = replace(result, joints=np.full_like(result.joints, np.nan),
                          status=np.full_like(result.status, Status.UNREACHABLE))
        result = nowhere.take(~known, result)
    return State(result, tip, realised)


def at_joints(machine: Machine, joints: np.ndarray, lengths: np.ndarray, cone: float) -> State:
    """The state at given joints (K, 5) (mm, rad) with tools of ``lengths`` (K,) mm: tip and axis
    by the forward kinematics, the IK result (margins, status) with exactly these joints."""
    fk = forward_kinematics(machine, joints, tool_length=lengths)
    tip = np.where(fk.reachable[:, None], fk.tip, np.nan)
    state = _solve(machine, tip, fk.axis, lengths, joints[:, 4], cone)
    return State(state.result.with_joints(np.where(fk.reachable[:, None], joints, np.nan)), tip, fk.axis)


@dataclass(frozen=True)
class Legs:
    """Straight pieces of the moves between cuts, L of them: the tip on the segment ``tip0`` ->
    ``tip1`` (lifted by ``lift`` mm along ``up`` in the interior), the axis by spherical
    interpolation, or, where ``reorient``, along the rotary angles (phi1, phi2) from ``phi0`` to
    ``phi1`` (rad) with the tip still (the points a held turn is split at; a free turn, ``above``
    finite, keeps only above that height); block fractions ``f0`` -> ``f1`` of CL pose ``pose``."""

    start: State
    end: State
    tip0: np.ndarray  # (L, 3) mm: the leg's line (before any lift)
    tip1: np.ndarray
    axis0: np.ndarray  # (L, 3)
    axis1: np.ndarray
    up: np.ndarray  # (L, 3): unit upward normal of the line in its vertical plane (0: vertical)
    lift: np.ndarray  # (L,) mm
    guard: np.ndarray  # (L,) bool: split where the tip dips below the line
    reorient: np.ndarray  # (L,) bool
    phi0: np.ndarray  # (L, 2) rad
    phi1: np.ndarray
    tol: np.ndarray  # (L,) mm
    axis_tol: np.ndarray  # (L,) rad
    length: np.ndarray  # (L,) mm: tool length
    pose: np.ndarray  # (L,) int
    f0: np.ndarray  # (L,)
    f1: np.ndarray
    final: np.ndarray  # (L,) bool: the leg's end is a block of its own (not the CL pose's)
    move: np.ndarray  # (L,) int: the move between cuts the leg belongs to
    #: (L,) mm, table-frame z: on a turn, the height the tip keeps above, free to swing between
    #: its ends (the envelope's top, the turn raised above it); NaN: the tip held still
    above: np.ndarray

    def height(self, leg: np.ndarray, u: np.ndarray) -> np.ndarray:
        """mm: how far the path is lifted above the line at fractions u of legs ``leg``: the full
        lift in the interior, reached along a ramp of slope 1/4 from each end."""
        size = np.linalg.norm(self.tip1[leg] - self.tip0[leg], axis=1)
        ramp = 4.0 * self.lift[leg]
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.lift[leg] * np.where(ramp > 0, np.minimum(1.0, np.minimum(u, 1.0 - u) * size / ramp), 0.0)

    def tip(self, leg: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The lifted path at fractions u of legs ``leg`` (mm, table frame)."""
        span = self.tip1[leg] - self.tip0[leg]
        return self.tip0[leg] + u[:, None] * span + self.height(leg, u)[:, None] * self.up[leg]

    def axis(self, leg: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The tool axis at fractions u of legs ``leg``."""
        angles = self.phi0[leg] + u[:, None] * (self.phi1[leg] - self.phi0[leg])
        turned = axis_from_angles(angles[:, 0], angles[:, 1])
        return np.where(self.reorient[leg][:, None], turned, slerp(self.axis0[leg], self.axis1[leg], u))

    def theta2(self, leg: np.ndarray, u: np.ndarray, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """theta2 (rad) to solve the point at fractions u near: on a reorientation its own angle, else
        the mean of the block ends' (``left``, ``right``)."""
        along = self.phi0[leg, 1] + u * (self.phi1[leg, 1] - self.phi0[leg, 1])
        return np.where(self.reorient[leg], -along, 0.5 * (left + right))


@dataclass(frozen=True)
class Split:
    """The block ends a split of legs made (K of them): leg, fraction u along it, the state."""

    leg: np.ndarray
    u: np.ndarray
    state: State
    unresolved: np.ndarray  # (L,) bool per leg


def split_legs(machine: Machine, legs: Legs, cone: float) -> Split:
    """Split every leg until the joint interpolation between its block ends stays within the
    leg's tolerances (and above its line where guarded), level by level, all legs at once.
    Returns the inserted block ends and each leg's own end where it is a block of its own."""
    n = len(legs.pose)
    leg, u = [np.arange(n), np.arange(n)], [np.zeros(n), np.ones(n)]
    states = [legs.start, legs.end]
    left, right = np.arange(n), np.arange(n, 2 * n)
    size = 2 * n
    unresolved = np.zeros(n, bool)
    for level in range(MAX_LEVELS + 1):
        if left.size == 0:
            break
        all_leg, all_u, every = np.concatenate(leg), np.concatenate(u), State.join(states)
        q, alpha = every.joints, every.result.alpha
        k, m = all_leg[left], len(left)
        free_turn = np.isfinite(legs.above[k])
        plain, turning = np.flatnonzero(~free_turn), np.flatnonzero(free_turn)
        rows = np.r_[np.repeat(plain, len(MEASURE)), np.repeat(turning, len(MEASURE_TURN))]
        f = np.r_[np.tile(MEASURE, len(plain)), np.tile(MEASURE_TURN, len(turning))]
        lo, hi = left[rows], right[rows]
        fk = forward_kinematics(machine, q[lo] + f[:, None] * (q[hi] - q[lo]), tool_length=legs.length[k][rows],
                                alpha_guess=alpha[lo] + f * (alpha[hi] - alpha[lo]))
        kk = k[rows]
        free = free_turn[rows]
        # a free turn is outside the envelope, above its top: its tip may go anywhere up there,
        # so a dip below the top splits it; its axis follows the rotary angles, a cone about the
        # table's axis, not the great circle of its ends. It may not sag below the lower of its
        # own ends by more than a rapid may (what a reader without the CL path judges a rapid by):
        # there it is cut at its lowest point, on its own joint-space line (the same path)
        tip_error = np.where(free, 0.0, distance_to_segment(fk.tip, every.tip[lo], every.tip[hi]))
        axis_error = np.where(free, 0.0, angle_to_arc(fk.axis, every.axis[lo], every.axis[hi]))
        dip = np.where(legs.guard[kk], dip_below(fk.tip, legs.tip0[kk], legs.tip1[kk], legs.up[kk]),
                       np.where(free, legs.above[kk] - fk.tip[:, 2], 0.0))
        sag_below_ends = np.where(free, np.fmin(every.tip[lo, 2], every.tip[hi, 2]) - fk.tip[:, 2], 0.0)
        bad = (~fk.reachable | ~(tip_error <= MARGIN * legs.tol[kk]) | ~(axis_error <= MARGIN * legs.axis_tol[kk])
               | (dip > DIP_SPLIT) | (sag_below_ends > MARGIN * legs.tol[kk]))
        # per free turn: where its tip is lowest, and whether it goes below the top anywhere
        lowest, below_top = np.full(m, 0.5), np.zeros(m, bool)
        if turning.size:
            z = fk.tip[len(plain) * len(MEASURE):, 2].reshape(len(turning), -1)
            lowest[turning] = MEASURE_TURN[np.argmin(np.nan_to_num(z, nan=np.inf), axis=1)]
            below_top[turning] = np.any(dip[len(plain) * len(MEASURE):].reshape(len(turning), -1) > DIP_SPLIT,
                                        axis=1)
        on_line = free_turn & ~below_top
        split = np.bincount(rows, bad, minlength=m) > 0
        # A block lifted less than fully at an end (on a ramp) sags below the line near that end
        # unless its sag is small against the lift: with the sag S (its largest deviation from
        # the chord) pointing straight down and parabolic, the chord lifted h_l and h_r at its
        # ends stays above the line where 4 S <= h_l + h_r.
        sag = np.zeros(m)
        np.maximum.at(sag, rows, tip_error)
        h_l, h_r = legs.height(k, all_u[left]), legs.height(k, all_u[right])
        on_ramp = legs.guard[k] & (np.minimum(h_l, h_r) < legs.lift[k])
        split |= on_ramp & (SAG_FACTOR * 4.0 * sag > h_l + h_r)
        split &= (all_u[right] - all_u[left]) > 1e-9
        counts = np.bincount(k[split], minlength=n)
        over = (level == MAX_LEVELS) | (np.bincount(all_leg, minlength=n) + counts > MAX_POINTS_PER_LEG)
        unresolved |= over & (counts > 0)
        split &= ~over[k]
        left, right, k, lowest, on_line = left[split], right[split], k[split], lowest[split], on_line[split]
        if left.size == 0:
            break
        mid_u = all_u[left] + np.where(on_line, lowest, 0.5) * (all_u[right] - all_u[left])
        mid = _solve(machine, legs.tip(k, mid_u), legs.axis(k, mid_u), legs.length[k],
                     legs.theta2(k, mid_u, q[left, 4], q[right, 4]), cone)
        if on_line.any():  # cut on the turn's own line, where its tip is lowest
            cut = np.flatnonzero(on_line)
            at = q[left[cut]] + lowest[cut, None] * (q[right[cut]] - q[left[cut]])
            mid = mid.scatter(cut, at_joints(machine, at, legs.length[k[cut]], cone))
        unreachable = mid.result.status == Status.UNREACHABLE
        unresolved[k[unreachable]] = True
        new = np.arange(size, size + len(k))
        size += len(k)
        leg.append(k)
        u.append(mid_u)
        states.append(mid)
        keep = ~unreachable
        left, right = np.r_[left[keep], new[keep]], np.r_[new[keep], right[keep]]
    ends = np.flatnonzero(legs.final)  # after the inserted block ends, the legs' own ends that are blocks
    return Split(np.concatenate([*leg[2:], ends]), np.concatenate([*u[2:], np.ones(len(ends))]),
                 State.join([*states[2:], legs.end.rows(ends)]), unresolved)


@dataclass(frozen=True)
class Moves:
    """K moves between cuts, each with one tool (``length`` mm): from ``start`` to ``end``, its
    blocks those of CL pose ``pose`` at fractions ``f0`` -> ``f1``; ``final``: the end is a
    block of its own (a joint position, a retract point), not the CL pose's."""

    start: State
    end: State
    length: np.ndarray
    pose: np.ndarray
    f0: np.ndarray
    f1: np.ndarray
    final: np.ndarray
    line: np.ndarray  # (K,) bool: may run on its straight line (else retract, reorient, approach)

    def rows(self, index: np.ndarray) -> Moves:
        return Moves(self.start.rows(index), self.end.rows(index), self.length[index], self.pose[index],
                     self.f0[index], self.f1[index], self.final[index], self.line[index])

    @staticmethod
    def join(moves: list[Moves]) -> Moves:
        return Moves(State.join([m.start for m in moves]), State.join([m.end for m in moves]),
                     *(np.concatenate([getattr(m, name) for m in moves])
                       for name in ("length", "pose", "f0", "f1", "final", "line")))


def _angles(state: State) -> np.ndarray:
    """(K, 2) the rotary angles (phi1, phi2) (rad) of the joints: alpha = theta1 + phi1, theta2 = -phi2."""
    return np.column_stack([state.result.alpha - state.joints[:, 3], -state.joints[:, 4]])


def _angle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return 2.0 * np.arcsin(np.clip(np.linalg.norm(u - v, axis=-1) / 2.0, 0.0, 1.0))


def keeps_its_pair(start: State, end: State, cone: float, samples: int = 33) -> np.ndarray:
    """(K,) bool: the spherical interpolation of the tool axis from each start to its end keeps
    theta2 continuous from the start's value to the end's (rad): the same angle pair, no whole
    turn more or less, and no pass through the pole cone inside the move, where theta2 would
    whip round (ends within the cone have a theta2 of choice)."""
    k = len(start.tip)
    u = np.linspace(0.0, 1.0, samples)
    axis = slerp(np.repeat(start.axis, samples, axis=0), np.repeat(end.axis, samples, axis=0),
                 np.tile(u, k)).reshape(k, samples, 3)
    defined = np.arctan2(np.hypot(axis[..., 0], axis[..., 1]), axis[..., 2]) > 2.0 * cone
    plus = -np.arctan2(axis[..., 0], -axis[..., 1])  # theta2 of angle pair +1 (pair -1: turned by pi)
    through_pole = np.any(~defined[:, 1:-1], axis=1) & defined[:, 0] & defined[:, -1]
    # undefined samples take the last defined value before them (the first defined one at the start)
    index = np.maximum.accumulate(np.where(defined, np.arange(samples), -1), axis=1)
    index = np.where(index < 0, np.argmax(defined, axis=1)[:, None], index)
    filled = np.take_along_axis(plus, index, axis=1)
    first = filled[:, 0]
    pair_shift = np.where(np.abs(wrap_angle(first - start.joints[:, 4])) <= np.pi / 2, 0.0, np.pi)
    begin = start.joints[:, 4] + wrap_angle(first + pair_shift - start.joints[:, 4])
    predicted = begin + np.sum(wrap_angle(np.diff(filled, axis=1)), axis=1)
    ends_well = ~defined[:, -1] | (np.abs(predicted - end.joints[:, 4]) < 1e-3)
    return ~through_pole & ends_well


#: A tool axis whose horizontal component is at most this is vertical (see :func:`envelope_exit`).
VERTICAL = 1e-12


@dataclass(frozen=True)
class Exit:
    """Where rays along tool axes leave the clearance envelope, one row per state (mm, table
    frame): ``point``, ``t`` mm along the unit axis from the tip, through a side face (``side``)
    or the top; ``top``: where the move goes on to, the point, or after a side exit straight above
    it at the envelope's top; ``down``: the ray would have to lower the tip to leave, toward the
    table under the part (refused)."""

    t: np.ndarray  # (K,) mm
    point: np.ndarray  # (K, 3) mm
    side: np.ndarray  # (K,) bool
    top: np.ndarray  # (K, 3) mm
    down: np.ndarray  # (K,) bool


def envelope_exit(lo: np.ndarray, hi: np.ndarray, tip: np.ndarray, axis: np.ndarray) -> Exit:
    """The exit of each ray tip + t axis (mm, table frame; unit axes (K, 3)) from the box lo -> hi
    ((3,) or (K, 3) mm, lo z may be -inf) by the slab method: the smallest t >= 0 with the point
    outside (0 for a tip outside already, on the boundary included). The box is convex: once the
    tip is out, so is every point further up the ray, and with it the whole tool, whose shank and
    holder lie up its axis from the tip. A tip beside the box (below its top) rises vertically from
    its exit to the top, which stays outside too: the box has no bottom."""
    lo, hi = np.broadcast_to(lo, tip.shape), np.broadcast_to(hi, tip.shape)
    # An axis (within rounding) vertical has no side to leave by: its rise would be its retract,
    # so it retracts to the top as the plane of the safe level had it, even from beside the box.
    vertical = np.hypot(axis[:, 0], axis[:, 1]) <= VERTICAL
    within = (tip > lo) & (tip < hi)
    inside = np.where(vertical, within[:, 2], np.all(within, axis=1))
    slab = np.where(vertical[:, None], [0.0, 0.0, 1.0], 1.0) * axis
    with np.errstate(divide="ignore", invalid="ignore"):
        t_face = np.where(slab > 0, (hi - tip) / slab, np.where(slab < 0, (lo - tip) / slab, np.inf))
    face = np.argmin(t_face, axis=1)
    t = np.where(inside, np.min(t_face, axis=1), 0.0)
    # the top face's t is (level - z) / axis z: the retract of the plane of the safe level, to the bit
    stuck = ~np.isfinite(t)  # a ray that never leaves (down through the open bottom)
    t = np.where(stuck, 0.0, t)
    point = tip + t[:, None] * axis
    side = np.where(inside, face != 2, tip[:, 2] < hi[:, 2]) & ~vertical & ~stuck
    top = np.where(side[:, None], np.column_stack([point[:, :2], hi[:, 2]]), point)
    return Exit(t, point, side, top, stuck | (t * axis[:, 2] < -SHORT))


def line_legs(moves: Moves, settings: SafeSettings) -> Legs:
    """One leg per move: the straight line from its start to its end (tip linear, axis by
    spherical interpolation), lifted half the rapid tolerance and guarded against dips."""
    k = len(moves.pose)
    up = upward_normal(moves.start.tip, moves.end.tip)
    # both ends above the envelope's top: nothing of the setup up there, the line is free (a
    # vertical one stays on its line: a retract)
    above = np.minimum(moves.start.tip[:, 2], moves.end.tip[:, 2]) >= settings.level
    vertical = np.all(up == 0, axis=1)
    lift = np.where(np.any(up != 0, axis=1), 0.5 * settings.rapid_tol, 0.0)
    return Legs(moves.start, moves.end, moves.start.tip, moves.end.tip, moves.start.axis, moves.end.axis, up, lift,
                np.ones(k, bool), np.zeros(k, bool), _angles(moves.start), _angles(moves.end),
                np.full(k, 0.5 * settings.rapid_tol), np.full(k, settings.rapid_axis_tol), moves.length, moves.pose,
                moves.f0, moves.f1, moves.final, np.arange(k),
                np.where(above & ~vertical, settings.level, np.nan))


def detour_legs(machine: Machine, moves: Moves, settings: SafeSettings, raised: np.ndarray | None = None
                ) -> tuple[Legs, np.ndarray]:
    """Up to six legs per move (mm and rad, table frame): retract along the start's tool axis out
    of the clearance envelope (:func:`envelope_exit`), rise vertically from a side exit to the
    envelope's top (the axis held), turn the axis there, travel at the top, descend vertically to
    the end's side exit, approach along the end's tool axis. Returns the legs and, per move,
    whether its start or end would have to lower the tool to leave the envelope (a tool axis
    pointing down).

    ``raised`` (per move, mm; NaN: not free): the move goes this far above the envelope's top, and
    its turn is one joint-space line, its tip free to swing above the top (split only where it
    would dip below it); without it the turn holds the tip still at the top."""
    a, b = moves.start, moves.end
    lo, hi = settings.envelope
    free = np.zeros(len(moves.pose), bool) if raised is None else np.isfinite(raised)
    if free.any():
        hi = np.repeat(hi[None], len(free), axis=0)
        hi[:, 2] += np.where(free, raised, 0.0)
    out_a, out_b = envelope_exit(lo, hi, a.tip, a.axis), envelope_exit(lo, hi, b.tip, b.axis)
    exit_a, exit_b, top_a, top_b = out_a.point, out_b.point, out_a.top, out_b.top
    phi_a, phi_b = _angles(a), _angles(b)
    retract, approach = out_a.t > SHORT, out_b.t > SHORT
    rise = np.linalg.norm(top_a - exit_a, axis=1) > SHORT
    descend = np.linalg.norm(top_b - exit_b, axis=1) > SHORT
    turn = np.any(np.abs(phi_b - phi_a) > 1e-9, axis=1)
    travel = np.linalg.norm(top_b - top_a, axis=1) > SHORT
    lengths, cone = moves.length, settings.cone
    # the waypoints; one with nothing after it is the end itself
    after_retract = _solve(machine, exit_a, a.axis, lengths, a.joints[:, 4], cone).where(
        rise | turn | travel | descend | approach, b)
    after_rise = _solve(machine, top_a, a.axis, lengths, a.joints[:, 4], cone).where(
        turn | travel | descend | approach, b)
    after_turn = _solve(machine, top_a, axis_from_angles(phi_b[:, 0], phi_b[:, 1]), lengths, b.joints[:, 4],
                        cone).where(travel | descend | approach, b)
    after_travel = _solve(machine, top_b, b.axis, lengths, b.joints[:, 4], cone).where(descend | approach, b)
    after_descend = _solve(machine, exit_b, b.axis, lengths, b.joints[:, 4], cone).where(approach, b)
    start_rise = after_retract.where(retract, a)
    start_turn = after_rise.where(rise, start_rise)
    start_travel = after_turn.where(turn, start_turn)
    start_descend = after_travel.where(travel, start_travel)
    start_approach = after_descend.where(descend, start_descend)
    present = np.column_stack([retract, rise, turn, travel, descend, approach])
    count = present.sum(axis=1)
    order = np.cumsum(present, axis=1) - 1  # the leg's place in its move
    pieces = []
    for kind, (start, end, tip0, tip1) in enumerate((
            (a, after_retract, a.tip, exit_a), (start_rise, after_rise, exit_a, top_a),
            (start_turn, after_turn, top_a, top_a), (start_travel, after_travel, top_a, top_b),
            (start_descend, after_descend, top_b, exit_b), (start_approach, b, exit_b, b.tip))):
        rows = np.flatnonzero(present[:, kind])
        m = len(rows)
        place, total = order[rows, kind], count[rows]
        span = moves.f1[rows] - moves.f0[rows]
        guard = kind == 3  # the travel, kept on its line; the vertical rise and descent lie beside the part
        up = upward_normal(tip0[rows], tip1[rows]) if guard else np.zeros((m, 3))
        # retract and approach leave and enter the cut's surroundings: the feed tolerances; the
        # rest is outside the envelope, at least the clearance from the part: the rapid ones
        rapid = kind in (1, 2, 3, 4)
        pieces.append(Legs(
            start.rows(rows), end.rows(rows), tip0[rows], tip1[rows], start.axis[rows], end.axis[rows], up,
            np.where(np.any(up != 0, axis=1), 0.5 * settings.rapid_tol, 0.0), np.full(m, guard),
            np.full(m, kind == 2), phi_a[rows], phi_b[rows],
            np.full(m, 0.5 * settings.rapid_tol if rapid else settings.tol),
            np.full(m, settings.rapid_axis_tol if rapid else settings.axis_tol), lengths[rows], moves.pose[rows],
            moves.f0[rows] + span * place / total, moves.f0[rows] + span * (place + 1) / total,
            (place < total - 1) | moves.final[rows], rows,
            np.where(free[rows] & (kind == 2), settings.level, np.nan)))
    legs = Legs(*(State.join([getattr(p, name) for p in pieces]) if name in ("start", "end")
                  else np.concatenate([getattr(p, name) for p in pieces]) for name in _LEG_FIELDS))
    return legs, out_a.down | out_b.down


_LEG_FIELDS = ("start", "end", "tip0", "tip1", "axis0", "axis1", "up", "lift", "guard", "reorient", "phi0", "phi1",
               "tol", "axis_tol", "length", "pose", "f0", "f1", "final", "move", "above")


#: A free turn goes up by its dip times this, and RAISE_EXTRA mm more (the dip changes as it rises).
RAISE_FACTOR, RAISE_EXTRA = 1.25, 1.0
#: Raises tried before a turn holds its tip still instead.
RAISE_TRIES = 6


def _turn_dips(machine: Machine, legs: Legs, level: float, moves: int) -> np.ndarray:
    """(moves,) mm: per move, how far its turn's joint-space line (one block) takes the tip below
    ``level`` (table-frame z; -inf without a turn, +inf where a waypoint of the move is not
    within reach)."""
    dip = np.full(moves, -np.inf)
    turn = np.flatnonzero(legs.reorient)
    if turn.size == 0:
        return dip
    q0, q1 = legs.start.joints[turn], legs.end.joints[turn]
    rows = np.repeat(np.arange(len(turn)), len(MEASURE_TURN))
    f = np.tile(MEASURE_TURN, len(turn))
    fk = forward_kinematics(machine, q0[rows] + f[:, None] * (q1 - q0)[rows], tool_length=legs.length[turn][rows])
    below = np.where(fk.reachable, level - fk.tip[:, 2], np.inf)
    dip[legs.move[turn]] = np.max(below.reshape(len(turn), -1), axis=1)
    reached = np.ones(moves, bool)  # every waypoint of the move, raised, within reach
    np.logical_and.at(reached, legs.move, (legs.start.result.status == Status.OK)
                      & (legs.end.result.status == Status.OK))
    return np.where(reached, dip, np.inf)


def _free_turns(machine: Machine, moves: Moves, settings: SafeSettings) -> np.ndarray:
    """(K,) mm: how far above the envelope's top each move turns with its tip free, one joint-space
    line (NaN: it holds the tip still at the top, where no raise up to RAISE_TRIES keeps the line
    above the top, or the raised points are out of reach).

    A turn held still at the tip is many short rotary blocks: LinuxCNC runs each to rest
    (docs/linuxcnc.md), 0.2 s apiece on the impeller's; turned in one block, the table turns at
    its own acceleration, and above the envelope the tip has nowhere it must be."""
    count = len(moves.pose)
    raised = np.zeros(count)
    chosen = np.full(count, np.nan)
    todo = np.arange(count)
    for _ in range(RAISE_TRIES):
        legs, _down = detour_legs(machine, moves.rows(todo), settings, raised[todo])
        dip = _turn_dips(machine, legs, settings.level, len(todo))
        done = dip <= 0.0
        chosen[todo[done]] = raised[todo[done]]
        todo, dip = todo[~done & np.isfinite(dip)], dip[~done & np.isfinite(dip)]
        if todo.size == 0:
            break
        raised[todo] += RAISE_FACTOR * dip + RAISE_EXTRA
    return np.where(np.isfinite(chosen) & (chosen >= 0), chosen, np.nan)


@dataclass(frozen=True)
class Between:
    """What :func:`between_cuts` made of a part: its blocks with the moves between cuts, and the
    problems found (CL pose index, reason)."""

    blocks: Blocks
    problems: tuple[tuple[int, str], ...]


def _state(blocks: Blocks, index: np.ndarray) -> State:
    return State(blocks.result.rows(index), blocks.tip[index], blocks.axis[index])


def _above(machine: Machine, state: State, lengths: np.ndarray, settings: SafeSettings, extra: np.ndarray
           ) -> State:
    """The state where each tool leaves the clearance envelope with its top raised by ``extra``
    (mm): up its axis out of it, then, from a side, vertically to the raised top (table frame)."""
    hi = np.repeat(settings.envelope[1:], len(extra), axis=0)
    hi[:, 2] = settings.level + extra
    out = envelope_exit(settings.envelope[0], hi, state.tip, state.axis)
    return _solve(machine, out.top, state.axis, lengths, state.joints[:, 4], settings.cone)


def _moves_between(machine: Machine, poses: MachinePoses, blocks: Blocks, settings: SafeSettings,
                   before: Blocks | None) -> tuple[list[Moves], list[Blocks]]:
    """The moves between cuts that :func:`between_cuts` makes, each from its start to its end
    state (no legs yet): from home into the program's first pose, away from a pose before a tool
    change or after the program's last pose, into every rapid's pose and the first pose after a
    tool change; and the blocks that position the machine before the program, if any."""
    n = len(poses)
    ext = blocks if before is None else before.then(blocks)
    skip = 0 if before is None else 1
    lengths = poses.tool_length
    changes = np.zeros(n + 1, bool)
    changes[[e.index for e in poses.events if isinstance(e, ToolChange) and 0 < e.index < n]] = True
    own = np.flatnonzero((ext.fraction == 1) & ~ext.between)
    known = np.all(np.isfinite(ext.joints), axis=1)
    cone = settings.cone
    moves: list[Moves] = []
    extra: list[Blocks] = []
    one = np.ones(1)

    def single(start: State, finish: State, pose: int, f0: float, f1: float, final: bool) -> Moves:
        return Moves(start, finish, lengths[[pose]], np.array([pose]), f0 * one, f1 * one, np.array([final]),
                     np.zeros(1, bool))

    # the program's start: from home (or over the first pose), positioned there first
    if before is None and own.size and ext.pose[own[0]] == 0 and known[own[0]]:
        first = _state(ext, own[:1])
        start = (at_joints(machine, settings.home[None], lengths[:1], cone) if settings.home is not None
                 else _above(machine, first, lengths[:1], settings, np.zeros(1)))
        extra.append(Blocks(start.tip, start.axis, np.zeros(1, int), np.zeros(1), start.result, np.zeros(0, int),
                            np.ones(1, bool)))
        moves.append(single(start, first, 0, 0.0, 1.0, False))
    # leaving a pose for a tool change after it, or home after the program's last pose (old tool)
    leave_to: dict[int, np.ndarray] = {}
    leaving = own[own >= skip]
    leaving = leaving[known[leaving] & (changes[ext.pose[leaving] + 1] | (ext.pose[leaving] == n - 1))]
    for k in leaving:  # the tool changes and the program's end: a few per program
        pose = int(ext.pose[k])
        here = _state(ext, np.array([k]))
        if pose == n - 1:
            target = settings.home
            if target is None:
                target = _above(machine, here, lengths[[pose]], settings, np.zeros(1)).joints[0]
        else:
            target = settings.tool_change
            if target is None:  # high enough that the new tool's tip is at the safe level too
                longer = max(float(lengths[pose + 1] - lengths[pose]), 0.0) * here.axis[:, 2]
                target = _above(machine, here, lengths[[pose]], settings, longer).joints[0]
        leave_to[pose + 1] = target
        moves.append(single(here, at_joints(machine, target[None], lengths[[pose]], cone), pose, 1.0, 2.0, True))
    # into every rapid's pose, and into the first pose after a tool change (from where it happened)
    into = own[(own >= max(skip, 1))]
    into = into[(poses.rapid[ext.pose[into]] | changes[ext.pose[into]]) & known[into] & known[into - 1]]
    if into.size:
        pose = ext.pose[into]
        retooled = changes[pose]
        start_joints = ext.joints[into - 1].copy()
        for i in np.flatnonzero(retooled):  # the tool was changed where the move away from the cut ended
            start_joints[i] = leave_to.get(int(pose[i]), start_joints[i])
        start = _state(ext, into - 1)
        if retooled.any():  # the new tool's tip and axis where the tool was changed
            rows = np.flatnonzero(retooled)
            start = start.scatter(rows, at_joints(machine, start_joints[rows], lengths[pose[rows]], cone))
        end = _state(ext, into)
        line = ~retooled & (_angle(start.axis, end.axis) <= settings.max_turn) & keeps_its_pair(start, end, cone)
        count = len(into)
        moves.append(Moves(start, end, lengths[pose], pose, np.zeros(count), np.ones(count), np.zeros(count, bool),
                           line))
    return moves, extra


def between_cuts(machine: Machine, poses: MachinePoses, blocks: Blocks, settings: SafeSettings, *,
                 before: Blocks | None) -> Between:
    """The moves between cuts of a part (see the module docstring): ``blocks`` those of some poses
    of the program's ``poses`` (pose indices of the whole program), ``before`` the last block of
    the part before (None for the first part)."""
    moves, extra = _moves_between(machine, poses, blocks, settings, before)
    cone = settings.cone
    if not moves:
        return Between(blocks, ())
    every = Moves.join(moves)
    problems: list[tuple[int, str]] = []
    known_ends = (np.all(np.isfinite(every.start.joints), axis=1) & np.all(np.isfinite(every.end.joints), axis=1)
                  & np.all(np.isfinite(every.start.tip), axis=1) & np.all(np.isfinite(every.end.tip), axis=1))
    for m in np.flatnonzero(~known_ends):
        problems.append((int(every.pose[m]), "the move between cuts starts or ends out of reach (the machine file's "
                                             "positions, or a retract above the safe level)"))
    every = every.rows(np.flatnonzero(known_ends))
    straight = np.flatnonzero(every.line)
    lines = line_legs(every.rows(straight), settings)
    done = split_legs(machine, lines, cone)
    failed = np.zeros(len(straight), bool)
    np.logical_or.at(failed, lines.move[done.leg], done.state.result.status != Status.OK)
    failed |= done.unresolved
    keep = ~failed[lines.move[done.leg]]
    pieces = [(lines, done, keep)]
    detour = np.r_[np.flatnonzero(~every.line), straight[failed]]
    if detour.size:
        around = every.rows(detour)
        legs, down = detour_legs(machine, around, settings, _free_turns(machine, around, settings))
        split = split_legs(machine, legs, cone)
        pieces.append((legs, split, np.ones(len(split.leg), bool)))
        for m in np.flatnonzero(down):
            problems.append((int(every.pose[detour[m]]), "the move between cuts cannot leave the clearance "
                                                         "envelope: the tool axis points down, and retracting "
                                                         "along it would lower the tool toward the table"))
        for m in np.unique(legs.move[split.unresolved]):
            problems.append((int(every.pose[detour[m]]), f"the move between cuts cannot be kept within "
                                                         f"{settings.rapid_tol:g} mm of its path"))
    for legs, split, mask in pieces:
        leg, u = split.leg[mask], split.u[mask]
        extra.append(Blocks(split.state.tip[mask], split.state.axis[mask], legs.pose[leg],
                            legs.f0[leg] + u * (legs.f1[leg] - legs.f0[leg]), split.state.result.rows(mask),
                            np.zeros(0, int), np.ones(len(leg), bool)))
    # the block that ends a move into a CL pose is the last of that move (after a tool change, or
    # at the program's start, a feed pose's own block is the approach's last)
    ends_a_move = np.zeros(len(blocks.pose), bool)
    ends_a_move[np.searchsorted(blocks.pose, every.pose[every.f1 == 1.0])] = True
    merged = replace(blocks, between=blocks.between | (ends_a_move & (blocks.fraction == 1)))
    for more in extra:
        merged = merged.then(more)
    order = np.lexsort((merged.fraction, merged.pose))
    return Between(merged.rows(order), tuple(problems))
