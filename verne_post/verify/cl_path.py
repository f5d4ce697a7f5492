"""The program against the CL path: every block end matched to the CL poses it may come from,
the deviation of the motion between them, the rapids' dips and the feeds."""

from __future__ import annotations

import bisect
import itertools
import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from ..kinematics.rows import finite_rows, norms
from ..machine import Machine
from ..motion.linearise import angle_to_arc, distance_to_segment
from .gcode_reader import GcodeProgram
from .limits import nanmax, worst_per_block
from .reference import FEED_LENGTH_SLACK, FEED_SLACK, PAIR_CHUNK, RAPID_DIP_TOL, STILL_TIP, Finding, Reference
from .sampling import Curves, Motion, Poses

# --------------------------------------------------------------------------------------------
# against the CL path


def _angle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return 2.0 * np.arcsin(np.clip(norms(u - v) / 2.0, 0.0, 1.0))


def _match(reference: Reference, ends: Poses, known: np.ndarray, tol: float, axis_tol: float) -> np.ndarray:
    """The block whose end reaches each CL pose (-1 where none does).

    Candidates: the block ends within ``tol`` (mm) and ``axis_tol`` (rad) of the pose. Where a
    pose has several (a path passing twice, points closer than ``tol``), the earliest one at or
    after the block the pose before it took.
    """
    n = len(reference.tip)
    matched = np.full(n, -1)
    usable = np.flatnonzero(known & ends.reachable)
    if usable.size == 0 or n == 0:
        return matched
    # tip and axis together (the axis scaled so that axis_tol weighs as much as tol): the block
    # ends of a rotation on the spot share their tip but not their axis
    weight = tol / axis_tol
    pose, block = _near(np.hstack([reference.tip, weight * reference.axis]),
                        np.hstack([ends.tip[usable], weight * ends.axis[usable]]), tol)
    block = usable[block]
    good = ((norms(reference.tip[pose] - ends.tip[block]) <= tol)
            & (_angle(reference.axis[pose], ends.axis[block]) <= axis_tol))
    pose, block = pose[good], block[good]
    if pose.size == 0:
        return matched
    # The program runs the CL path in order: each pose takes the earliest candidate at or after
    # the block the pose before it took (a path passing a point twice, points closer than tol).
    # Where none is left (a program out of order), the last candidate, which the order check reports.
    order = np.lexsort((block, pose))
    pose, block = pose[order], block[order]
    bounds = np.flatnonzero(np.r_[True, pose[1:] != pose[:-1], True])
    lo, hi = bounds[:-1], bounds[1:]
    taken = block[lo]  # a pose with one candidate takes it whatever the pose before took
    blocks = block.tolist()
    for i in np.flatnonzero(hi - lo > 1).tolist():  # in order: each after the pose before it
        start, stop = int(lo[i]), int(hi[i])
        k = bisect.bisect_left(blocks, int(taken[i - 1]) if i else -1, start, stop)
        taken[i] = blocks[k] if k < stop else blocks[stop - 1]
    matched[pose[lo]] = taken
    return matched


# Cells of the search grid, in search radii (see _near): wider cells, fewer neighbours to look in,
# more candidates in each (on the 105k job 8: 184 ms, 32: 96 ms, 64: 82 ms with 20 % more pairs;
# scipy's k-d tree took 120 ms).
_CELL = 32.0
# odd 64-bit multipliers (SplitMix64's constants): a cell's key is the sum of its six coordinates times them
_MIX = np.array([0x9E3779B97F4A7C15, 0xBF58476D1CE4E5B9, 0x94D049BB133111EB, 0xD6E8FEB86659FD93,
                 0xA0761D6478BD642F, 0xE7037ED1A0B428DB], dtype=np.uint64)


