"""Where to clamp the part: the work offset with the most room to every limit of the machine.

The VERNE's workspace is no box: which part zeros (work offsets, mm, part zero in the table
frame) let a whole program run depends on every pose's tool axis and tool length. The search
maximises the program's smallest *headroom* (see :mod:`verne_post.checks.headroom`: every limit and
singularity margin as a comparable fraction, 0 at the limit):

1. Screen (fast, vectorised): a few hundred CL poses (the extreme ones in 26 directions, per
   tool, plus an even spread) through the working-mode kernel, the better of both tool-axis
   angle pairs, at a coarse grid of offsets over the machine's reach; then a pattern search
   (26 neighbours, step halving) from the best grid points, with the angle pairs the branch
   stage chooses at the best one (the better pair is not always the one the program takes).
2. Verify: the whole program at the best offset through the checks of ``check`` (IK and branch
   choice, linearisation, every check along the motion). Poses that come out worse than the
   screen knew are added to the screened set and the search resumes (at most a few rounds).
3. Room: along -x, +x, -y, +y, -z, +z, how far the part may move and still run (bisection on
   the screened poses, each end confirmed by the full checks, which stop at the first failure
   they find): the setter's clamping tolerance.

Everything is deterministic (fixed grids, no random numbers). mm and the table frame
throughout; the headroom is a fraction.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial
from typing import Any

import numpy as np

from ..api import Status, classify, joint_bounds, placeable, pose_margins
from ..bodies.world import World, cutting
from ..checks.collision import tool_stacks, tool_use_of_poses
from ..checks.headroom import UNREACHABLE, describe, headroom, smallest
from ..checks.limits import Violation, motion_samples
from ..checks.stage import Checked, check_poses
from ..kinematics import machine_ik_working, margins, module_ik_working
from ..machine import Machine
from ..motion.branch import solve_path
from ..motion.poses import MachinePoses
from ..options import PostOptions
from ..processes.helpers import Pool

AXES = "xyz"
#: Room is found to this resolution (mm); the reported room is the last distance that runs.
ROOM_RESOLUTION = 0.25
ROOM_LIMIT = 4000.0  # mm: farther than any VERNE workspace reaches
SCREEN_POSES = 300
COARSE_POSES = 120
FINEST_STEP = 1.0  # mm: the pattern search stops at this step
FINE_FROM = 16.0  # mm: smaller steps of the pattern search use the larger screen
IMPROVEMENT = 1e-5  # headroom: smaller gains do not move the pattern search
ROUNDS = 4  # verify / enrich / search rounds at most


@dataclass(frozen=True)
class Placement:
    """The chosen work offset and how good it is (mm, table frame; headroom as a fraction)."""

    offset: tuple[float, float, float]  # part zero in the table frame, mm
    feasible: bool  # the whole program passes every check at ``offset``
    margin: float  # smallest headroom over the program (0 at a limit, 1 as far as the machine gets)
    limit: str  # the constraint with that smallest headroom
    line: int  # CL line where it occurs
    # per x, y, z: how far the part may move towards - and + (mm); None where not asked for (the
    # room certifies every distance with the full checks: about 40 of them on the impeller)
    room: tuple[tuple[float, float], ...] | None
    reason: str  # why no offset works ("" when feasible)
    screened: int  # candidate offsets screened
    seconds: float
    collisions: tuple[Violation, ...] = ()  # the bodies that meet at the best offset, where that is why


    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (mm)."""
        return {
            "work_offset_mm": list(self.offset),
            "feasible": self.feasible,
            "smallest_headroom": self.margin,
            "limiting_constraint": self.limit,
            "line": self.line,
            "room_mm": None if self.room is None else {axis: {"minus": lo, "plus": hi}
                                                       for axis, (lo, hi) in zip(AXES, self.room, strict=True)},
            "reason": self.reason or None,
            "offsets_screened": self.screened,
            "seconds": self.seconds,
        }

    def header(self) -> tuple[str, ...]:
        """G-code header lines: how the offset was chosen and the room around it (where found)."""
        chosen = (f"WORK OFFSET CHOSEN BY VERNE-POST PLACE FOR THE MOST HEADROOM TO EVERY LIMIT: SMALLEST "
                  f"{self.margin:.3f} AT CL LINE {self.line}, {self.limit.upper()}")
        if self.room is None:
            return chosen, "ROOM AROUND IT NOT MEASURED ('VERNE-POST PLACE' OR --ROOM MEASURES IT)"
        room = " ".join(f"{a.upper()} -{lo:.1f}/+{hi:.1f}" for a, (lo, hi) in zip(AXES, self.room, strict=True))
        return chosen, f"PART MAY MOVE BY {room} MM AND STILL RUN"


# ----------------------------------------------------------------------------- screening


