"""The end of a reading: the reader's pose rows and runs become the :class:`Toolpath` (the common
frame, mm, feeds per pose, the notes of a ``--feed`` default)."""

from __future__ import annotations

from array import array

import numpy as np

from ..errors import InputError
from .state import MOTION, PoseRows, ReaderState, validate_poses
from .toolpath import Toolpath


def toolpath_of(state: ReaderState) -> Toolpath:
    """The toolpath the reader's records made, in the common frame and in mm (the state's pose
    rows are given up to it)."""
    n = len(state.rows)
    if n == 0:
        raise InputError("no motion records in file", source=state.src)
    arr = state.rows.array()
    tip, axis = arr[:, :3].copy(), arr[:, 3:].copy()
    line = np.frombuffer(state.lines, dtype=np.int64).copy()
    del arr
    state.rows, state.lines = PoseRows(), array("q")  # read: the room goes to the arrays
    validate_poses(tip, axis, line, state.src, "GOTO")
    axis /= np.sqrt(np.einsum("ij,ij->i", axis, axis))[:, None]
    starts = np.array([r[0] for r in state.runs], dtype=np.int64)
    counts = np.diff(np.append(starts, n))
    feed = np.repeat(np.array([r[1] for r in state.runs], dtype=float), counts)
    inverse = np.repeat(np.array([r[2] for r in state.runs], dtype=bool), counts)
    tool = np.repeat(np.array([r[3] for r in state.runs], dtype=np.int64), counts)
    frame = np.repeat(np.array([r[4] for r in state.runs], dtype=np.int64), counts)
    tip, axis = _to_common_frame(state, tip, axis, frame, line)
    tip *= state.scale
    motion = np.zeros(n, dtype=np.int8)
    if state.motion:
        motion[np.fromiter(state.motion.keys(), dtype=np.int64)] = np.fromiter(state.motion.values(), dtype=np.int8)
    rapid = motion == MOTION["rapid"]
    for idx, f in state.feed_override.items():
        feed[idx] = f
        inverse[idx] = False
    feed[rapid] = np.nan
    inverse[rapid] = False
    notes: tuple[str, ...] = ()
    if state.default_feed is not None:
        before = np.arange(n) < (n if state.first_fedrat is None else state.first_fedrat)
        given = before & ~rapid
        if state.feed_override:
            given[np.fromiter(state.feed_override.keys(), dtype=np.int64)] = False
        used = int(given.sum())
        if used:
            first = int(line[np.argmax(given)])
            notes = (f"FEED {state.default_feed:g} MM/MIN FROM --feed FOR THE {used} FEED MOVES BEFORE THE FIRST "
                     f"FEDRAT (FROM CL LINE {first})",)
        else:
            state.warn(None, f"--feed {state.default_feed:g} not used: a FEDRAT comes before every feed move")
    return Toolpath(
        source=state.src, tip=np.ascontiguousarray(tip), axis=np.ascontiguousarray(axis), line=line,
        rapid=rapid, feed=feed, tool=tool, inverse_time=inverse,
        events=tuple(e for e in state.events if e is not None), part_name=state.part_name, units=state.units,
        warnings=state.warnings.lines(), dialect=state.dialect.describe(state.arc_direction), motion=motion,
        notes=notes,
    )  # fmt: skip

def _to_common_frame(state: ReaderState, tip: np.ndarray, axis: np.ndarray, frame: np.ndarray,
                     line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Apply the frame records as the dialect says (``apply``), or bring every ``local`` frame
    into the first pose's frame so that one work offset places the whole part."""
    used = sorted(set(np.unique(frame).tolist()))
    if state.dialect.frames == "apply":
        targets = {fid: state.frames[fid] for fid in used if fid != 0}
    else:
        ref = int(frame[0])
        R0, o0 = state.frames[ref]  # the first MCS (frame 0 takes the first frame record)
        distinct = [fid for fid in used if fid != ref and not _same_frame(state.frames[fid], (R0, o0))]
        if distinct:
            first = int(line[np.argmax(np.isin(frame, distinct))])
            state.warn(first, f"{len(distinct) + 1} different machine coordinate systems (MSYS/CSYS/ORIGIN): "
                      "later operations are transformed into the first one's frame")
        targets = {fid: (R0.T @ state.frames[fid][0], R0.T @ (state.frames[fid][1] - o0)) for fid in distinct}
    for fid, (R, o) in targets.items():
        m = frame == fid
        tip[m] = o + tip[m] @ R.T
        axis[m] = axis[m] @ R.T
    return tip, axis


def _same_frame(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> bool:
    return bool(np.allclose(a[0], b[0], atol=1e-9) and np.allclose(a[1], b[1], atol=1e-9))