def _near(queries: np.ndarray, points: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Every pair (query, point), rows of (n, 6) and (m, 6), at most ``radius`` apart in each
    coordinate, and maybe some more (the caller keeps the pairs its own test accepts).

    A grid of cells ``_CELL`` radii wide, each cell a 64-bit key (two cells sharing one only
    add candidates): a query looks in its own cell and, along each coordinate where it lies
    within the radius of its cell's side, the neighbour there (on average 1.06^6 = 1.4 cells).
    numpy only: a k-d tree (scipy.spatial) cost the verifying process 0.45 s to import.
    """
    size = _CELL * radius
    reach = 1.01 * radius  # a neighbour looked at a little early: the cells' rounding never loses a pair

    def keys(cells: np.ndarray) -> np.ndarray:
        return np.sum(cells.astype(np.int64).astype(np.uint64) * _MIX, axis=1, dtype=np.uint64)  # mod 2^64

    point_keys = keys(np.floor(points / size))
    order = np.argsort(point_keys, kind="stable")
    sorted_keys = point_keys[order]
    cell = np.floor(queries / size)
    side = np.where(queries - cell * size <= reach, -1.0, np.where((cell + 1.0) * size - queries <= reach, 1.0, 0.0))
    needs = (side != 0.0) @ (1 << np.arange(queries.shape[1]))  # per query, the coordinates with a neighbour
    looking, looked = [], []
    for bits in range(1 << queries.shape[1]):  # each set of those coordinates
        who = np.flatnonzero((needs & bits) == bits)
        looking.append(who)
        looked.append(keys(cell[who] + side[who] * ((bits >> np.arange(queries.shape[1])) & 1)))
    who, key = np.concatenate(looking), np.concatenate(looked)
    ascending = np.argsort(key)  # a search of sorted keys runs in cache, 3x faster than of these
    who, key = who[ascending], key[ascending]
    lo, hi = np.searchsorted(sorted_keys, key, "left"), np.searchsorted(sorted_keys, key, "right")
    count = hi - lo
    at = np.repeat(lo - np.cumsum(count) + count, count) + np.arange(int(count.sum()))
    return np.repeat(who, count), order[at]


@dataclass(frozen=True)
class _Pieces:
    """The CL segments each block belongs to: poses ``first[m]``..``last[m]`` (segment s runs from
    pose s - 1 to s; first == last: the block should stay at that pose). ``lost``: blocks amid
    more than :data:`LOST_PIECE` CL segments none of whose poses is reached, compared with the
    CL path by those reach findings alone (their piece is cut to one pose)."""

    first: np.ndarray  # (M,)
    last: np.ndarray  # (M,)
    lost: np.ndarray  # (M,) bool

    def pairs(self, blocks: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(owner, from pose, to pose): every segment of the pieces of ``blocks``."""
        a, b = self.first[blocks], self.last[blocks]
        count = np.maximum(b - a, 1)
        owner = np.repeat(np.arange(len(blocks)), count)
        s = a[owner] + 1 + _ranks(count)
        point = (b == a)[owner]
        return owner, np.where(point, b[owner], s - 1), np.where(point, b[owner], s)

    def chunks(self, blocks: np.ndarray) -> Iterator[tuple[slice, np.ndarray, np.ndarray, np.ndarray]]:
        """:meth:`pairs` of ``blocks[rows]`` for successive ``rows`` of about PAIR_CHUNK pairs in
        all: where the program strays from the CL path the pieces grow long (a block between two
        far apart reached poses belongs to every segment between them), and their pairs with them."""
        for rows in _chunks(np.maximum(self.last[blocks] - self.first[blocks], 1)):
            yield (rows, *self.pairs(blocks[rows]))


def _chunks(count: np.ndarray) -> Iterator[slice]:
    """Successive slices of ``count`` whose sums are about PAIR_CHUNK (one item may exceed it alone)."""
    total = np.cumsum(count)
    edges = np.r_[0, np.searchsorted(total, np.arange(PAIR_CHUNK, total[-1] if total.size else 0, PAIR_CHUNK)),
                  len(count)]
    for start, stop in itertools.pairwise(edges.tolist()):
        if stop > start:
            yield slice(start, stop)


def _ranks(count: np.ndarray) -> np.ndarray:
    """0, 1, ..., count[i] - 1 for each i, one after the other."""
    return np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)