@dataclass(frozen=True)
class _Points:
    """The points the screen may use: the CL poses, and after a full check its block ends
    (CL poses and the points linearisation inserted on the moves into them), with what the
    branch stage chose there. Tips mm in the part frame."""

    pose: np.ndarray  # (P,) CL pose index of each point, non-decreasing
    tip: np.ndarray  # (P, 3) mm, part frame
    axis: np.ndarray  # (P, 3)
    length: np.ndarray  # (P,) mm
    theta2: np.ndarray  # (P,) rad
    pair: np.ndarray  # (P,) angle pair the branch stage chose (+1, -1), 0 before any full check
    run: np.ndarray  # (P,) runs as in verne_post.motion.branch (one pair each): split at sequences and pole-cone edges
    in_cone: np.ndarray  # (P,) theta2 interpolated by the branch stage: no choice of pair

    def screen(self, rows: np.ndarray) -> _Points:
        """The points of CL poses ``rows``: what the fast screen evaluates."""
        k = np.isin(self.pose, rows)
        return _Points(*(getattr(self, name)[k] for name in _Points.__dataclass_fields__))

    def paired(self, machine: Machine, poses: MachinePoses, offset: np.ndarray) -> _Points:
        """The CL poses (``self`` holds them all, one point each) with the angle pairs the branch
        stage chooses at ``offset`` (mm): the screen then takes the pairs the program will."""
        solved = solve_path(machine, poses.tip + offset, poses.axis, poses.sequence, tool_length=poses.tool_length,
                            cone=np.radians(machine.pole.cone))
        pair = np.where(solved.in_cone, 1, solved.result.pair).astype(int)
        return replace(self, theta2=np.nan_to_num(solved.result.joints[:, 4]), pair=pair)

    def chosen(self, checked: Checked, offset: np.ndarray) -> _Points:
        """The block ends of a full check at ``offset`` (every CL pose has one) and the branch
        stage's choices there; ``self`` must hold every CL pose."""
        # the moves between cuts are not the program's points: they follow the part (or the
        # machine's fixed positions) by the safe-motion stage's rules, checked in full each time
        blocks = checked.blocks.rows(np.flatnonzero(~checked.blocks.between))
        result = blocks.result
        pose = blocks.pose
        first = np.searchsorted(self.pose, pose)  # a point of the same CL pose: its length and run
        in_cone = checked.path.in_cone[pose]
        # In the cone the pair only says which theta2 was taken: the screen's "+1" is that theta2.
        pair = np.where(in_cone, 1, result.pair).astype(int)
        return _Points(pose, blocks.tip - offset, blocks.axis, self.length[first], np.nan_to_num(result.joints[:, 4]),
                       pair, self.run[first], in_cone)


def _points_of(machine: Machine, poses: MachinePoses) -> _Points:
    in_cone = np.arctan2(np.hypot(poses.axis[:, 0], poses.axis[:, 1]), poses.axis[:, 2]) < max(
        np.radians(machine.pole.cone), 1e-12)
    run = np.cumsum(np.r_[True, (poses.sequence[1:] != poses.sequence[:-1]) | (in_cone[1:] != in_cone[:-1])])
    n = len(poses)
    return _Points(np.arange(n), poses.tip, poses.axis, poses.tool_length, np.zeros(n), np.zeros(n, int), run,
                   in_cone)


#: The 26 neighbours of a point of a cubic grid (pattern search, extreme poses).
_DIRECTIONS = np.array([d for d in np.ndindex(3, 3, 3) if d != (1, 1, 1)], dtype=float) - 1.0


def _spread(poses: MachinePoses, machine: Machine, size: int) -> np.ndarray:
    """Pose indices: per tool length the extremes of the tip and of the platform centre (tip +
    Delta axis) in 26 directions and of the tilt, then an even spread up to ``size``."""
    picked = [np.linspace(0, len(poses) - 1, size).round().astype(int)]
    tilt = np.arctan2(np.hypot(poses.axis[:, 0], poses.axis[:, 1]), poses.axis[:, 2])
    for length in np.unique(poses.tool_length):
        rows = np.flatnonzero(poses.tool_length == length)
        delta = machine.geometry.spindle_nose + length
        for points in (poses.tip[rows], poses.tip[rows] + delta * poses.axis[rows]):
            picked.append(rows[np.argmax(points @ _DIRECTIONS.T, axis=0)])
        picked.append(rows[[np.argmin(tilt[rows]), np.argmax(tilt[rows])]])
    return np.unique(np.concatenate(picked))


def _smallest_headroom(machine: Machine, tip: np.ndarray, axis: np.ndarray, length: np.ndarray, pair: np.ndarray,
                       theta2: np.ndarray, exact: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N,) smallest headroom of tool poses (tips mm, table frame; tool lengths mm) with angle
    pairs ``pair`` (+1, -1); on the pole theta2 (rad), turned by pi for pair -1. With the joints
    (N, 5) mm, rad and the platform's tilt (N,) rad found (NaN where out of reach)."""
    values = np.full((len(tip), 9), np.nan)
    joints, alpha = np.full((len(tip), 5), np.nan), np.full(len(tip), np.nan)
    at_pole = np.where(pair > 0, theta2, theta2 + np.pi)
    for value in np.unique(length):
        rows = np.flatnonzero(length == value)
        geom = machine.kinematic_geometry(float(value))
        with np.errstate(invalid="ignore", divide="ignore"):
            ik = machine_ik_working(geom, tip[rows], axis[rows], pair=pair[rows], theta2_at_pole=at_pole[rows],
                                    exact_fallback=exact)
            ok = ik.reachable
            values[rows[ok]] = headroom(machine, ik.joints[ok], margins(geom, ik.joints[ok], ik.platform[ok],
                                                                        ik.alpha[ok]))
        joints[rows], alpha[rows] = ik.joints, ik.alpha
    return smallest(values)[0], joints, alpha


