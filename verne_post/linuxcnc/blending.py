"""Blocks laid out so that LinuxCNC 2.9's blending keeps the tool tip on the path.

LinuxCNC 2.9 (src/emc/tp/tp.c, branch 2.9; docs/linuxcnc.md) blends a block that moves A or C into
the next parabolically: when the block, slowing to rest, is below its blend speed, the next one
starts, and both move together. ``G64 P`` bounds that blend by the X Y Z words only
(``tpComputeBlendVelocity``: the blend speed is at most ``2 sqrt(a P / cos theta)``, theta half the
angle between the two blocks' X Y Z directions, ``a`` the block's acceleration). Here X Y Z are the
sliders: where they go on nearly straight while the table stops or turns back (the end of a pass,
a retract), the corner is sharp in A and C, which LinuxCNC blends without bound, and the tip left
the path by up to 0.084 mm on the impeller (certified 0.0045 mm).

The blend, per block end (joints q in mm and rad): the block before has at most ``f1`` of itself
left when the next starts, ``2 P / cos theta`` of its X Y Z travel (what slowing from the blend speed
takes) and at most half of it (it never ran faster than its triangle); the next block runs at its
own acceleration meanwhile, ``a2 / a1`` times as far, ``f2`` of itself (each block's acceleration
is its slowest axis's at its limit over its X Y Z travel: src/emc/task/emccanon.cc
``getStraightAcceleration``). Both at constant acceleration over the same time:
q(s) = q_corner - f1 (1 - s)^2 dq1 + f2 s^2 dq2, s in [0, 1].

:func:`guard_corners`: where that blend takes the tip further from the CL path than allowed, the
block ends a little earlier and the next starts a little later, with a short block on the same
joint-space line on each side (a guard). LinuxCNC blends two blocks at a time: at the corner the
block before has at most its guard left to run while the block after has run at most its own
guard, and blends between a block and its guard stay on their common straight line. The executed
path is the programmed one (the guards lie on its joint-space lines); the blocks only give
LinuxCNC less room. LinuxCNC hardly blends a block into a short one, so each guard is as long as
the tolerance allows: the blend at the corner is then as large as allowed. Guards are laid after
the timing (:func:`split_durations`): the planner's spline never sees them. Measured through LinuxCNC: docs/linuxcnc.md.

Where the blend goes further than allowed is decided by :mod:`~verne_post.linuxcnc.blend_bound`'s
estimate wherever its bound tells, by the full FK (:func:`blend_deviation`) elsewhere: the same
decisions at a seventh of the cost.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

import numpy as np

from ..api import forward_kinematics
from ..machine import Machine
from ..motion.linearise import Blocks, distance_to_segment
from ..planning.controller import rotary_block_floor
from ..planning.timing import Limits
from .blend_bound import blend_estimate

#: Where the blend is measured (s in the module docstring).
SAMPLES = np.linspace(0.025, 0.975, 20)
#: The blend may use this share of the tolerance before a corner is guarded: what the measure's 20
#: samples may understate the blend's largest distance by (at most 10.3 %, tests/test_blending.py),
#: no more. At 0.8 the impeller had 950 more guard blocks and ran 21 s longer in LinuxCNC
#: (docs/linuxcnc.md).
MARGIN = 0.89
#: A guard moves some joint by this many units of the written numbers (1e-4 mm, 1e-5 deg:
#: output.numbers), so that it survives the rounding as a block of its own direction.
MIN_GUARD_UNITS = 20.0
#: ... and takes at most this share of its block (the guards at both ends of a block never meet).
MAX_GUARD = 0.25
#: Halvings of the guards of a corner before it is left as it is.
MAX_LEVELS = 30
#: tp.c's ``TP_MIN_ARC_ANGLE``: below cos(pi/2 - it) LinuxCNC applies no tolerance to a blend.
MIN_ARC_ANGLE = 1e-6


_MODE = re.compile(r"\bG\s*0*(61(?:\.1)?|64)(?![\d.])(?:\s*P\s*(\{tolerance[^}]*\}|[-+]?(?:\d+\.?\d*|\.\d+)))?",
                   re.IGNORECASE)


def blend_tolerance(program_start: tuple[str, ...], tol: float) -> float | None:
    """The ``G64 P`` (mm) the program's start lines leave in force: ``tol`` for ``P{tolerance}``, 0
    for a ``G64`` without P or no mode at all (LinuxCNC's default: blends without bound), None under
    ``G61``/``G61.1`` (no blends). Comments are not read: start lines carry none."""
    mode: float | None = 0.0
    for line in program_start:
        for code, p in _MODE.findall(line):
            mode = None if code.startswith("61") else tol if p.startswith("{") else float(p) if p else 0.0
    return mode


def blend_fractions(joints: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """The shares ``f1`` of the block before and ``f2`` of the block after each inner block end that a
    LinuxCNC parabolic blend there may take ((M - 2,) each; module docstring). ``joints`` (M, 5) mm and
    rad, the first three the sliders (LinuxCNC's X Y Z); ``tolerance`` the ``G64 P`` (mm; 0: none)."""
    step = np.abs(np.diff(joints, axis=0))
    length = np.linalg.norm(step[:, :3], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        before, after = np.diff(joints, axis=0)[:-1, :3], np.diff(joints, axis=0)[1:, :3]
        dot = np.einsum("ij,ij->i", before, after) / (length[:-1] * length[1:])
        cos_theta = np.cos(0.5 * np.arccos(np.clip(-dot, -1.0, 1.0)))
        bounded = (tolerance > 0) & (length[:-1] > 0) & (length[1:] > 0) & (
            cos_theta > np.cos(0.5 * np.pi - MIN_ARC_ANGLE))
        travel = np.where(bounded, 2.0 * tolerance / cos_theta, np.inf)
        f1 = np.where(bounded, np.minimum(0.5, travel / length[:-1]), 0.5)
        f2 = np.where(bounded, np.minimum(0.5, travel / length[1:]), 0.5)
    return np.nan_to_num(f1, nan=0.5), np.nan_to_num(f2, nan=0.5)


def blend_deviation(machine: Machine, corner: np.ndarray, before: np.ndarray, after: np.ndarray,
                    f1: np.ndarray, f2: np.ndarray, tips: tuple[np.ndarray, np.ndarray, np.ndarray],
                    tool_length: np.ndarray) -> np.ndarray:
    """(K,) mm: the largest distance of the blend's tip (module docstring) from the CL path around
    each corner: the segments tip0 -> tip1 -> tip2 of ``tips`` (table frame, mm). ``corner`` (K, 5)
    joints at the block end (mm, rad), ``before``/``after`` the two blocks' joint steps, ``f1``/``f2``
    the shares of them the blend takes, ``tool_length`` (K,) mm."""
    k, s = len(corner), SAMPLES
    q = (corner[:, None, :] - (f1[:, None] * (1.0 - s) ** 2)[:, :, None] * before[:, None, :]
         + (f2[:, None] * s ** 2)[:, :, None] * after[:, None, :]).reshape(-1, 5)
    fk = forward_kinematics(machine, q, tool_length=np.repeat(tool_length, len(s)))
    tip0, tip1, tip2 = (np.repeat(t, len(s), axis=0) for t in tips)
    distance = np.minimum(distance_to_segment(fk.tip, tip0, tip1), distance_to_segment(fk.tip, tip1, tip2))
    return np.where(fk.reachable, distance, np.inf).reshape(k, -1).max(axis=1)


@dataclass(frozen=True)
class Guarded:
    """Blocks with their guards: ``blocks`` and ``rapid`` as given with the guards' rows among them;
    ``owner`` (M',) the given block each row's motion belongs to, ``piece`` (M',) the share of that
    block the row's motion takes (1 where a block has no guard)."""

    blocks: Blocks
    rapid: np.ndarray
    owner: np.ndarray
    piece: np.ndarray


def guard_corners(machine: Machine, blocks: Blocks, rapid: np.ndarray, tool_length: np.ndarray, *,
                  tol: float, rapid_tol: float, blend_tolerance: float) -> Guarded:
    """``blocks`` (moving blocks in program order, joints mm and rad) with guards where a LinuxCNC
    blend could take the tip further than ``tol`` (mm; ``rapid_tol`` around moves between cuts) from
    the CL path (module docstring). ``tool_length`` (M,) mm per block; ``blend_tolerance`` mm: the
    program's ``G64 P`` (0: none)."""
    before, after = corner_guards(machine, blocks, rapid, tool_length, tol=tol, rapid_tol=rapid_tol,
                                  blend_tolerance=blend_tolerance)
    return with_guards(blocks, rapid, before, after)


def corner_guards(machine: Machine, blocks: Blocks, rapid: np.ndarray, tool_length: np.ndarray, *,
                  tol: float, rapid_tol: float, blend_tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """The guards :func:`guard_corners` lays: (M,) shares of each block (the motion into row j)
    guarded at its end, and (M,) at its start. Each corner is decided from its own two blocks alone,
    so a program in parts gets the guards of the whole (the pipeline hands a part the next block)."""
    joints = blocks.joints
    m = len(joints)
    none = (np.zeros(m), np.zeros(m))
    if m < 3:
        return none
    step = np.diff(joints, axis=0)
    # the block ends a rotary takes part in, within one tool (a tool change stops the machine)
    turns = np.any(step[:-1, 3:] != 0, axis=1) | np.any(step[1:, 3:] != 0, axis=1)
    same_tool = (tool_length[:-2] == tool_length[1:-1]) & (tool_length[1:-1] == tool_length[2:])
    f1, f2 = blend_fractions(joints, blend_tolerance)
    finite = np.all(np.isfinite(joints), axis=1)  # a program that does not run (unreachable poses) has no blends
    corner = 1 + np.flatnonzero(turns & same_tool & finite[:-2] & finite[1:-1] & finite[2:])
    if not corner.size:
        return none
    # a blend between a rapid and a feed block runs partly in the feed: the feed's tolerance
    budget = MARGIN * np.where(rapid[corner] & rapid[corner + 1], rapid_tol, tol)
    f1, f2 = f1[corner - 1], f2[corner - 1]

    def deviation(c: np.ndarray, share1: np.ndarray, share2: np.ndarray) -> np.ndarray:
        """:func:`blend_deviation` at block ends ``c`` (the full kinematics)."""
        return blend_deviation(machine, joints[c], step[c - 1], step[c], share1, share2,
                               (blocks.tip[c - 1], blocks.tip[c], blocks.tip[c + 1]), tool_length[c])

    def over(c: np.ndarray, share1: np.ndarray, share2: np.ndarray, limit: np.ndarray) -> np.ndarray:
        """Where the blend at block ends ``c`` goes further than ``limit`` (mm): told by the estimate
        and its bound (:func:`~verne_post.linuxcnc.blend_bound.blend_estimate`) where they can, by the
        full kinematics where they cannot."""
        estimate, bound = blend_estimate(machine, blocks, c, share1, share2, tool_length[c], SAMPLES)
        surely = estimate - bound > limit
        unsure = ~surely & (estimate + bound > limit)
        if unsure.any():
            surely[unsure] = deviation(c[unsure], share1[unsure], share2[unsure]) > limit[unsure]
        return surely

    # Where the blend may go over the budget, the full kinematics decides, and its deviation sets the
    # guards' lengths; but where the estimate shows it over and below budget min(2 f1, f2) / MAX_GUARD,
    # both guards come out MAX_GUARD whatever the deviation there (scale 1 below gives the same).
    estimate, bound = blend_estimate(machine, blocks, corner, f1, f2, tool_length[corner], SAMPLES)
    capped = (estimate - bound > budget) & (
        estimate + bound < (1.0 - 1e-9) * budget * np.minimum(2.0 * f1, f2) / MAX_GUARD)
    scale, guarded = np.where(capped, 1.0, 0.0), capped.copy()
    near = np.flatnonzero(~capped & (estimate + bound > budget))
    if near.size:
        found = deviation(corner[near], f1[near], f2[near])
        guarded[near] = found > budget[near]
        scale[near] = np.clip(budget[near] / found, 0.0, 1.0)
    corner, budget, f1, f2, scale = corner[guarded], budget[guarded], f1[guarded], f2[guarded], scale[guarded]
    if not corner.size:
        return none
    units = np.r_[np.full(3, 1e-4), np.full(2, np.radians(1e-5))]
    least = MIN_GUARD_UNITS / np.max(np.abs(step) / units, axis=1)  # (M - 1,) share per block
    # Each guard as long as the budget allows: LinuxCNC blends a block into its guard (a short block)
    # hardly at all, so the corner's blend, as large as the guards allow, is what saves time. The
    # deviation grows about linearly with the shares: aim at the budget (scale), then halve where not enough.
    g1 = np.clip(2.0 * f1 * scale, np.minimum(least[corner - 1], MAX_GUARD), MAX_GUARD)
    g2 = np.clip(f2 * scale, np.minimum(least[corner], MAX_GUARD), MAX_GUARD)
    pending = np.arange(len(corner))
    for _ in range(MAX_LEVELS):
        pending = pending[over(corner[pending], np.minimum(f1[pending], 0.5 * g1[pending]),
                               np.minimum(f2[pending], g2[pending]), budget[pending])]
        shrink = (g1[pending] > least[corner[pending] - 1]) | (g2[pending] > least[corner[pending]])
        pending = pending[shrink]
        if not pending.size:
            break
        g1[pending] = np.maximum(0.5 * g1[pending], np.minimum(least[corner[pending] - 1], MAX_GUARD))
        g2[pending] = np.maximum(0.5 * g2[pending], np.minimum(least[corner[pending]], MAX_GUARD))
    guard_before = np.zeros(m)  # share of block j (the motion into row j) guarded at its end
    guard_after = np.zeros(m)  # ... at its start
    guard_before[corner], guard_after[corner + 1] = g1, g2
    return guard_before, guard_after


def with_guards(blocks: Blocks, rapid: np.ndarray, guard_before: np.ndarray, guard_after: np.ndarray) -> Guarded:
    """The blocks with a block end inserted at share ``guard_after[j]`` and ``1 - guard_before[j]``
    along block j (where > 0; never block 0, whose start is not here), on its joint-space line."""
    m = len(blocks.joints)
    if not np.any(guard_before) and not np.any(guard_after):
        return Guarded(blocks, rapid, np.arange(m), np.ones(m))
    owner = np.r_[np.arange(m), np.flatnonzero(guard_after), np.flatnonzero(guard_before)]
    share = np.r_[np.ones(m), guard_after[guard_after > 0], 1.0 - guard_before[guard_before > 0]]
    order = np.lexsort((share, owner))
    owner, share = owner[order], share[order]
    piece = share - np.where(np.r_[False, owner[1:] == owner[:-1]], np.r_[0.0, share[:-1]], 0.0)
    start = np.maximum(owner - 1, 0)
    u, end = share[:, None], (share == 1.0)[:, None]  # a block's own end kept exactly (a + (b - a) is not b)

    def along(values: np.ndarray) -> np.ndarray:
        return np.where(end, values[owner], values[start] + u * (values[owner] - values[start]))

    joints, tip, axis = along(blocks.joints), along(blocks.tip), along(blocks.axis)
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    same_pose = blocks.pose[start] == blocks.pose[owner]
    before = np.where(same_pose, blocks.fraction[start], 0.0)
    fraction = np.where(share < 1.0, before + share * (blocks.fraction[owner] - before), blocks.fraction[owner])
    result = blocks.result.rows(owner)
    alpha = blocks.result.alpha[start] + share * (blocks.result.alpha[owner] - blocks.result.alpha[start])
    result = replace(result, joints=joints, alpha=np.where(share < 1.0, alpha, result.alpha))
    guarded = Blocks(tip, axis, blocks.pose[owner], fraction, result, blocks.unresolved, blocks.between[owner])
    return Guarded(guarded, rapid[owner], owner, piece)


def split_durations(machine: Machine, guarded: Guarded, duration: np.ndarray, tool_length: np.ndarray,
                    block_time: float = 0.0) -> np.ndarray:
    """(M',) s: each row's share of its block's ``duration`` (s, per given block), at least the
    least time LinuxCNC takes for it (:func:`~verne_post.planning.controller.rotary_block_floor`)
    and ``block_time`` (s). A piece's share is the larger of its share of the block's joint-space
    line and of the tip's path along it (by FK: ``tool_length`` (M',) mm), so that no piece runs
    the tip faster than its block did."""
    piece = guarded.piece
    split = piece < 1.0
    if not split.any():
        return duration[guarded.owner]
    joints = guarded.blocks.joints
    # The tip only where a share is taken: the rows of split blocks and the block end before each
    # (a whole block's share is 1 either way). Each row's FK is its own (no warm start from a
    # neighbour), so these rows get the numbers the whole program would; NaN elsewhere leaves
    # the whole blocks' share 0, below their piece 1.
    cut = np.zeros(len(duration), bool)
    cut[guarded.owner[split]] = True
    rows = cut[guarded.owner]
    rows = np.flatnonzero(rows | np.r_[rows[1:], False])
    tip = np.full((len(joints), 3), np.nan)
    tip[rows] = forward_kinematics(machine, joints[rows], tool_length=tool_length[rows]).tip
    chord = np.r_[0.0, np.linalg.norm(np.diff(tip, axis=0), axis=1)]
    total = np.bincount(guarded.owner, chord, minlength=len(duration))[guarded.owner]
    with np.errstate(divide="ignore", invalid="ignore"):
        tip_share = np.where(total > 0, chord / total, 0.0)
    own = np.maximum(piece, tip_share) * duration[guarded.owner]
    least = np.maximum(rotary_block_floor(joints, Limits.from_machine(machine)), block_time)
    return np.where(split, np.maximum(own, least), own)