def _out_of_order(block: np.ndarray) -> np.ndarray:
    """Which of the blocks reaching successive CL poses break a non-decreasing order: those below
    an earlier one, or those above a later one, whichever are fewer (an outlier is then dropped
    alone, not everything it overtakes). What is left is non-decreasing."""
    if block.size == 0:
        return np.zeros(0, bool)
    below = block < np.maximum.accumulate(block)
    above = block > np.minimum.accumulate(block[::-1])[::-1]
    return below if below.sum() <= above.sum() else above


def _pieces(matched: np.ndarray, m_blocks: int) -> _Pieces:
    anchor_pose = np.flatnonzero(matched >= 0)
    anchor_block = matched[anchor_pose]
    n = len(matched)
    if anchor_pose.size == 0:
        first, last = np.zeros(m_blocks, np.int64), np.full(m_blocks, n - 1, np.int64)
    else:
        i = np.searchsorted(anchor_block, np.arange(m_blocks), side="left")
        last = np.where(i < anchor_pose.size, anchor_pose[np.minimum(i, anchor_pose.size - 1)], n - 1)
        first = np.where(i > 0, anchor_pose[np.maximum(i - 1, 0)], 0)
        last = np.maximum(last, first)
    # a long stretch the program does not follow: comparing each of its blocks with every segment
    # of the stretch would cost blocks x segments, and its reach findings already say it
    lost = last - first > LOST_PIECE
    return _Pieces(first, np.where(lost, first, last), lost)


#: CL segments (their poses all unreached) beyond which the blocks among them are not compared segment by segment.
LOST_PIECE = 1000