def _screen_headroom(machine: Machine, screen: _Points, offsets: np.ndarray, exact: bool = False) -> np.ndarray:
    """(K, S) smallest headroom of each screened pose at each offset (K, 3).

    Like the branch stage, a pose takes the angle pair chosen before (``screen.pair``) while
    that runs, else the other one; where no choice is known yet, the better of the two. On the
    pole the two choices are theta2 and theta2 + pi.
    """
    k, s = len(offsets), len(screen.pose)
    tip = (screen.tip[None] + offsets[:, None]).reshape(-1, 3)
    axis = np.broadcast_to(screen.axis, (k, s, 3)).reshape(-1, 3)
    length = np.tile(screen.length, k)
    theta2 = np.tile(screen.theta2, k)

    def found(pair: np.ndarray, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        return _smallest_headroom(machine, tip[rows], axis[rows], length[rows], pair, theta2[rows], exact)[0]

    if not np.any(screen.pair):
        return np.maximum(found(np.ones(k * s)), found(-np.ones(k * s))).reshape(k, s)
    # One pair per run: the chosen one while it runs throughout, else the other; neither: the
    # run fails (the branch stage would switch pairs mid-cut). In the cone there is no choice.
    starts = np.flatnonzero(np.r_[True, screen.run[1:] != screen.run[:-1]])
    counts = np.diff(np.r_[starts, s])
    chosen = np.tile(screen.pair, k)
    preferred = found(chosen).reshape(k, s)
    preferred_runs = np.repeat(np.minimum.reduceat(preferred, starts, axis=1), counts, axis=1) >= 0
    # The other pair only matters in the runs off the pole where the chosen one fails.
    other = np.full(k * s, UNREACHABLE)
    rows = np.flatnonzero(~preferred_runs & ~screen.in_cone)
    other[rows] = found(-chosen[rows], rows)
    other = other.reshape(k, s)
    other_runs = np.repeat(np.minimum.reduceat(other, starts, axis=1), counts, axis=1) >= 0
    best = np.where(preferred_runs | screen.in_cone | ~other_runs, preferred, other)
    return np.where(preferred_runs | other_runs | screen.in_cone, best, np.minimum(best, -1e-9))


def _score(room: np.ndarray) -> np.ndarray:
    """One number per offset from (K, S) headrooms: the smallest where every pose runs, else
    minus the share of poses that fail (so the search is led towards feasibility)."""
    failing = np.mean(room < 0, axis=1)
    return np.where(failing > 0, -failing, np.min(room, axis=1))


def _scores(machine: Machine, screen: _Points, offsets: np.ndarray, seat: _Seat | None) -> np.ndarray:
    """:func:`_score` of offsets (K, 3) mm on ``screen``; an offset that puts the part off the
    table (overhang mm > 0, :meth:`_Seat.overhang`) below every other, the less the overhang the
    better, scored by that alone without the kinematics (most of the coarse grid over the
    machine's reach puts the part beside the table)."""
    if seat is None:
        return _score(_screen_headroom(machine, screen, offsets))
    overhang = seat.overhang(offsets)
    score = -1.0 - overhang / 1e4
    on = np.flatnonzero(overhang <= 0)
    if on.size:
        score[on] = _score(_screen_headroom(machine, screen, offsets[on]))
    return score


@dataclass(frozen=True)
class _Seat:
    """The part's footprint (mm, part frame: the setup's box, else the feed points') and the
    table's top face (table frame), for :func:`_overhang`; None where bodies are not checked."""

    lo: np.ndarray
    hi: np.ndarray
    radius: float
    top: float

    @classmethod
    def of(cls, machine: Machine, poses: MachinePoses) -> _Seat | None:
        if not machine.bodies.check:
            return None
        box = poses.setup.bounds()
        if box is None:  # the part's material under its deepest cut: safe.clearance at least
            feed = poses.tip[~poses.rapid] if (~poses.rapid).any() else poses.tip
            box = np.array([feed.min(axis=0) - [0.0, 0.0, machine.safe.clearance], feed.max(axis=0)])
        table = machine.bodies.table
        return cls(box[0], box[1], 0.5 * table.diameter, table.top)

    def overhang(self, offsets: np.ndarray) -> np.ndarray:
        """(K,) mm: how far the part at each offset (K, 3) lies off the table's top face (beyond
        its rim, or below its face); 0 where it sits on it."""
        corners = np.array([[x, y] for x in (self.lo[0], self.hi[0]) for y in (self.lo[1], self.hi[1])])
        rim = np.linalg.norm(offsets[:, None, :2] + corners[None], axis=2).max(axis=1) - self.radius
        below = self.top - (offsets[:, 2] + self.lo[2])
        return np.maximum(np.maximum(rim, below), 0.0)


def _search_box(machine: Machine, poses: MachinePoses) -> tuple[np.ndarray, np.ndarray]:
    """Range of offsets (mm) for the coarse grid: the tips' box inside the VERNE's reach.

    Reach (table frame, tool along the table normal, any rotary angle): within the platform
    positions the parallel module reaches, |x|, |y| up to about 1000 mm, and z between the
    platform's lowest and highest tip height for the program's tool lengths.
    """
    g = machine.geometry
    radius = 1000.0
    delta = g.spindle_nose + poses.tool_length
    # Platform z in the base frame (z down) spans about 780..2100 mm; the tip z in the table
    # frame is da + dt - zP - Delta for a vertical tool on a level table.
    low = g.da + g.dt - 2100.0 - float(np.max(delta))
    high = g.da + g.dt - 780.0 - float(np.min(delta))
    lo_tip, hi_tip = poses.tip.min(axis=0), poses.tip.max(axis=0)
    lower = np.array([-radius, -radius, low]) - lo_tip
    upper = np.array([radius, radius, high]) - hi_tip
    centre = (lower + upper) / 2.0
    return np.minimum(lower, centre), np.maximum(upper, centre)


def _grid(lower: np.ndarray, upper: np.ndarray, counts: tuple[int, int, int]) -> np.ndarray:
    axes = [np.linspace(lo, hi, n) for lo, hi, n in zip(lower, upper, counts, strict=True)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def _pattern_search(machine: Machine, coarse: _Points, fine: _Points, starts: np.ndarray, step: float,
                    tick: Callable[[], None], seat: _Seat | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """Maximise the score from each start (B, 3): move to the best of the 26 neighbours at
    ``step`` (mm) while that improves, else halve the step, down to FINEST_STEP. Steps of
    FINE_FROM mm and more use the ``coarse`` screen, smaller ones the ``fine`` one. Returns
    (offsets, scores on the fine screen) best first, and the number of offsets screened."""
    current = starts.astype(float)
    steps = np.full(len(current), step)
    evaluations = 0
    for screen, smallest_step in ((coarse, FINE_FROM), (fine, FINEST_STEP)):
        score = _scores(machine, screen, current, seat)
        while np.any(steps >= smallest_step):
            active = np.flatnonzero(steps >= smallest_step)
            trial = (current[active, None] + steps[active, None, None] * _DIRECTIONS[None]).reshape(-1, 3)
            scores = _scores(machine, screen, trial, seat).reshape(len(active), -1)
            evaluations += len(trial)
            best = np.argmax(scores, axis=1)
            better = scores[np.arange(len(active)), best] > score[active] + IMPROVEMENT
            moved = active[better]
            current[moved] = trial.reshape(len(active), -1, 3)[better, best[better]]
            score[moved] = scores[better, best[better]]
            # A step that paid off is tried twice as long next time (up to the first), else halved.
            steps[moved] = np.minimum(steps[moved] * 2.0, step)
            steps[active[~better]] /= 2.0
            tick()
    order = np.argsort(-score, kind="stable")
    return current[order], score[order], evaluations


# ----------------------------------------------------------------------------- full checks


@dataclass(frozen=True)
class _Verdict:
    """The whole program at one offset."""

    checked: Checked
    margin: float  # smallest headroom over block ends and motion samples
    pose: int  # CL pose (index) at the smallest headroom
    limit: str
    worst: np.ndarray  # CL pose indices of the lowest headrooms (to add to the screen)

    @property
    def runs(self) -> bool:
        return not self.checked.violations


def _verify(machine: Machine, poses: MachinePoses, offset: np.ndarray, options: PostOptions) -> _Verdict:
    """The full checks of the program (poses at work offset 0) at ``offset`` (mm), with the
    smallest headroom over block ends and motion samples and the poses to screen next."""
    shifted = poses.shifted(offset)
    return _verdict(machine, poses, shifted, check_poses(machine, shifted, options))


def _confirm(machine: Machine, poses: MachinePoses, offset: np.ndarray, options: PostOptions
             ) -> tuple[np.ndarray | None, bool, _Ends | None]:
    """The room's full check at ``offset`` (mm): (None where the program runs, else the CL poses
    to screen next; whether the screen of CL poses can see why: False where only bodies meet; the
    block ends of the CL lines where it fails, for the screen of ends). It stops at the first
    failure (see :func:`verne_post.checks.stage.check_poses`)."""
    shifted = poses.shifted(offset)
    checked = check_poses(machine, shifted, options, first_failure=True)
    if not checked.violations:
        return None, True, None
    screenable = any(v.kind != "collision" for v in checked.violations)
    ends = np.flatnonzero(np.isin(shifted.line[checked.blocks.pose], [v.line for v in checked.violations]))
    ends = np.unique(np.r_[ends, np.maximum(ends - 1, 0)])  # each block's start too
    return _verdict(machine, poses, shifted, checked).worst, screenable, _Ends.of(machine, poses, checked, offset, ends)


def _verdict(machine: Machine, poses: MachinePoses, shifted: MachinePoses, checked: Checked) -> _Verdict:
    """A full check's smallest headroom and the poses to screen next; ``shifted``: the poses
    checked, ``poses`` the same at work offset 0."""
    blocks = checked.blocks
    lengths = shifted.tool_length[blocks.pose]
    along = motion_samples(machine, blocks.result, checked.rapid, lengths, shifted.line[blocks.pose])
    joints = np.concatenate([blocks.joints, along.joints])
    room = np.concatenate([headroom(machine, blocks.joints, blocks.result.margins),
                           headroom(machine, along.joints, along.margins)])
    # The moves between cuts must run (their violations count), but their headroom is not the
    # placement's aim: home and the tool-change position sit where the machine file puts them,
    # whatever the offset.
    between = np.r_[blocks.between, blocks.between[along.block]]
    room[between] = np.inf
    value, which = smallest(room)
    # Motion samples between blocks m - 1 and m belong to the CL pose of block m.
    pose = np.concatenate([blocks.pose, blocks.pose[along.block]])
    k = int(np.argmin(value))
    order = np.argsort(value, kind="stable")
    worst = np.unique(np.concatenate([pose[order[:40]], pose[value < 0]]))
    bad = np.flatnonzero(np.isin(poses.line, [v.line for v in checked.violations]))
    worst = np.union1d(worst, bad)
    # A cut that needs both angle pairs fails as a whole: screen it (at most 400 poses of each).
    branch_lines = [v.line for v in checked.violations if v.kind == "branch"]
    for sequence in np.unique(poses.sequence[np.isin(poses.line, branch_lines)]):
        rows = np.flatnonzero(poses.sequence == sequence)
        worst = np.union1d(worst, rows[np.linspace(0, len(rows) - 1, min(len(rows), 400)).astype(int)])
    limit = describe(machine, joints[k], int(which[k]))
    return _Verdict(checked, float(value[k]), int(pose[k]), limit, worst)


# ----------------------------------------------------------------------------- room


#: The room's screen of block ends takes, of every ENDS_STRIDE ends of the cuts at the chosen
#: offset, the one whose blocks come nearest to a body, where that is under ENDS_CLEARANCE mm
#: (clear_motion's cap: every end it did not call far). Where a full check then fails at some CL
#: line, that line's ends join it, the moves between cuts' too: they follow the part by the
#: safe-motion stage's rules (and the branch stage's on the pole), so they are screened only
#: where they were seen to fail.
ENDS_STRIDE = 16
ENDS_CLEARANCE = 100.0


@dataclass(frozen=True)
class _Ends:
    """The room's screen of block ends of full checks (tips mm, part frame), each standing still:
    its joints within their limits and margins, its bodies apart. With the angle pair and theta2
    (rad) the branch stage chose there, the tool stack, and whether the cutter may touch the
    stock. Ends at the machine's fixed positions (home, tool change) keep their joints ``fixed``
    (mm, rad; NaN rows elsewhere): they do not follow the part."""

    tip: np.ndarray
    axis: np.ndarray
    length: np.ndarray
    pair: np.ndarray
    theta2: np.ndarray
    stack: np.ndarray
    cut: np.ndarray
    fixed: np.ndarray
    between: np.ndarray  # a move between cuts' end

    @classmethod
    def of(cls, machine: Machine, poses: MachinePoses, checked: Checked, offset: np.ndarray,
           ends: np.ndarray | None = None) -> _Ends:
        """The ends ``ends`` (indices of ``checked.blocks``; None: see ENDS_STRIDE) of a full
        check at ``offset`` (mm); ``poses`` at work offset 0."""
        blocks = checked.blocks
        if ends is None:
            near = np.full(len(blocks.pose), np.inf)
            if checked.clearance is not None:
                near = np.minimum(checked.clearance, np.r_[checked.clearance[1:], np.inf])
            near[blocks.between] = np.inf
            padded = np.r_[near, np.full(-len(near) % ENDS_STRIDE, np.inf)].reshape(-1, ENDS_STRIDE)
            nearest = np.arange(0, padded.size, ENDS_STRIDE) + np.argmin(padded, axis=1)
            ends = nearest[padded.min(axis=1) < ENDS_CLEARANCE]
        joints = blocks.joints[ends]
        fixed = np.zeros(len(ends), bool)
        for position in (machine.positions.home, machine.positions.tool_change):
            if position is not None:
                fixed |= np.all(np.abs(joints - position.joints()) <= 1e-9, axis=1)
        stacks = tool_stacks(machine, poses)
        radius = max(float(s.radius[0]) for s in stacks) if stacks else 0.0
        cut = cutting(poses.setup.shifted(offset), blocks.tip, checked.rapid, radius)[ends]
        pose = blocks.pose[ends]
        in_cone = checked.path.in_cone[pose]
        return cls(blocks.tip[ends] - offset, blocks.axis[ends], poses.tool_length[pose],
                   np.where(in_cone, 1, blocks.result.pair[ends]).astype(int), np.nan_to_num(joints[:, 4]),
                   tool_use_of_poses(poses)[pose], cut, np.where(fixed[:, None], joints, np.nan), blocks.between[ends])

    def then(self, other: _Ends) -> _Ends:
        return _Ends(*(np.concatenate([getattr(self, name), getattr(other, name)])
                       for name in _Ends.__dataclass_fields__))

    def fail(self, machine: Machine, poses: MachinePoses, offsets: np.ndarray) -> np.ndarray:
        """(K,) whether some end fails with the part at each offset (K, 3) (mm, table frame): out of
        reach, a joint limit or margin, or bodies that meet."""
        found = np.zeros(len(offsets), bool)
        if not len(self.tip):
            return found
        stacks = tool_stacks(machine, poses)
        moving = np.flatnonzero(np.isnan(self.fixed[:, 0]))
        for k, offset in enumerate(offsets):
            joints, alpha = self.fixed.copy(), np.zeros(len(self.tip))
            room, joints[moving], alpha[moving] = _smallest_headroom(
                machine, self.tip[moving] + offset, self.axis[moving], self.length[moving], self.pair[moving],
                self.theta2[moving], exact=True)
            found[k] = bool(np.any(room < 0))  # out of reach too (UNREACHABLE)
            if found[k] or not machine.bodies.check:
                continue
            world = World(machine.bodies, machine.geom, stacks, poses.setup, offset)
            found[k] = bool(np.any(world.clearance_at(placeable(machine, joints), self.stack, self.cut, alpha) <= 0.0))
        return found


def _room(machine: Machine, poses: MachinePoses, points: _Points, rows: np.ndarray, offset: np.ndarray,
          options: PostOptions, tick: Callable[[], None], chosen: Checked | None = None
          ) -> tuple[tuple[float, float], ...]:
    """How far (mm) the part may move from ``offset`` along -x, +x, -y, +y, -z, +z and still run.

    Per direction: bisection on the screens to ROOM_RESOLUTION, its inner end run through the
    full checks. The screens: the screened CL poses (joints, exact kernel), and, with the full
    check at ``offset`` (``chosen``), block ends standing still (:class:`_Ends`: the ends of
    the cuts that came nearest to a body). Where a full check fails, the failing poses
    join the first and the failing lines' ends the second, and the bisection runs again below;
    what the screens still cannot see (a block's joint-space line, a cut that needs both angle
    pairs) is then bisected with the full checks themselves: the room is the room of everything
    the post checks, the bodies included. The full checks of different directions run side by
    side in up to ``options.workers`` processes (each direction's own checks in turn, as in one
    process: the same room).
    """
    directions = np.repeat(np.eye(3), 2, axis=0) * np.tile([-1.0, 1.0], 3)[:, None]
    inside = np.zeros(6)  # farthest distance known to run (full checks)
    outside = np.full(6, ROOM_LIMIT)  # nearest distance known to fail
    failed_at = np.full(6, ROOM_LIMIT)  # nearest distance a full check failed at
    pending = np.arange(6)
    ends = None if chosen is None else _Ends.of(machine, poses, chosen, offset)
    checks = Pool((machine, poses, options), options.workers)

    def bisect_fully(which: list[int]) -> None:
        """Bisect the directions ``which`` with the full checks themselves, in step (one check
        per direction at a time: an interrupted room waits for one check, not a bisection)."""
        while which := [d for d in which if outside[d] - inside[d] > 2 * ROOM_RESOLUTION]:
            middle = [(inside[d] + outside[d]) / 2.0 for d in which]
            verdicts = checks.map(_confirm_at, [(offset + m * directions[d],) for d, m in zip(which, middle,
                                                                                               strict=True)])
            for d, m, (worst, _, _) in zip(which, middle, verdicts, strict=True):
                if worst is None:
                    inside[d] = m
                else:
                    outside[d] = failed_at[d] = m
                tick()

    try:
        for round_ in range(ROUNDS):
            screen = points.screen(rows)
            lo, hi = _bisect(machine, screen, offset, directions[pending], inside[pending], outside[pending],
                             None if ends is None else partial(ends.fail, machine, poses))
            outside[pending] = hi
            tick()
            failed, unseen = [], []
            ats = offset + lo[:, None] * directions[pending]
            confirmed = checks.map(_confirm_at, [(at,) for at in ats])
            for k, d in enumerate(pending):
                at = ats[k]
                worst, screenable, failing = confirmed[k]
                tick()
                if worst is None:
                    inside[d] = lo[k]
                    continue
                outside[d] = failed_at[d] = lo[k]
                grown = np.union1d(rows, worst)
                # the failing ends can join the screen where it sees them fail here and not where the
                # program runs (ends that do not follow the part, near home, may fail anywhere else)
                seen = failing is not None and np.array_equal(
                    failing.fail(machine, poses, np.array([at, offset + inside[d] * directions[d]])), [True, False])
                if round_ < ROUNDS - 1 and (seen or (screenable and len(grown) > len(rows))):
                    if seen:  # the failing ends (where the screens did not look) join the screen of ends
                        ends = failing if ends is None else ends.then(failing)
                    rows = grown
                    failed.append(d)
                    continue
                unseen.append(d)  # what the screens cannot see
            bisect_fully(unseen)
            pending = np.array(failed, dtype=int)
            if not pending.size:
                break
        if ends is not None and ends.between.any():
            # the moves between cuts' ends follow the part only roughly: where the screen's edge may be
            # theirs, the full checks confirm that it fails there, else bisect on with them
            edges = np.flatnonzero(outside < failed_at)
            verdicts = checks.map(_confirm_at, [(offset + outside[d] * directions[d],) for d in edges])
            running = []
            for d, (worst, _, _) in zip(edges, verdicts, strict=True):
                if worst is None:
                    inside[d], outside[d] = outside[d], failed_at[d]
                    running.append(int(d))
                tick()
            bisect_fully(running)
    finally:
        checks.close()
    return tuple((float(np.floor(inside[2 * a] * 100) / 100), float(np.floor(inside[2 * a + 1] * 100) / 100))
                 for a in range(3))


_Context = tuple[Machine, MachinePoses, PostOptions]


def _confirm_at(context: _Context, offset: np.ndarray) -> tuple[np.ndarray | None, bool, _Ends | None]:
    """:func:`_confirm` at ``offset`` (mm) of the room's program (a :class:`Pool` call)."""
    machine, poses, options = context
    return _confirm(machine, poses, offset, options)


def _bisect(machine: Machine, screen: _Points, offset: np.ndarray, directions: np.ndarray, lo: np.ndarray,
            hi: np.ndarray, fail: Callable[[np.ndarray], np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Bisect each direction's distance (mm) between ``lo`` (runs) and ``hi`` (fails or the
    limit) on the screen, all directions at once; returns the final (lo, hi). ``fail(offsets)``:
    where the screen of block ends fails, at offsets (K, 3) mm the CL poses' screen passes."""
    lo, hi = lo.copy(), hi.copy()
    # Distances grow fast from the known end, so a wide bracket is narrowed in a few steps.
    while np.any(hi - lo > ROOM_RESOLUTION):
        wide = hi - lo > 64.0
        mid = np.where(wide, lo + np.minimum(np.maximum(2.0 * lo, 16.0), (hi - lo) / 2.0), (lo + hi) / 2.0)
        mid = np.where(hi - lo > ROOM_RESOLUTION, mid, lo)
        offsets = offset + mid[:, None] * directions
        runs = _score(_screen_headroom(machine, screen, offsets, exact=True)) >= 0
        ask = np.flatnonzero(runs & (mid > lo))
        if fail is not None and ask.size:
            runs[ask] &= ~fail(offsets[ask])
        lo, hi = np.where(runs, mid, lo), np.where(runs | (mid == lo), hi, mid)
    return lo, hi


# ----------------------------------------------------------------------------- the search


def _search(machine: Machine, poses: MachinePoses, options: PostOptions, tick: Callable[[str], None]
            ) -> tuple[np.ndarray, _Verdict, _Points, np.ndarray, int]:
    """Coarse grid, pattern search and full checks (see the module docstring). Returns the best
    offset, its full check, the screen's points and rows there, and the offsets screened."""
    points = _points_of(machine, poses)
    rows = _spread(poses, machine, SCREEN_POSES)
    coarse_rows = _spread(poses, machine, COARSE_POSES)
    lower, upper = _search_box(machine, poses)
    counts = np.array([9, 9, 7])
    grid = _grid(lower, upper, counts)
    seat = _Seat.of(machine, poses)
    scores = _scores(machine, points.screen(coarse_rows), grid, seat)
    screened = len(grid)
    tick("coarse grid")
    step = float(np.max((upper - lower) / (counts - 1))) / 2.0
    starts = grid[np.argsort(-scores, kind="stable")[:2]]
    points = points.paired(machine, poses, starts[0])
    best: tuple[np.ndarray, _Verdict, _Points, np.ndarray] | None = None
    for _ in range(ROUNDS):
        candidates, found, count = _pattern_search(machine, points.screen(coarse_rows), points.screen(rows), starts,
                                                   step, lambda: tick("search"), seat)
        screened += count
        candidates = np.round(candidates, 3)  # a micrometre is plenty for a setter
        verdict = _verify(machine, poses, candidates[0], options)
        tick("full check")
        points = points.chosen(verdict.checked, candidates[0])
        if best is None or (verdict.runs, verdict.margin) > (best[1].runs, best[1].margin):
            best = (candidates[0], verdict, points, rows)
        if verdict.runs and verdict.margin >= found[0] - 1e-3:
            break  # the screen saw the binding poses: its optimum is the program's
        rows = np.union1d(rows, verdict.worst)
        starts, step = candidates[:1], 8.0
    assert best is not None
    return (*best, screened)


def place(machine: Machine, poses: MachinePoses, options: PostOptions,
          progress: Callable[[str], None] = lambda stage: None, room: bool = True) -> Placement:
    """The work offset (mm, part zero in the table frame) where the whole program runs with the
    largest smallest headroom; ``poses`` are the program's poses at work offset 0 0 0.

    ``room``: also how far the part may move from it and still run (step 3 of the module
    docstring: most of the time, as every distance it reports is certified by the full checks;
    without it, ``Placement.room`` is None). ``progress`` is called after each step (some 5
    calls, 20 to 40 with the room) with a short stage name.
    """
    clock = time.perf_counter()
    offset, verdict, points, rows, screened = _search(machine, poses, options, progress)
    line = int(poses.line[verdict.pose])
    if not verdict.runs:
        # bodies that meet where the joints can go: the collision is the answer, not the search
        # (where a limit fails too, the limit is the reason and the bodies' places are moot)
        found = verdict.checked.violations
        collisions = tuple(v for v in found if v.kind == "collision") \
            if all(v.kind == "collision" for v in found) else ()
        reason = (f"at the best offset found, line {collisions[0].line}: {collisions[0].message}" if collisions
                  else diagnose(machine, poses, options, verdict))
        return Placement(tuple(float(v) for v in offset), False, verdict.margin, verdict.limit, line,
                         ((0.0, 0.0),) * 3 if room else None, reason, screened, time.perf_counter() - clock, collisions)
    found = _room(machine, poses, points, rows, offset, options, lambda: progress("room"), verdict.checked) \
        if room else None
    return Placement(tuple(float(v) for v in offset), True, verdict.margin, verdict.limit, line, found, "",
                     screened, time.perf_counter() - clock)


# ----------------------------------------------------------------------------- no offset works


def _subset(poses: MachinePoses, rows: np.ndarray) -> MachinePoses:
    """The poses ``rows`` as a program of their own (rapid into the first)."""
    rapid = poses.rapid[rows].copy()
    rapid[0] = True
    return replace(poses, tip=poses.tip[rows], axis=poses.axis[rows], line=poses.line[rows], rapid=rapid,
                   feed=poses.feed[rows], inverse_time=poses.inverse_time[rows], tool=poses.tool[rows],
                   tool_length=poses.tool_length[rows], sequence=poses.sequence[rows], events=())


def _runs_alone(machine: Machine, poses: MachinePoses, options: PostOptions) -> bool:
    return _search(machine, poses, options, lambda stage: None)[1].runs


def _tilt(axis: np.ndarray) -> np.ndarray:
    """Angle (deg) between unit tool axes (N, 3) and the table normal."""
    return np.degrees(np.arctan2(np.hypot(axis[:, 0], axis[:, 1]), axis[:, 2]))


def largest_tilt(machine: Machine, tool_length: float) -> float:
    """Largest tool-axis tilt (deg from the table normal) at which the VERNE can stand with a
    tool of ``tool_length`` (mm) somewhere in its workspace clear of every limit: a fixed grid
    of platform positions (the module's closed-form IK) and theta1 every 5 degrees."""
    geom = machine.kinematic_geometry(tool_length)
    axes = (np.linspace(-700.0, 700.0, 21), np.linspace(-700.0, 700.0, 21), np.linspace(600.0, 2200.0, 25))
    platform = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    with np.errstate(invalid="ignore", divide="ignore"):
        module = module_ik_working(geom, platform)
    lower, upper = joint_bounds(machine)
    theta1 = np.radians(np.arange(max(np.degrees(lower[3]), -180.0), min(np.degrees(upper[3]), 180.0) + 1e-9, 5.0))
    rows = np.repeat(np.flatnonzero(module.reachable), len(theta1))
    t1 = np.tile(theta1, int(module.reachable.sum()))
    joints = np.column_stack([module.rho[rows], t1, np.zeros(len(rows))])
    alpha = module.alpha[rows]
    found = pose_margins(machine, joints, platform[rows], alpha, np.ones(len(rows), bool), tool_length)
    ok = classify(machine, joints, np.ones(len(rows), bool), found) == Status.OK
    return float(np.degrees(np.max(np.abs(alpha[ok] - t1[ok]), initial=0.0)))


def diagnose(machine: Machine, poses: MachinePoses, options: PostOptions, verdict: _Verdict) -> str:
    """Why no work offset works: a pose no offset reaches (its tilt), an operation that cannot
    run on its own (and the shorter tool that could), or the operations that need different
    offsets."""
    tools = [np.flatnonzero(poses.tool == t) for t in dict.fromkeys(poses.tool.tolist())]
    tilt = _tilt(poses.axis)
    reasons = []
    alone = []
    for rows in tools:
        length = float(poses.tool_length[rows[0]])
        most = largest_tilt(machine, length)
        beyond = rows[tilt[rows] > most + 1.0]
        tool = int(poses.tool[rows[0]])
        if beyond.size:
            k = beyond[np.argmax(tilt[beyond])]
            reasons.append(f"line {poses.line[k]}: the tool axis is tilted {tilt[k]:.1f} deg from the table normal; "
                           f"with tool {tool} ({length:g} mm) the VERNE tilts at most about {most:.0f} deg "
                           f"({beyond.size} poses of this tool tilt further): a smaller tilt is needed")
            alone.append(False)
            continue
        runs = _runs_alone(machine, _subset(poses, rows), options)
        alone.append(runs)
        if not runs:
            shorter = next((f for f in (0.75, 0.5, 0.25)
                            if _runs_alone(machine, replace(_subset(poses, rows), tool_length=np.full(
                                len(rows), length * f)), options)), None)
            hint = (f"; it would run with a tool of {length * shorter:g} mm" if shorter else
                    "; no shorter tool helps: a smaller tilt or a smaller part is needed")
            reasons.append(f"tool {tool} (CL lines {poses.line[rows[0]]}-{poses.line[rows[-1]]}) cannot run at any "
                           f"work offset even on its own{hint}")
    if not reasons:
        together = tools[0]
        for k in range(1, len(tools)):
            candidate = np.union1d(together, tools[k])
            if not _runs_alone(machine, _subset(poses, candidate), options):
                reasons.append(f"tool {poses.tool[tools[k][0]]} (from CL line {poses.line[tools[k][0]]}) needs a "
                               f"different work offset from the tools before it: each runs on its own, not together "
                               f"(split the program, or re-clamp between the operations)")
                break
            together = candidate
    if not reasons:
        first = verdict.checked.violations[0]
        reasons.append(f"at the best offset found, line {first.line}: {first.message}")
    return "; ".join(reasons)


__all__ = ["Placement", "largest_tilt", "place"]
