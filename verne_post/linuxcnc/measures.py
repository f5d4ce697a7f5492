"""What a LinuxCNC run did, measured against the program and the CL path: the tool tip of every
servo sample by forward kinematics against the program's own joint-space path
(:func:`path_deviation`) and against the CL file's feed moves (:func:`cl_deviation`), and the time
each block took against the time the program gives it (:func:`block_times`). Units: mm, s; tips
in the table frame."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..api import forward_kinematics
from ..errors import InputError
from ..machine import Machine
from ..verify.gcode_reader import GcodeProgram, read_gcode
from .simulate import SimulationResult

#: Sample points queried at once against a path (bounds the memory of a long run).
CHUNK = 1 << 16
#: Planned block durations (s) the time table is split at (the issue's table: under 10 ms, ...).
DURATION_BINS = (0.01, 0.02, 0.05)


@dataclass(frozen=True, eq=False)
class PathDeviation:
    """The tip of each servo sample against the program's own joint-space path (mm, by FK).

    ``deviation`` (S,) mm: distance of each sample's tip to the nearest point of the tips of the
    program's blocks, each block's straight joint-space line sampled densely; ``rapid`` (S,) the
    sample runs a move between cuts (G0 or a G1 marked RAPID); ``feeds`` and ``between_cuts``
    the largest deviation of each kind (0 if none); ``spacing`` mm, the densest tip spacing of
    the sampled path (the measure's own error is below spacing^2 / (8 radius) on a curve).
    """

    deviation: np.ndarray
    rapid: np.ndarray
    feeds: float
    between_cuts: float
    worst_line: int
    spacing: float


def program_blocks(text: str, machine: Machine) -> GcodeProgram:
    """The program's motion blocks as verne-post reads them (``verify.gcode_reader``)."""
    return read_gcode(text, controller=machine.controller.profile())


def path_deviation(machine: Machine, text: str, result: SimulationResult, *, spacing: float = 0.2) -> PathDeviation:
    """How far the executed tip leaves the program's path: see :class:`PathDeviation`."""

    program = program_blocks(text, machine)
    ok = np.all(np.isfinite(program.joints), axis=1)
    ends, lines = program.joints[ok], program.line[ok]
    rapid, lengths = program.rapid[ok], np.nan_to_num(program.tool_length[ok], nan=0.0)
    if len(ends) == 0:
        raise InputError("the program has no block with all five axes")
    _, _, tips = _dense_path(machine, ends, lengths, spacing)
    sample_block = np.maximum(_sample_blocks(lines, result), 0)
    sampled = forward_kinematics(machine, result.joints, tool_length=lengths[sample_block]).tip
    best = _to_polyline(sampled, tips, np.ones(len(tips), bool), spacing)
    is_rapid = rapid[sample_block]
    feeds = float(np.nanmax(best[~is_rapid], initial=0.0))
    between = float(np.nanmax(best[is_rapid], initial=0.0))
    worst = int(lines[sample_block[int(np.nanargmax(best))]]) if len(best) else 0
    step = np.linalg.norm(np.diff(tips, axis=0), axis=1)
    return PathDeviation(best, is_rapid, feeds, between, worst, float(step.max(initial=0.0)))


def _dense_path(machine: Machine, ends: np.ndarray, lengths: np.ndarray, spacing: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each block's straight joint-space line sampled until its tips are ``spacing`` apart or closer
    and the tip curve between two of them leaves their chord by under ``spacing / 20``: (points
    (P, 5), the block of each (P,), their tips (P, 3))."""
    pieces = np.ones(len(ends), dtype=np.int64)
    pieces[1:] = np.maximum(1, np.ceil(np.degrees(np.abs(np.diff(ends[:, 3:], axis=0))).max(axis=1)))
    for _ in range(12):
        points, owner, fraction = _pieces(ends, pieces)
        tips = forward_kinematics(machine, points, tool_length=lengths[owner]).tip
        step = np.r_[0.0, np.linalg.norm(np.diff(tips, axis=0), axis=1)]
        middle = points - 0.5 * (points - np.r_[points[:1], points[:-1]])
        middle_tips = forward_kinematics(machine, middle, tool_length=lengths[owner]).tip
        previous = np.r_[tips[:1], tips[:-1]]
        bow = np.linalg.norm(middle_tips - 0.5 * (tips + previous), axis=1)
        coarse = (fraction > 0) & ((step > spacing) | (bow > spacing / 20))
        blocks = np.unique(owner[coarse])
        if len(blocks) == 0 or pieces.sum() > 5_000_000:
            break
        pieces[blocks] *= 2
    return points, owner, tips


def _pieces(ends: np.ndarray, pieces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points along each block's joint-space line: block 0 its end only, block k ``pieces[k]``
    points after its start; the block of each and its fraction along it (0 for block 0)."""
    owner = np.repeat(np.arange(len(ends)), np.r_[1, pieces[1:]])
    start = np.r_[0, np.cumsum(np.r_[1, pieces[1:]])[:-1]]
    rank = np.arange(len(owner)) - start[owner] + 1
    fraction = np.where(owner > 0, rank / pieces[owner], 0.0)
    before = ends[np.maximum(owner - 1, 0)]
    points = before + fraction[:, None] * (ends[owner] - before)
    return points, owner, fraction


def _to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    length2 = np.einsum("ij,ij->i", ab, ab)
    s = np.where(length2 > 0, np.einsum("ij,ij->i", p - a, ab) / np.where(length2 > 0, length2, 1.0), 0.0)
    s = np.clip(s, 0.0, 1.0)
    return np.linalg.norm(p - (a + s[:, None] * ab), axis=1)




def _sample_blocks(lines: np.ndarray, result: SimulationResult) -> np.ndarray:
    """(S,) the block (index into ``lines``, the blocks' program lines in order) each sample runs:
    the one LinuxCNC's line pin names, else the last one named before it (-1 before any)."""
    sample_line = result.line if len(result.line) == len(result.t) else np.zeros(len(result.t), np.int64)
    named = np.searchsorted(lines, sample_line)
    named = np.where((named < len(lines)) & (lines[np.minimum(named, len(lines) - 1)] == sample_line), named, -1)
    index = np.where(named >= 0, np.arange(len(named)), 0)
    np.maximum.accumulate(index, out=index)
    return np.where(named[index] >= 0, named[index], -1)


def _to_polyline(points: np.ndarray, vertices: np.ndarray, joined: np.ndarray, spacing: float) -> np.ndarray:
    """(P,) mm: distance of each point to the polyline through ``vertices`` (V, 3), vertex k joined
    to k + 1 where ``joined[k + 1]`` (a lone vertex counts as a point), in chunks. The vertices must
    lie closer together than the distances that matter.

    A segment of at most ``spacing`` (mm) nearest a point has an end within half of it of the
    point's foot on it, so within (distance to the nearest vertex) + spacing / 2 of the point:
    every vertex that close is searched, not only the nearest few (a path that passes one point
    many times, pass after pass, has many vertices there, and the nearest few may all belong to
    other passes)."""
    tree = cKDTree(vertices)
    half = 0.5 * spacing
    last = len(vertices) - 1

    def to_segments(point: np.ndarray, vertex: np.ndarray) -> np.ndarray:
        """Each point's distance to the segments (vertex - 1, vertex) and (vertex, vertex + 1)."""
        found = np.full(len(point), np.inf)
        for side in (-1, 0):
            a = np.clip(vertex + side, 0, last)
            b = np.clip(a + 1, 0, last)
            found = np.minimum(found, _to_segment(point, vertices[a], vertices[np.where(joined[b], b, a)]))
        return found

    best = np.full(len(points), np.inf)
    for start in range(0, len(points), CHUNK):
        chunk = points[start:start + CHUNK]
        k = min(4, len(vertices))
        distance, nearest = tree.query(chunk, k=k)
        distance, nearest = distance.reshape(len(chunk), -1), nearest.reshape(len(chunk), -1)
        found = np.min(np.column_stack([to_segments(chunk, nearest[:, c]) for c in range(k)]), axis=1)
        # where the k-th nearest vertex is still within reach, every vertex within it (the servo
        # samples of a standstill are one point: each distinct point once)
        wide = np.flatnonzero((distance[:, -1] <= distance[:, 0] + half) & (k < len(vertices)))
        if wide.size:
            unique, back = np.unique(chunk[wide], axis=0, return_inverse=True)
            reach = np.zeros(len(unique))
            np.maximum.at(reach, back.ravel(), distance[wide, 0] + half)
            near = tree.query_ball_point(unique, reach, return_sorted=False)
            count = np.fromiter((len(v) for v in near), np.int64, len(near))
            owner = np.repeat(np.arange(len(unique)), count)
            vertex = np.fromiter((i for v in near for i in v), np.int64, int(count.sum()))
            least = np.full(len(unique), np.inf)
            for rows in range(0, len(owner), CHUNK):  # pairs in chunks
                part = slice(rows, rows + CHUNK)
                np.minimum.at(least, owner[part], to_segments(unique[owner[part]], vertex[part]))
            found[wide] = np.minimum(found[wide], least[back.ravel()])
        best[start:start + CHUNK] = found
    return np.where(np.isfinite(best), best, np.nan)


@dataclass(frozen=True, eq=False)
class ClDeviation:
    """The tip of each feed sample against the CL file's feed moves (mm, table frame).

    ``deviation`` (S,) mm, NaN on samples of moves between cuts (they leave the CL rapids by
    design: docs/moves-between-cuts.md); ``feeds`` the largest; ``worst_line`` the program line
    where it is; ``spacing`` mm the CL path's sampling (its chords are exact: the CL path is straight
    between its points).
    """

    deviation: np.ndarray
    feeds: float
    worst_line: int
    spacing: float


def cl_deviation(machine: Machine, text: str, result: SimulationResult, tip: np.ndarray, rapid: np.ndarray,
                 *, spacing: float = 0.2) -> ClDeviation:
    """How far the executed tip leaves the CL path's feed moves: ``tip`` (N, 3) mm, the CL points in
    the table frame (the work offset added), ``rapid`` (N,) their rapid flags; each sample of a feed
    block by FK against the straight CL segments into the feed points."""
    program = program_blocks(text, machine)
    ok = np.all(np.isfinite(program.joints), axis=1)
    lines, lengths = program.line[ok], np.nan_to_num(program.tool_length[ok], nan=0.0)
    if not ok.any():
        raise InputError("the program has no block with all five axes")
    block = _sample_blocks(lines, result)
    feed = (block >= 0) & ~program.rapid[ok][np.maximum(block, 0)]
    sampled = forward_kinematics(machine, result.joints[feed], tool_length=lengths[block[feed]]).tip
    # the CL feed segments, each cut into pieces of at most ``spacing``: a polyline with breaks
    step = np.linalg.norm(np.diff(tip, axis=0), axis=1)
    pieces = np.r_[1, np.where(~rapid[1:], np.maximum(1, np.ceil(step / spacing)), 1)].astype(np.int64)
    owner = np.repeat(np.arange(len(tip)), pieces)
    first = np.r_[0, np.cumsum(pieces)[:-1]]
    rank = np.arange(len(owner)) - first[owner] + 1
    fraction = rank / pieces[owner]
    before = tip[np.maximum(owner - 1, 0)]
    vertices = before + fraction[:, None] * (tip[owner] - before)
    joined = (owner > 0) & ~rapid[owner]
    deviation = np.full(len(result.t), np.nan)
    deviation[feed] = _to_polyline(sampled, vertices, joined, spacing) if len(sampled) else np.empty(0)
    worst = int(np.nanargmax(deviation)) if np.any(np.isfinite(deviation)) else -1
    return ClDeviation(deviation, float(np.nanmax(deviation, initial=0.0)) if worst >= 0 else 0.0,
                       int(lines[block[worst]]) if worst >= 0 else 0, spacing)


@dataclass(frozen=True, eq=False)
class BlockTimes:
    """Each block's time as LinuxCNC ran it against the time the program gives it (s).

    ``line`` (B,) program lines of the blocks; ``planned`` (B,) s the block's duration at its F
    (NaN where the program gives none: G0); ``executed`` (B,) s the servo samples LinuxCNC spent
    on the block (its ``motion.program-line``); ``bins``: per range of planned duration (``label``,
    blocks, planned s, executed s).
    """

    line: np.ndarray
    planned: np.ndarray
    executed: np.ndarray
    bins: tuple[tuple[str, int, float, float], ...]

    @property
    def lost(self) -> np.ndarray:
        """(B,) s: executed minus planned (NaN where not planned)."""
        return self.executed - self.planned

    def worst(self, count: int = 10) -> list[tuple[int, float, float]]:
        """The ``count`` blocks that lost most time: (line, planned s, executed s)."""
        lost = np.nan_to_num(self.lost, nan=-np.inf)
        order = np.argsort(-lost, kind="stable")[:count]
        return [(int(self.line[i]), float(self.planned[i]), float(self.executed[i])) for i in order
                if np.isfinite(lost[i]) and lost[i] > 0]


def block_times(machine: Machine, text: str, result: SimulationResult) -> BlockTimes:
    """The time LinuxCNC spent on each block of the program (:class:`BlockTimes`)."""
    program = program_blocks(text, machine)
    named = _sample_blocks(program.line, result)
    counted = (named >= 0) & (result.line == program.line[np.maximum(named, 0)])  # the pin names it
    executed = np.bincount(named[counted], minlength=len(program.line)) * result.period
    planned = program.duration
    edges = np.r_[0.0, DURATION_BINS, np.inf]
    bins = []
    for low, high in itertools.pairwise(edges):
        inside = np.isfinite(planned) & (planned >= low) & (planned < high)
        label = (f"under {1000 * high:g} ms" if low == 0 else f"over {1000 * low:g} ms" if not np.isfinite(high)
                 else f"{1000 * low:g}-{1000 * high:g} ms")
        bins.append((label, int(inside.sum()), float(planned[inside].sum()), float(executed[inside].sum())))
    return BlockTimes(program.line, planned, executed, tuple(bins))