def _deviation(reference: Reference, pieces: _Pieces, blocks: np.ndarray, tip: np.ndarray, axis: np.ndarray,
               tol: float, axis_tol: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tip distance (mm), axis angle (rad) and end pose of the segment of each point's piece
    (points of ``blocks``) nearest to it, tip and axis over ``tol`` (mm) and ``axis_tol`` (rad);
    in chunks of at most PAIR_CHUNK point-segment pairs."""
    count = np.maximum(pieces.last[blocks] - pieces.first[blocks], 1)
    tip_error, axis_error, nearest = np.empty(len(blocks)), np.empty(len(blocks)), np.empty(len(blocks), np.int64)
    for rows, owner, a, b in pieces.chunks(blocks):
        distance = distance_to_segment(tip[rows][owner], reference.tip[a], reference.tip[b])
        angle = angle_to_arc(axis[rows][owner], reference.axis[a], reference.axis[b])
        # the segment nearest in tip and axis together, each over its tolerance
        cost = distance / tol + angle / axis_tol
        group = np.cumsum(count[rows]) - count[rows]
        nearest_pair = np.flatnonzero(cost == np.repeat(np.minimum.reduceat(cost, group), count[rows]))
        best = nearest_pair[np.r_[True, owner[nearest_pair][1:] != owner[nearest_pair][:-1]]]
        tip_error[rows], axis_error[rows], nearest[rows] = distance[best], angle[best], b[best]
    return tip_error, axis_error, nearest


def path_findings(program: GcodeProgram, machine: Machine, reference: Reference, motion: Motion, tol: float,
                  axis_tol: float, findings: list[Finding], skip: int, rapid_tol: float, box: np.ndarray
                  ) -> tuple[float | None, float | None, float | None, float | None, int, float | None, float | None]:
    """Reach, order, deviation, rapid and feed findings; returns the largest tip deviation (mm),
    axis deviation (deg), feed ratio, peak feed ratio within a block, the number of CL points
    reached (of those after the first ``skip``: the first ``skip`` blocks and poses were
    verified with the part before), the largest rapid deviation and dip (mm, :func:`_rapids`).

    A program that reaches fewer than :data:`FOLLOWED_SHARE` of the poses follows another path:
    one ``mismatch`` finding instead (and no deviation, rapid or feed figures). Blocks amid a
    long unreached stretch (:data:`LOST_PIECE`) are left to its reach findings (and the largest
    deviations are then None: not measured)."""
    m_blocks = len(program)
    lines, cl_lines = program.line, reference.line
    ends = motion.ends
    matched = _match(reference, ends, motion.known, tol, axis_tol)
    reached = np.flatnonzero(matched >= 0)
    disorder = reached[_out_of_order(matched[reached])]
    reached_count = int(np.count_nonzero(matched[skip:] >= 0)) - int(np.count_nonzero(disorder >= skip))
    poses = len(matched) - skip
    if reached_count < FOLLOWED_SHARE * poses:
        # the block-by-block comparison rests on the reached poses: without them every block would
        # be compared with the whole path, thousands of findings that hide the one cause
        findings.append(mismatch(int(lines[skip]) if m_blocks > skip else program.last_line, reached_count, poses))
        return None, None, None, None, reached_count, None, None
    for k in disorder:
        findings.append(Finding(int(lines[matched[k]]), "order", "reaches this CL point out of the order of the "
                                "CL path", cl_line=int(cl_lines[k])))
        matched[k] = -1
    pieces = _pieces(matched, m_blocks)
    _unreached(reference, matched, ends, lines, tol, findings)

    # deviation at the block ends and the interior samples of feed moves that follow the CL path
    curves = motion.curves
    # a CL move across a tool change cannot be cut as programmed: the tool that reaches its end
    # is not the one that left its start (the program moves between cuts there)
    tool_at = np.where(matched >= 0, program.tool[np.maximum(matched, 0)], -2)
    cl_rapid, cl_feed = np.zeros(m_blocks, bool), np.zeros(m_blocks, bool)
    for rows, owner, a, b in pieces.chunks(np.arange(m_blocks)):  # (lost pieces: one pose, no segment)
        segment = a != b  # a piece of one pose has no motion of its own
        retooled = (tool_at[a] != tool_at[b]) & (tool_at[a] != -2) & (tool_at[b] != -2)
        size = rows.stop - rows.start
        cl_rapid[rows] = np.bincount(owner, (reference.rapid[b] | retooled) & segment, minlength=size) > 0
        cl_feed[rows] = np.bincount(owner, ~reference.rapid[b] & ~retooled & segment, minlength=size) > 0
    cl_feed[:1] = False  # the first block comes from wherever the machine stands
    for m in np.flatnonzero(program.rapid & cl_feed):
        findings.append(Finding(int(lines[m]), "motion", "rapid where the CL path feeds",
                                cl_line=int(cl_lines[pieces.last[m]])))
    follows = ~program.rapid[curves.moves] & ~cl_rapid[curves.moves]
    inner_follows = np.repeat(follows, curves.n - 1)
    end_blocks = np.flatnonzero(motion.known & ends.reachable & ~program.rapid)  # rapids: _rapids
    end_blocks = end_blocks[end_blocks >= skip]
    point_block = np.r_[end_blocks, curves.block[inner_follows]]
    point_tip = np.concatenate([ends.tip[end_blocks], curves.samples.tip[inner_follows]])
    point_axis = np.concatenate([ends.axis[end_blocks], curves.samples.axis[inner_follows]])
    ok = finite_rows(point_tip) & ~pieces.lost[point_block]
    point_block, point_tip, point_axis = point_block[ok], point_tip[ok], point_axis[ok]
    tip_error, axis_error, nearest = _deviation(reference, pieces, point_block, point_tip, point_axis, tol,
                                                axis_tol)
    bound_tip, bound_axis = np.zeros(m_blocks), np.zeros(m_blocks)
    bound_tip[curves.moves[follows]] = motion.bound_tip[follows]
    bound_axis[curves.moves[follows]] = motion.bound_axis[follows]
    tip_total = tip_error + bound_tip[point_block]
    axis_total = axis_error + bound_axis[point_block]
    for k in worst_per_block(point_block, tip_total - tol):
        findings.append(Finding(int(lines[point_block[k]]), "tip", f"tool tip {tip_total[k]:.4f} mm from the CL "
                                f"path (max {tol:g} mm)", cl_line=int(cl_lines[nearest[k]]),
                                value=float(tip_total[k]), limit=tol))
    for k in worst_per_block(point_block, axis_total - axis_tol):
        findings.append(Finding(int(lines[point_block[k]]), "axis", f"tool axis {np.degrees(axis_total[k]):.4f} "
                                f"deg from the CL path (max {np.degrees(axis_tol):g} deg)",
                                cl_line=int(cl_lines[nearest[k]]), value=float(np.degrees(axis_total[k])),
                                limit=float(np.degrees(axis_tol))))
    feed_ratio, peak_ratio = _feed(program, reference, machine, matched, pieces, curves, follows, findings)
    rapid_dev, rapid_dip = _rapids(program, reference, motion, pieces, skip, rapid_tol, box, findings)
    if pieces.lost.any():  # blocks not measured: no largest deviation to tell
        return None, None, feed_ratio, peak_ratio, reached_count, rapid_dev, rapid_dip
    return (float(tip_total.max(initial=0.0)), float(np.degrees(axis_total.max(initial=0.0))), feed_ratio,
            peak_ratio, reached_count, rapid_dev, rapid_dip)


#: A program that reaches fewer of its CL poses than this share follows another path: one finding says so.
FOLLOWED_SHARE = 0.5


def mismatch(line: int, reached: int, poses: int) -> Finding:
    """The finding of a program that does not follow its CL path (``reached`` of ``poses``)."""
    return Finding(line, "mismatch", f"{reached} of {poses} CL points reached: the program does not follow this "
                   "CL path; another CL file, machine file or work offset?", value=float(reached), limit=float(poses))


def _below_line(point: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """mm (>= 0): how far each point lies below the segment a -> b (table frame): below the line
    in the line's vertical plane (perpendicular to the line, toward -z), or below its lower end."""
    d = b - a
    horizontal = np.hypot(d[:, 0], d[:, 1])
    length = np.linalg.norm(d, axis=1)
    # the upward normal of the line in its vertical plane: (-dz dx/h, -dz dy/h, h) / |d|
    with np.errstate(divide="ignore", invalid="ignore"):
        normal = np.column_stack([-d[:, 2] * d[:, 0] / horizontal, -d[:, 2] * d[:, 1] / horizontal, horizontal]
                                 ) / length[:, None]
    sloped = (horizontal > 1e-6 * length) & (length > 1e-9)
    below = np.where(sloped, -np.sum((point - a) * np.where(sloped[:, None], normal, 0.0), axis=1), 0.0)
    return np.maximum(np.maximum(below, np.minimum(a[:, 2], b[:, 2]) - point[:, 2]), 0.0)


def _from_ray(point: np.ndarray, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """mm: distance of each point from the ray from ``origin`` along the unit ``direction``."""
    along = np.maximum(np.sum((point - origin) * direction, axis=1), 0.0)
    return np.linalg.norm(point - origin - along[:, None] * direction, axis=1)


def _rapids(program: GcodeProgram, reference: Reference, motion: Motion, pieces: _Pieces, skip: int,
            rapid_tol: float, box: np.ndarray, findings: list[Finding]) -> tuple[float | None, float | None]:
    """Rapid findings against the CL path, from the block ends and samples of the rapid blocks.

    A rapid's tip may be on the CL rapid's straight line (within ``rapid_tol`` mm, never more
    than :data:`RAPID_DIP_TOL` below it), on a retract or approach ray (a CL pose's tool axis
    from its tip outward, within ``rapid_tol``), or outside the bounding box of the program's feed
    points (``box``, (2, 3) mm, table frame): above it, or beside it and not below its bottom,
    away from every feed point either way (a move between cuts that leaves the clearance
    envelope through a side rises beside the part); the sampling bound of each move counts
    against it, the whole ball of that radius about the sample must be outside. Returns the
    largest distance from where a rapid may be and the largest dip below its CL line (mm) of the
    points judged by their line, None without rapids."""
    ends, curves = motion.ends, motion.curves
    blocks = np.flatnonzero(program.rapid & motion.known & ends.reachable & ~pieces.lost)
    blocks = blocks[blocks >= skip]
    inner = np.repeat(program.rapid[curves.moves] & ~pieces.lost[curves.moves], curves.n - 1)
    block = np.r_[blocks, curves.block[inner]]
    if block.size == 0:
        return None, None
    point = np.concatenate([ends.tip[blocks], curves.samples.tip[inner]])
    bound = np.r_[np.zeros(len(blocks)), np.repeat(motion.bound_tip, curves.n - 1)[inner]]
    known = finite_rows(point)  # an unreachable sample is a finding of its own
    block, point, bound = block[known], point[known], bound[known]
    count = len(block)
    on_line, on_ray = np.full(count, np.inf), np.full(count, np.inf)
    nearest_line, least_dip = np.full(count, np.inf), np.full(count, np.inf)
    ref = reference.tip
    for rows, owner, a, b in pieces.chunks(block):
        at, widen, index = point[rows][owner], bound[rows][owner], np.arange(rows.start, rows.stop)[owner]
        line = distance_to_segment(at, ref[a], ref[b]) + widen
        dip = _below_line(at, ref[a], ref[b]) + widen
        ray = np.minimum(_from_ray(at, ref[a], reference.axis[a]), _from_ray(at, ref[b], reference.axis[b])) + widen
        np.minimum.at(on_line, index, np.where(dip <= RAPID_DIP_TOL, line, np.inf))
        np.minimum.at(on_ray, index, ray)
        np.minimum.at(nearest_line, index, line)
        np.minimum.at(least_dip, index, dip)
    # the sample widened by its bound on every side: a box of half-width ``bound`` about it
    lo, hi = box
    low, high = point - bound[:, None], point + bound[:, None]
    above = low[:, 2] >= hi[2]
    # beside: clear of the box horizontally, and no lower than its lowest feed point (under the
    # part stands the table, never a place to pass)
    beside = np.any((low[:, :2] >= hi[:2]) | (high[:, :2] <= lo[:2]), axis=1) & (low[:, 2] >= lo[2])
    outside = above | beside
    deviation = np.where(outside, 0.0, np.minimum(on_line, on_ray))
    judged = ~outside & (on_ray > rapid_tol)  # points that only their CL line can justify
    last = pieces.last[block]
    for k in worst_per_block(block, deviation - rapid_tol):
        findings.append(Finding(int(program.line[block[k]]), "rapid", f"rapid tool tip {nearest_line[k]:.4f} mm "
                                f"from its CL line and {least_dip[k]:.4f} mm below it (max {rapid_tol:g} mm and "
                                f"none below), on no retract ray and inside the feed points' box",
                                cl_line=int(reference.line[last[k]]), value=float(min(deviation[k], 1e300)),
                                limit=rapid_tol))
    return (float(np.max(np.where(np.isfinite(deviation), deviation, nearest_line))),
            float(np.max(np.where(judged, least_dip, 0.0), initial=0.0)))


def rapid_block_dips(program: GcodeProgram, motion: Motion, rapid_tol: float, findings: list[Finding]) -> float | None:
    """Without the CL path: each rapid block (G0, or G1 marked ``(RAPID)``) judged by its largest
    dip below the lower of its two ends (mm, sampling bound included; a finding where it exceeds
    ``rapid_tol``). Returns the largest dip, None without rapid moves."""
    curves = motion.curves
    rapid_moves = np.flatnonzero(program.rapid[curves.moves])
    if rapid_moves.size == 0:
        return None
    start, count = curves.start[rapid_moves], curves.n[rapid_moves] + 1
    z = curves.tip[np.repeat(start, count) + _ranks(count), 2]
    lowest = np.minimum.reduceat(np.nan_to_num(z, nan=np.inf), np.cumsum(count) - count)
    ends = np.fmin(curves.tip[start, 2], curves.tip[start + count - 1, 2])
    dip = np.maximum(ends - lowest + motion.bound_tip[rapid_moves], 0.0)
    dip = np.where(np.isfinite(dip), dip, 0.0)  # a move out of reach is a finding of its own
    for k in np.flatnonzero(dip > rapid_tol):
        findings.append(Finding(int(program.line[curves.moves[rapid_moves[k]]]), "rapid", f"rapid dips "
                                f"{dip[k]:.4f} mm below the lower of its ends (max {rapid_tol:g} mm)",
                                value=float(dip[k]), limit=rapid_tol))
    return float(dip.max(initial=0.0))


def _unreached(reference: Reference, matched: np.ndarray, ends: Poses, lines: np.ndarray, tol: float,
               findings: list[Finding]) -> None:
    """A finding per CL pose no block end reaches, at the block between the reached poses around it
    whose move (the chord of its ends) passes nearest (the earlier one of equals); the first pose
    of a run of unreached ones at the first block before that whose end leaves the CL segment into
    the pose (farther than ``tol``): where the program leaves the CL path (where the tool turns
    about a point, a later block may pass nearer)."""
    missing = np.flatnonzero(matched < 0)
    anchors = np.flatnonzero(matched >= 0)
    if missing.size == 0:
        return
    i = np.searchsorted(anchors, missing)
    before = matched[anchors[i - 1]] if anchors.size else np.full(missing.size, -1)
    before = np.where(i > 0, before, -1)
    after = matched[anchors[np.minimum(i, anchors.size - 1)]] if anchors.size else np.full(missing.size, -1)
    after = np.where(i < anchors.size, after, len(lines) - 1)
    count = np.clip(after - before, 1, 1000)
    gap, where = np.empty(missing.size), np.empty(missing.size, np.int64)
    for rows in _chunks(count):  # up to 1000 blocks for each missing pose: bounded in chunks
        owner = np.repeat(np.arange(rows.stop - rows.start), count[rows])
        block = np.clip(before[rows][owner] + 1 + _ranks(count[rows]), 0, len(lines) - 1)
        target = reference.tip[missing[rows][owner]]
        distance = distance_to_segment(target, ends.tip[np.maximum(block - 1, 0)], ends.tip[block])
        distance = np.nan_to_num(distance, nan=np.inf)
        order = np.lexsort((block, distance, owner))
        best = order[np.r_[True, owner[order][1:] != owner[order][:-1]]]
        gap[rows], where[rows] = distance[best], block[best]
    # the first pose of each run: the first block whose end leaves the CL segment into it
    first = np.flatnonzero(np.r_[True, np.diff(missing) > 1] & (before >= 0) & (before + 1 < where))
    if first.size:
        span = where[first] - before[first]
        for rows in _chunks(span):
            owner = np.repeat(np.arange(rows.stop - rows.start), span[rows])
            run = first[rows][owner]
            block = before[run] + 1 + _ranks(span[rows])
            pose = missing[run]
            off = ~(distance_to_segment(ends.tip[block], reference.tip[pose - 1], reference.tip[pose]) <= tol)
            left = np.full(rows.stop - rows.start, np.iinfo(np.int64).max)
            np.minimum.at(left, owner[off], block[off])
            found = left < where[first[rows]]
            at = first[rows][found]
            where[at] = left[found]
            gap[at] = np.nan_to_num(distance_to_segment(reference.tip[missing[at]], ends.tip[where[at] - 1],
                                                        ends.tip[where[at]]), nan=np.inf)
    for j, k in enumerate(missing):
        near = f" (the move passes {gap[j]:.4f} mm from it)" if math.isfinite(gap[j]) else ""
        findings.append(Finding(int(lines[where[j]]), "reach", "no block end reaches this CL point" + near,
                                cl_line=int(reference.line[k]), value=float(gap[j]), limit=tol))


def _feed(program: GcodeProgram, reference: Reference, machine: Machine, matched: np.ndarray, pieces: _Pieces,
          curves: Curves, follows: np.ndarray, findings: list[Finding]) -> tuple[float | None, float | None]:
    """Programmed feeds against the timed G1 blocks, as speed ratios (> 1: too fast).

    - CL moves per minute: the tip speed of each block (the length of its tip path over its
      duration) over the programmed feed of its CL segments (the lowest, if several);
    - inverse-time CL moves (FEDRAT/INVERS) give a duration: the blocks from the one reaching
      the move's start to the one reaching its end take no less;
    - CL moves where the tip stands still: the speed of the rotary joints (theta1, theta2
      together) of each block, at most the machine's ``timing.rotary_feed``.

    Returns the largest ratio, and the largest over the fastest sample interval within a block
    (near the pole the joint interpolation moves the tip unevenly within a block: reported, not
    a finding).
    """
    moves = curves.moves
    timed = follows & (program.duration[moves] > 0) & ~pieces.lost[moves]
    step = norms(np.diff(curves.tip, axis=0))  # consecutive points; across moves dropped
    within = np.ones(len(step), bool)
    within[(curves.start + curves.n)[:-1]] = False
    step = np.where(within, step, 0.0)
    minutes = program.duration[moves] / 60.0
    speed = np.add.reduceat(step, curves.start) / minutes if len(step) else np.zeros(0)  # mm/min
    peak = np.maximum.reduceat(step, curves.start) * curves.n / minutes if len(step) else np.zeros(0)
    lowest, inverse = np.full(len(moves), np.inf), np.zeros(len(moves), bool)
    travels, turns = np.zeros(len(moves), bool), np.zeros(len(moves), bool)
    for rows, owner, a, b in pieces.chunks(moves):
        size = rows.stop - rows.start
        travel = norms(reference.tip[b] - reference.tip[a]) >= STILL_TIP
        per_minute = np.where(travel & ~reference.inverse_time[b], reference.feed[b], np.nan)
        np.fmin.at(lowest, np.arange(rows.start, rows.stop)[owner], per_minute)
        inverse[rows] = np.bincount(owner, travel & reference.inverse_time[b], minlength=size) > 0
        travels[rows] = np.bincount(owner, travel, minlength=size) > 0
        turns[rows] = np.bincount(owner, a != b, minlength=size) > 0
    lowest[inverse] = np.inf
    still = ~travels & turns
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(timed & np.isfinite(lowest), speed / lowest, np.nan)
        # the rounding of the written block ends, as a share of the length the feed allows
        ratio_slack = FEED_SLACK + FEED_LENGTH_SLACK / (lowest * minutes)
        peak_ratio = np.where(timed & np.isfinite(lowest), peak / lowest, np.nan)
        turn = np.degrees(norms(program.joints[moves, 3:] - program.joints[moves - 1, 3:]))
        rotary_ratio = np.where(timed & still, turn / minutes / machine.timing.rotary_feed, np.nan)
    for i in np.flatnonzero(ratio > 1 + ratio_slack):
        m = moves[i]
        findings.append(Finding(int(program.line[m]), "feed", f"tool tip at {speed[i]:.1f} mm/min, programmed "
                                f"{lowest[i]:.1f} mm/min", cl_line=int(reference.line[pieces.last[m]]),
                                value=float(ratio[i]), limit=1.0))
    for i in np.flatnonzero(rotary_ratio > 1 + FEED_SLACK):
        m = moves[i]
        findings.append(Finding(int(program.line[m]), "feed", f"the table turns at {turn[i] / minutes[i]:.1f} "
                                f"deg/min with the tip standing still (max {machine.timing.rotary_feed:g} deg/min, "
                                f"timing.rotary_feed)", cl_line=int(reference.line[pieces.last[m]]),
                                value=float(rotary_ratio[i]), limit=1.0))
    # inverse time: whole CL moves between two reached poses
    k = np.flatnonzero(reference.inverse_time[1:] & (matched[1:] >= 0) & (matched[:-1] >= 0)
                       & (norms(np.diff(reference.tip, axis=0)) >= STILL_TIP)) + 1
    elapsed = np.r_[0.0, np.cumsum(np.nan_to_num(program.duration))]
    taken = elapsed[matched[k] + 1] - elapsed[matched[k - 1] + 1]
    with np.errstate(divide="ignore"):
        inverse_ratio = 60.0 / reference.feed[k] / taken
    for j in np.flatnonzero(inverse_ratio > 1 + FEED_SLACK):
        findings.append(Finding(int(program.line[matched[k[j]]]), "feed", f"the move takes {taken[j]:.4f} s, "
                                f"programmed {60.0 / reference.feed[k[j]]:.4f} s (inverse time)",
                                cl_line=int(reference.line[k[j]]), value=float(inverse_ratio[j]), limit=1.0))
    return nanmax(np.r_[ratio, inverse_ratio, rotary_ratio]), nanmax(peak_ratio)
