"""verne-post verify: what a joint-space program makes the VERNE do, certified from its text.

The program is read back from its text as the controller runs it (:mod:`.gcode_reader`, not the
writer's arrays), and the tool tip and axis at every block end and along the joint-space line
between block ends (the controller interpolates the joints linearly) come from the forward
kinematics (:func:`.api.forward_kinematics`): a route independent of the inverse kinematics
that made the joints. Checked, each finding naming the G-code line (and the CL line):

- the program: what the controller would refuse (G1 without a feed, ...), no M2/M30 (cut
  off), tool lengths: DELTA of each ``(TOOL n LENGTH l DELTA d)`` = spindle nose + LENGTH;
- at every sample: joint travel (sliders, tilt, limited rotary), reach, leg I rod clearance
  and singularity margins;
- the joint velocities the G1 block durations imply (rapids run at the controller's speeds);
- against the CL path (``against``): every CL point reached by a block end (``tol``,
  ``axis_tol``); the tip within ``tol`` (mm) and the axis within ``axis_tol`` (degrees) of the
  CL segments the block belongs to (arcs are already expanded into segments by the CL reader,
  within its chordal tolerance), at its end and between; no G0 where the CL path feeds; the
  tip speed each G1 block implies not above the programmed feed (inverse-time CL moves: not
  done in less than their time; turns on the spot: timing.rotary_feed of the machine file).

Sampling, and why the maximum between samples is bounded: along a block the tip is a smooth
curve t(f) of the joint fraction f. Between samples h apart it leaves the chord of its samples
by at most max|t''| h^2 / 8, and the distance to a segment is convex along that chord, so the
largest distance is at most the largest sampled one plus max|t''| h^2 / 8. max|t''| h^2 is
estimated by the largest second difference of the samples (exact for a quadratic curve; the
blocks are short, so the third-derivative term is small). Each feed block is first sampled at
``FIRST_INTERVALS`` intervals; where the estimate shows that the sampling error could exceed
``SAMPLING_SHARE`` of the tolerance, the block is sampled again, densely enough (at most
``MAX_INTERVALS``). The same holds for the axis (angles on the unit sphere, chords for small
angles). The reported deviations include this bound. Rapids: ``RAPID_INTERVALS`` intervals
for travel, reach and margins.
"""

from __future__ import annotations

import bisect
import itertools
import math
from collections.abc import Iterable
from dataclasses import dataclass, fields, is_dataclass, replace
from typing import Any

import numpy as np

from ..api import JOINT_NAMES, classify, forward_kinematics, joint_bounds, pose_margins
from ..cl.toolpath import Toolpath
from ..errors import InputError
from ..kinematics import Margins
from ..machine import Machine
from ..motion.linearise import angle_to_arc, distance_to_segment
from ..motion.poses import MachinePoses
from .gcode_reader import GcodeProgram, ReadState, read_gcode

__all__ = ["Finding", "Reference", "Verification", "Verifier", "verify_blocks", "verify_program"]

DEFAULT_TOL = 0.005  # mm, when neither the caller nor the program header gives one
DEFAULT_AXIS_TOL = 0.05  # deg
FIRST_INTERVALS = 3
MAX_INTERVALS = 256
SAMPLING_SHARE = 0.1
RAPID_INTERVALS = 32
DEFAULT_RAPID_TOL = 0.5  # mm: a rapid's tip from its CL line, when neither caller nor header gives one
#: mm: how far below its CL line a rapid may pass: the rounding of the written joints and the
#: forward kinematics' convergence, no more (a rapid never approaches the part on the way).
RAPID_DIP_TOL = 1e-3
#: mm: a DELTA comment further than this from spindle nose + LENGTH is a finding (the joints
#: were computed for another tool length, which moves the tip by that much along the axis).
DELTA_TOL = 1e-3
#: Relative slack on the programmed feed and the joint velocity limits for the rounding of the
#: written numbers (block ends to 1e-4 mm, F to its decimals).
FEED_SLACK = 0.01
JOINT_SPEED_SLACK = 0.01
#: mm: what the rounding of a block's two ends can add to its tip path. Sliders are written to
#: 1e-4 mm and angles to 1e-5 deg (about 1e-4 mm at the table's reach): each end may sit up to
#: ~2e-4 mm from the planned pose, so a block of a few micrometres can look several per cent
#: faster than planned without being so. Absolute, so it matters only for tiny blocks.
FEED_LENGTH_SLACK = 5e-4
#: mm: a CL move whose tip travels less than this turns on the spot (as the planner's TIP_EPS).
STILL_TIP = 1e-4
#: Point-segment pairs and poses evaluated at once (bound the memory of a long program).
_PAIR_CHUNK = 1 << 17
_POSE_CHUNK = 1 << 15

_JOINT_WORDS = ("slider rho1", "slider rho2", "slider rho3", "tilt theta1", "rotary theta2")


@dataclass(frozen=True)
class Reference:
    """The CL path a program must follow, in the table frame: as :class:`.toolpath.Toolpath`
    (``tip`` (N, 3) mm, unit ``axis``, ``line``, ``rapid``, ``feed`` mm/min or 1/min where
    ``inverse_time``)."""

    source: str
    tip: np.ndarray
    axis: np.ndarray
    line: np.ndarray
    rapid: np.ndarray
    feed: np.ndarray
    inverse_time: np.ndarray

    @classmethod
    def of(cls, path: Toolpath | MachinePoses, work_offset: Iterable[float] = (0.0, 0.0, 0.0)) -> Reference:
        """From a CL toolpath (part frame) and the work offset (mm), or from machine poses
        (already in the table frame: offset 0)."""
        return cls(path.source, np.asarray(path.tip, float) + np.asarray(tuple(work_offset), float), path.axis,
                   path.line, path.rapid, path.feed, path.inverse_time)

    def rows(self, index: slice | np.ndarray) -> Reference:
        return replace(self, **{name: getattr(self, name)[index] for name in _POSE_FIELDS})

    def then(self, other: Reference) -> Reference:
        """These poses, then those of ``other``."""
        return replace(self, **{name: np.concatenate([getattr(self, name), getattr(other, name)])
                                for name in _POSE_FIELDS})


_POSE_FIELDS = ("tip", "axis", "line", "rapid", "feed", "inverse_time")


@dataclass(frozen=True)
class Finding:
    """Something the program does wrong, at a G-code line (and the CL line it concerns)."""

    line: int
    kind: str  # program, tool, limit, unreachable, rod_clearance, singular, joint_speed, reach, order, motion,
    #            tip, axis, feed
    message: str
    cl_line: int | None = None
    value: float | None = None  # the figure found (mm, deg, ratio or margin, as the message says)
    limit: float | None = None


@dataclass(frozen=True)
class Verification:
    """Outcome of :func:`verify_program`; ``ok`` when there are no findings."""

    source: str
    against: str | None
    findings: tuple[Finding, ...]
    blocks: int
    samples: int
    tol: float  # mm
    axis_tol: float  # deg
    work_offset: tuple[float, float, float]
    tip_deviation: float | None  # mm, largest along the feed blocks and at block ends (sampling bound included)
    axis_deviation: float | None  # deg
    cl_points: int | None
    cl_points_reached: int | None
    feed_ratio: float | None  # largest tip speed of a block (path length / duration) over the programmed feed
    peak_feed_ratio: float | None  # the same for the fastest sample interval within a block (information)
    joint_speed_ratio: dict[str, float | None]  # largest joint velocity over its limit, G1 blocks
    smallest_margins: dict[str, float | None]
    rapid_tol: float = DEFAULT_RAPID_TOL  # mm
    # mm: with the CL path, the largest distance of a rapid's tip from where it may be (its CL line,
    # not below it; a retract or approach ray along a CL pose's axis; or above every feed point)
    rapid_deviation: float | None = None
    # mm: with the CL path, the largest dip below a rapid's CL line; without, below the lower end
    # of each run of rapid blocks
    rapid_dip: float | None = None

    @property
    def ok(self) -> bool:
        return not self.findings

    def certificate(self) -> str:
        """The header line of a program that passed, e.g. ``VERIFIED: MAX TIP DEVIATION ...``."""
        parts = ["VERIFIED:"]
        if self.tip_deviation is not None and self.axis_deviation is not None:
            parts.append(f"MAX TIP DEVIATION {self.tip_deviation:.4f} MM, MAX AXIS DEVIATION "
                         f"{self.axis_deviation:.3f} DEG,")
        if self.rapid_deviation is not None:
            parts.append(f"MAX RAPID DEVIATION {self.rapid_deviation:.4f} MM,")
        parts.append("ALL LIMITS HELD")
        return " ".join(parts)

    def report(self) -> dict[str, Any]:
        """JSON-ready summary (mm, degrees; null where a figure does not apply)."""
        return {
            "source": self.source,
            "against": self.against,
            "ok": self.ok,
            "findings": [{"line": f.line, "cl_line": f.cl_line, "kind": f.kind, "message": f.message,
                          "value": _number(f.value), "limit": _number(f.limit)} for f in self.findings],
            "blocks": self.blocks,
            "samples": self.samples,
            "tolerances": {"tip_mm": self.tol, "axis_deg": self.axis_tol},
            "work_offset_mm": list(self.work_offset),
            "max_tip_deviation_mm": _number(self.tip_deviation),
            "max_axis_deviation_deg": _number(self.axis_deviation),
            "cl_points": self.cl_points,
            "cl_points_reached": self.cl_points_reached,
            "max_feed_ratio": _number(self.feed_ratio),
            "max_feed_ratio_within_a_block": _number(self.peak_feed_ratio),
            "max_joint_speed_ratio": {k: _number(v) for k, v in self.joint_speed_ratio.items()},
            "rapid_tol_mm": self.rapid_tol,
            "max_rapid_deviation_mm": _number(self.rapid_deviation),
            "max_rapid_dip_mm": _number(self.rapid_dip),
            "smallest_margins": {k: _number(v) for k, v in self.smallest_margins.items()},
        }


def _number(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


def verify_program(text: str | Iterable[str], machine: Machine, *, source: str = "<program>",
                   against: Toolpath | Reference | None = None,
                   work_offset: tuple[float, float, float] | None = None, tol: float | None = None,
                   axis_tol: float | None = None, rapid_tol: float | None = None) -> Verification:
    """Verify program text (one string or its lines) for ``machine``; see the module docstring.

    ``against``: the CL path, as read (part frame: the work offset is ``work_offset``, else the
    program header's, else the machine's) or as a :class:`Reference` (table frame). ``tol`` mm
    and ``axis_tol`` degrees: else the program header's, else 0.005 mm and 0.05 degrees.
    Raises :class:`~verne_post.errors.InputError` for text that is not a program it can read.
    """
    program = read_gcode(text, source)
    header_tol = program.tolerance or (None, None, math.nan)
    tol = float(tol if tol is not None else header_tol[0] if header_tol[0] is not None else DEFAULT_TOL)
    axis_tol = float(axis_tol if axis_tol is not None else header_tol[1] if header_tol[1] is not None
                     else DEFAULT_AXIS_TOL)
    rapid_tol = float(rapid_tol if rapid_tol is not None else header_tol[2] if math.isfinite(header_tol[2])
                      else DEFAULT_RAPID_TOL)
    if not (0 < tol < math.inf and 0 < axis_tol < math.inf and 0 < rapid_tol < math.inf):
        # a header's 0 would match nothing, or all
        raise InputError(f"the tolerances must be positive numbers, not {tol:g} mm, {axis_tol:g} deg and "
                         f"{rapid_tol:g} mm", source=source)
    offset = tuple(work_offset or program.work_offset or machine.work_offset)
    reference = against if isinstance(against, Reference) or against is None else Reference.of(against, offset)
    return verify_blocks(program, machine, reference, tol, axis_tol, offset, rapid_tol=rapid_tol,
                         top=None if reference is None else feed_top(reference))


def feed_top(reference: Reference) -> float:
    """mm, table-frame z: the highest feed point of a CL path (of any point, if it has no feed)."""
    feed = reference.tip[~reference.rapid] if (~reference.rapid).any() else reference.tip
    return float(np.max(feed[:, 2])) if len(feed) else -math.inf


def verify_blocks(program: GcodeProgram, machine: Machine, reference: Reference | None, tol: float,
                  axis_tol: float, work_offset: Iterable[float] = (0.0, 0.0, 0.0), *, overlap: bool = False,
                  final: bool = True, rapid_tol: float = DEFAULT_RAPID_TOL, top: float | None = None
                  ) -> Verification:
    """The checks of :func:`verify_program` on a program already read (tol mm, axis_tol deg,
    rapid_tol mm; ``top``: the highest feed point of the whole CL path, table-frame z mm, above
    which a rapid may go anywhere; default: the reference's).

    A part of a program (:class:`Verifier`): with ``overlap`` the first block and the first CL
    pose are the last ones of the part before, already verified: only the motion from there
    counts; the end of the program is looked for only when ``final``.
    """
    findings = [] if program.end_line is not None or not final else [
        Finding(program.last_line, "program", "the program ends without M2/M30 (cut off?)")]
    findings += [Finding(line, "program", reason) for line, reason in program.problems]
    unknown = ~np.all(np.isfinite(program.joints), axis=1)
    if unknown.any():
        k = int(np.argmax(unknown))
        axes = "".join(a for a, known in zip("XYZAC", np.isfinite(program.joints[k]), strict=True) if not known)
        findings.append(Finding(int(program.line[k]), "program", f"moves with {' '.join(axes)} never programmed: "
                                                                 f"the first motion must give every axis"))
    lengths = _tool_lengths(program, machine, findings)
    motion = _Motion.of(program, machine, lengths, tol, np.radians(axis_tol))
    block, interior, samples = motion.all_samples()
    findings += _limit_findings(machine, program.line[block], interior, samples)
    speed_ratio = _joint_speed(program, machine, findings)
    tip_dev = axis_dev = feed_ratio = peak_ratio = None
    reached = None
    rapid_dev: float | None
    rapid_dip: float | None
    skip = int(overlap)
    if reference is not None:
        tip_dev, axis_dev, feed_ratio, peak_ratio, reached, rapid_dev, rapid_dip = _against(
            program, machine, reference, motion, tol, np.radians(axis_tol), findings, skip, rapid_tol,
            feed_top(reference) if top is None else top)
    else:
        rapid_dev, rapid_dip = None, _run_dips(program, motion, rapid_tol, findings)
    if overlap:  # what the part before found at its last block
        findings = [f for f in findings if f.line != program.line[0]]
    x, y, z = work_offset
    unique: dict[tuple[int, str], Finding] = {}
    for finding in findings:  # one per line and kind: the first (worst or earliest) stays
        unique.setdefault((finding.line, finding.kind), finding)
    margins = samples.margins
    return Verification(
        source=program.source, against=None if reference is None else reference.source,
        findings=tuple(sorted(unique.values(), key=lambda f: (f.line, f.kind))), blocks=len(program) - skip,
        samples=len(block) - skip, tol=tol, axis_tol=axis_tol,
        work_offset=(float(x), float(y), float(z)),
        tip_deviation=tip_dev, axis_deviation=axis_dev,
        cl_points=None if reference is None else len(reference.tip) - skip, cl_points_reached=reached,
        feed_ratio=feed_ratio, peak_feed_ratio=peak_ratio, joint_speed_ratio=speed_ratio,
        smallest_margins={name: _nanmin(getattr(margins, name)) for name in
                          ("serial", "parallel", "machine", "rod_clearance")},
        rapid_tol=rapid_tol, rapid_deviation=rapid_dev, rapid_dip=rapid_dip,
    )


class Verifier:
    """Verification of a long program a part at a time, each part with the CL poses it must
    reach (table frame, :class:`Reference`): memory bounded by the largest part.

    Each part is read on from where the part before left the reading (modal state, position,
    tool) and verified from the last block end of the part before, against its CL poses after
    the last pose of the part before; findings and figures are gathered into one
    :class:`Verification`. A part whose blocks reach no pose of its own (a move back to where
    the program stands) hands its poses on to the next. Tolerances: mm and degrees.
    """

    def __init__(self, machine: Machine, *, source: str, tol: float, axis_tol: float,
                 work_offset: tuple[float, float, float], rapid_tol: float = DEFAULT_RAPID_TOL,
                 top: float | None = None) -> None:
        self.machine, self.source, self.tol, self.axis_tol, self.work_offset = (machine, source, tol, axis_tol,
                                                                                 work_offset)
        self.rapid_tol, self.top = rapid_tol, top  # mm; the whole program's highest feed point (table z)
        self.state: ReadState | None = None
        self.last: GcodeProgram | None = None  # the last block so far (one row)
        self.pending: Reference | None = None  # poses not yet verified: the last one reached, and any after
        self.parts: list[Verification] = []

    def read(self, text: str, reference: Reference | None = None, final: bool = False) -> None:
        """Verify the next part of the program (whole lines) against ``reference``, the next CL
        poses; ``final`` for the last part."""
        program = read_gcode(text, self.source, self.state, final)
        self.state = program.state
        if reference is not None and self.pending is not None:
            reference = self.pending.then(reference)
        if len(program) == 0 and not final:
            self.parts.append(verify_blocks(program, self.machine, None, self.tol, self.axis_tol, self.work_offset,
                                            final=False, rapid_tol=self.rapid_tol, top=self.top))
            self.pending = reference
            return
        overlap = self.last is not None
        if overlap:
            program = _joined_program(self.last, program)
        self.parts.append(verify_blocks(program, self.machine, reference, self.tol, self.axis_tol, self.work_offset,
                                        overlap=overlap, final=final, rapid_tol=self.rapid_tol, top=self.top))
        if len(program):
            self.last = _last_block(program)
        if reference is not None and len(reference.tip):
            self.pending = reference.rows(slice(-1, None))

    def result(self) -> Verification:
        """The verification of every part read."""
        parts = self.parts
        unique: dict[tuple[int, str], Finding] = {}
        for finding in (f for part in parts for f in part.findings):
            unique.setdefault((finding.line, finding.kind), finding)
        against = next((part.against for part in parts if part.against is not None), None)

        def most(name: str, pick: Any = max) -> float | None:
            values = [getattr(part, name) for part in parts if getattr(part, name) is not None]
            return pick(values) if values else None

        def total(name: str) -> int | None:
            values = [getattr(part, name) for part in parts if getattr(part, name) is not None]
            return sum(values) if values else None

        def per_name(name: str, pick: Any) -> dict[str, float | None]:
            names = getattr(parts[0], name) if parts else {}
            out = {}
            for key in names:
                values = [getattr(part, name)[key] for part in parts if getattr(part, name)[key] is not None]
                out[key] = pick(values) if values else None
            return out

        return Verification(
            source=self.source, against=against,
            findings=tuple(sorted(unique.values(), key=lambda f: (f.line, f.kind))),
            blocks=sum(part.blocks for part in parts), samples=sum(part.samples for part in parts), tol=self.tol,
            axis_tol=self.axis_tol, work_offset=self.work_offset,
            tip_deviation=most("tip_deviation"), axis_deviation=most("axis_deviation"),
            cl_points=total("cl_points"), cl_points_reached=total("cl_points_reached"),
            feed_ratio=most("feed_ratio"), peak_feed_ratio=most("peak_feed_ratio"),
            joint_speed_ratio=per_name("joint_speed_ratio", max), smallest_margins=per_name("smallest_margins", min),
            rapid_tol=self.rapid_tol, rapid_deviation=most("rapid_deviation"), rapid_dip=most("rapid_dip"),
        )


_BLOCK_FIELDS = ("joints", "rapid", "inverse_time", "feed", "duration", "line", "tool", "tool_length")


def _last_block(program: GcodeProgram) -> GcodeProgram:
    return replace(program, **{name: getattr(program, name)[-1:] for name in _BLOCK_FIELDS})


def _joined_program(first: GcodeProgram, then: GcodeProgram) -> GcodeProgram:
    """``then`` with the blocks of ``first`` before its own."""
    return replace(then, **{name: np.concatenate([getattr(first, name), getattr(then, name)])
                            for name in _BLOCK_FIELDS})


def _nanmin(values: np.ndarray) -> float | None:
    finite = values[np.isfinite(values)]
    return float(finite.min()) if finite.size else None


# --------------------------------------------------------------------------------------------
# tools


def _tool_lengths(program: GcodeProgram, machine: Machine, findings: list[Finding]) -> np.ndarray:
    """Tool length (mm) per block: the TOOL comment, else the machine's tool table; NaN with a
    finding where neither gives one. DELTA of every comment is checked."""
    nose = machine.geometry.spindle_nose
    for note in program.tool_notes:
        if abs(note.delta - (nose + note.length)) > DELTA_TOL:
            findings.append(Finding(note.line, "tool", f"tool {note.tool}: DELTA {note.delta:.4f} mm is not the "
                                                       f"spindle nose {nose:.4f} mm + LENGTH {note.length:.4f} mm",
                                    value=note.delta, limit=nose + note.length))
    lengths = program.tool_length.copy()
    for tool in np.unique(program.tool[np.isnan(lengths)]):
        rows = np.isnan(lengths) & (program.tool == tool)
        if int(tool) in machine.tools:
            lengths[rows] = machine.tools[int(tool)].length
        else:
            reason = ("motion with no tool loaded (no M6, no TOOL comment)" if tool < 0 else
                      f"tool {tool} has no length: no (TOOL {tool} LENGTH l DELTA d) comment and not in the "
                      f"machine's tool table")
            findings.append(Finding(int(program.line[np.argmax(rows)]), "tool", reason))
    return lengths


# --------------------------------------------------------------------------------------------
# sampling the motion


@dataclass(frozen=True)
class _Poses:
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
           alpha_guess: np.ndarray | None = None) -> _Poses:
        """Poses of joint sets (mm, rad) with tool lengths (mm), where ``valid`` (default all)."""
        n = len(joints)
        valid = np.ones(n, bool) if valid is None else valid
        tip, axis, platform = np.full((n, 3), np.nan), np.full((n, 3), np.nan), np.full((n, 3), np.nan)
        alpha, reachable = np.full(n, np.nan), np.zeros(n, bool)
        margin_parts = []
        for start in range(0, max(n, 1), _POSE_CHUNK):  # chunks bound the kinematics' temporary arrays
            rows = slice(start, start + _POSE_CHUNK)
            use = np.flatnonzero(valid[rows]) + start
            if use.size:
                fk = forward_kinematics(machine, joints[use], tool_length=lengths[use],
                                        alpha_guess=None if alpha_guess is None else alpha_guess[use])
                tip[use], axis[use], alpha[use], platform[use] = fk.tip, fk.axis, fk.alpha, fk.platform
                reachable[use] = fk.reachable
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
class _Curves:
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
    samples: _Poses

    @property
    def start(self) -> np.ndarray:
        return np.cumsum(self.n + 1) - (self.n + 1)

    @property
    def block(self) -> np.ndarray:
        """The block of each interior sample."""
        return np.repeat(self.moves, self.n - 1)

    def take(self, mask: np.ndarray) -> _Curves:
        return _Curves(self.moves[mask], self.n[mask], self.d2_tip[mask], self.d2_axis[mask],
                       self.tip[np.repeat(mask, self.n + 1)], self.axis[np.repeat(mask, self.n + 1)],
                       _rows(self.samples, np.repeat(mask, self.n - 1)))

    @classmethod
    def sample(cls, machine: Machine, joints: np.ndarray, lengths: np.ndarray, ends: _Poses, moves: np.ndarray,
               n: np.ndarray) -> _Curves:
        """Sample the lines from block end m - 1 to m (joints mm/rad) with block m's tool."""
        inner = n - 1
        owner = np.repeat(np.arange(len(moves)), inner)
        first = np.cumsum(inner) - inner
        f = (np.arange(int(inner.sum())) - first[owner] + 1) / n[owner]
        m = moves[owner]
        q = joints[m - 1] + f[:, None] * (joints[m] - joints[m - 1])
        guess = ends.alpha[m - 1] + f * (ends.alpha[m] - ends.alpha[m - 1])
        samples = _Poses.at(machine, q, lengths[m], alpha_guess=np.nan_to_num(guess))
        start_tip, start_axis = ends.tip[moves - 1].copy(), ends.axis[moves - 1].copy()
        retooled = lengths[moves] != lengths[moves - 1]  # after a tool change: the start with the new tool
        if retooled.any():
            fk = forward_kinematics(machine, joints[moves[retooled] - 1], tool_length=lengths[moves[retooled]])
            start_tip[retooled], start_axis[retooled] = fk.tip, fk.axis
        start = np.cumsum(n + 1) - (n + 1)
        inside = start[owner] + np.arange(len(owner)) - first[owner] + 1
        tip, axis = np.empty((int((n + 1).sum()), 3)), np.empty((int((n + 1).sum()), 3))
        tip[start], axis[start] = start_tip, start_axis
        tip[inside], axis[inside] = samples.tip, samples.axis
        tip[start + n], axis[start + n] = ends.tip[moves], ends.axis[moves]
        d2_tip, d2_axis = np.zeros(len(moves)), np.zeros(len(moves))
        if len(owner):
            for d2, points in ((d2_tip, tip), (d2_axis, axis)):
                second = points[inside - 1] - 2 * points[inside] + points[inside + 1]
                d2[:] = np.nan_to_num(np.maximum.reduceat(np.linalg.norm(second, axis=1), first), nan=np.inf)
        return cls(moves, n, d2_tip, d2_axis, tip, axis, samples)


@dataclass(frozen=True)
class _Motion:
    """Poses at the M block ends and along the moves between them, for all the checks."""

    known: np.ndarray  # (M,) block end known (joints and tool length)
    ends: _Poses  # (M,)
    curves: _Curves

    @classmethod
    def of(cls, program: GcodeProgram, machine: Machine, lengths: np.ndarray, tol: float, axis_tol: float
           ) -> _Motion:
        """Sample every move densely enough for the sampling error to stay below
        SAMPLING_SHARE of ``tol`` (mm) and ``axis_tol`` (rad); see the module docstring."""
        q = program.joints
        known = np.all(np.isfinite(q), axis=1) & np.isfinite(lengths)
        ends = _Poses.at(machine, q, lengths, known)
        moves = np.flatnonzero(known[1:] & known[:-1]) + 1
        rapid = program.rapid[moves]
        n = np.where(rapid, RAPID_INTERVALS, FIRST_INTERVALS)
        todo = np.arange(len(moves))
        done = []
        for _ in range(4):
            curves = _Curves.sample(machine, q, lengths, ends, moves[todo], n[todo])
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

    def all_samples(self) -> tuple[np.ndarray, np.ndarray, _Poses]:
        """(block, interior, poses) of the block ends and the interior samples."""
        m = len(self.known)
        block = np.r_[np.arange(m), self.curves.block]
        interior = np.r_[np.zeros(m, bool), np.ones(len(self.curves.block), bool)]
        return block, interior, _joined([self.ends, self.curves.samples])


# --------------------------------------------------------------------------------------------
# limits


def _quantity(joint: int, value: float) -> str:
    return f"{value:.4f} mm" if joint < 3 else f"{np.degrees(value):.4f} deg"


def _worst_per_block(block: np.ndarray, excess: np.ndarray) -> np.ndarray:
    """Index of the largest positive ``excess`` in each block that has one."""
    bad = np.flatnonzero(excess > 0)
    order = bad[np.lexsort((-excess[bad], block[bad]))]
    return order[np.r_[True, block[order][1:] != block[order][:-1]]] if order.size else order


def _limit_findings(machine: Machine, lines: np.ndarray, interior: np.ndarray, poses: _Poses) -> list[Finding]:
    """Travel, reach, rod clearance and singularity margins of samples (G-code ``lines``; block
    ends and ``interior`` samples): the worst sample of each line and kind."""
    lower, upper = joint_bounds(machine)
    t = machine.singularity
    found = poses.margins
    out: list[Finding] = []

    def add(kind: str, excess: np.ndarray, text: Any, value: np.ndarray | None = None, limit: float | None = None
            ) -> None:
        for k in _worst_per_block(lines, np.nan_to_num(excess, nan=-1.0)):
            where = "between block ends: " if interior[k] else ""
            out.append(Finding(int(lines[k]), kind, where + text(k), value=None if value is None else
                               float(value[k]), limit=limit))

    add("unreachable", (~poses.reachable & np.isfinite(poses.joints).all(axis=1)).astype(float),
        lambda k: "the sliders admit no assembly of the parallel module (out of reach)")
    q = poses.joints
    for j in range(5):
        shown = q[:, j] if j < 3 else np.degrees(q[:, j])  # mm, deg in the report
        scale = 1.0 if j < 3 else 180.0 / np.pi
        if np.isfinite(upper[j]):
            add("limit", q[:, j] - upper[j], lambda k, j=j: f"{_JOINT_WORDS[j]} = {_quantity(j, q[k, j])} exceeds "
                f"max {_quantity(j, upper[j])}", shown, float(upper[j] * scale))
        if np.isfinite(lower[j]):
            add("limit", lower[j] - q[:, j], lambda k, j=j: f"{_JOINT_WORDS[j]} = {_quantity(j, q[k, j])} is "
                f"below min {_quantity(j, lower[j])}", shown, float(lower[j] * scale))
    add("rod_clearance", t.rod_clearance_min - found.rod_clearance,
        lambda k: f"leg I rods {found.rod_clearance[k]:.2f} mm apart (min {t.rod_clearance_min:.2f} mm: rods "
                  f"would cross)", found.rod_clearance, t.rod_clearance_min)
    for name, threshold in (("serial", t.serial_min), ("parallel", t.parallel_min), ("machine", t.machine_min)):
        value = getattr(found, name)
        add("singular", threshold - value, lambda k, name=name, value=value, threshold=threshold:
            f"too close to a {name} singularity (margin {value[k]:.4f}, min {threshold:.4f})", value, threshold)
    return out


def _joint_speed(program: GcodeProgram, machine: Machine, findings: list[Finding]) -> dict[str, float | None]:
    """Joint velocities the G1 block durations imply (|step| / duration) against the limits."""
    limit = np.array([getattr(machine.joints, name).velocity for name in JOINT_NAMES])  # mm/s, deg/s
    limit[3:] = np.radians(limit[3:])
    step = np.abs(np.diff(program.joints, axis=0, prepend=np.full((1, 5), np.nan)))
    timed = program.duration > 0  # G1 blocks, between cuts too; G0 runs at the controller's speeds
    with np.errstate(invalid="ignore"):
        ratio = np.where(timed[:, None], step / np.where(timed, program.duration, 1.0)[:, None] / limit, np.nan)
    for j in range(5):
        for k in np.flatnonzero(ratio[:, j] > 1 + JOINT_SPEED_SLACK):
            speed = ratio[k, j] * limit[j]
            unit, shown, top = ("mm/s", speed, limit[j]) if j < 3 else ("deg/s", np.degrees(speed),
                                                                       np.degrees(limit[j]))
            findings.append(Finding(int(program.line[k]), "joint_speed", f"{_JOINT_WORDS[j]} at {shown:.1f} {unit} "
                                    f"(max {top:.1f} {unit}) in {program.duration[k] * 1e3:.3f} ms",
                                    value=float(ratio[k, j]), limit=1.0))
    return {name: _nanmax(ratio[:, j]) for j, name in enumerate(JOINT_NAMES)}


def _nanmax(values: np.ndarray) -> float | None:
    finite = values[np.isfinite(values)]
    return float(finite.max()) if finite.size else None


# --------------------------------------------------------------------------------------------
# against the CL path


def _angle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return 2.0 * np.arcsin(np.clip(np.linalg.norm(u - v, axis=-1) / 2.0, 0.0, 1.0))


def _match(reference: Reference, ends: _Poses, known: np.ndarray, tol: float, axis_tol: float) -> np.ndarray:
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
    good = ((np.linalg.norm(reference.tip[pose] - ends.tip[block], axis=1) <= tol)
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
    pose s - 1 to s; first == last: the block should stay at that pose)."""

    first: np.ndarray  # (M,)
    last: np.ndarray  # (M,)

    def pairs(self, blocks: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(owner, from pose, to pose): every segment of the pieces of ``blocks``."""
        a, b = self.first[blocks], self.last[blocks]
        count = np.maximum(b - a, 1)
        owner = np.repeat(np.arange(len(blocks)), count)
        s = a[owner] + 1 + _ranks(count)
        point = (b == a)[owner]
        return owner, np.where(point, b[owner], s - 1), np.where(point, b[owner], s)


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
        return _Pieces(np.zeros(m_blocks, np.int64), np.full(m_blocks, n - 1, np.int64))
    i = np.searchsorted(anchor_block, np.arange(m_blocks), side="left")
    last = np.where(i < anchor_pose.size, anchor_pose[np.minimum(i, anchor_pose.size - 1)], n - 1)
    first = np.where(i > 0, anchor_pose[np.maximum(i - 1, 0)], 0)
    return _Pieces(first, np.maximum(last, first))


def _deviation(reference: Reference, pieces: _Pieces, blocks: np.ndarray, tip: np.ndarray, axis: np.ndarray,
               tol: float, axis_tol: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tip distance (mm), axis angle (rad) and end pose of the segment of each point's piece
    (points of ``blocks``) nearest to it, tip and axis over ``tol`` (mm) and ``axis_tol`` (rad);
    in chunks of at most _PAIR_CHUNK point-segment pairs."""
    count = np.maximum(pieces.last[blocks] - pieces.first[blocks], 1)
    tip_error, axis_error, nearest = np.empty(len(blocks)), np.empty(len(blocks)), np.empty(len(blocks), np.int64)
    total = np.cumsum(count)
    edges = np.r_[0, np.searchsorted(total, np.arange(_PAIR_CHUNK, total[-1] if total.size else 0, _PAIR_CHUNK)),
                  len(blocks)]
    for start, stop in itertools.pairwise(edges):
        if stop <= start:
            continue
        rows = np.arange(start, stop)
        owner, a, b = pieces.pairs(blocks[rows])
        distance = distance_to_segment(tip[rows][owner], reference.tip[a], reference.tip[b])
        angle = angle_to_arc(axis[rows][owner], reference.axis[a], reference.axis[b])
        # the segment nearest in tip and axis together, each over its tolerance
        cost = distance / tol + angle / axis_tol
        group = np.cumsum(count[rows]) - count[rows]
        nearest_pair = np.flatnonzero(cost == np.repeat(np.minimum.reduceat(cost, group), count[rows]))
        best = nearest_pair[np.r_[True, owner[nearest_pair][1:] != owner[nearest_pair][:-1]]]
        tip_error[rows], axis_error[rows], nearest[rows] = distance[best], angle[best], b[best]
    return tip_error, axis_error, nearest


def _against(program: GcodeProgram, machine: Machine, reference: Reference, motion: _Motion, tol: float,
             axis_tol: float, findings: list[Finding], skip: int, rapid_tol: float, top: float
             ) -> tuple[float, float, float | None, float | None, int, float | None, float | None]:
    """Reach, order, deviation, rapid and feed findings; returns the largest tip deviation (mm),
    axis deviation (deg), feed ratio, peak feed ratio within a block, the number of CL points
    reached (of those after the first ``skip``: the first ``skip`` blocks and poses were
    verified with the part before), the largest rapid deviation and dip (mm, :func:`_rapids`)."""
    m_blocks = len(program)
    lines, cl_lines = program.line, reference.line
    ends = motion.ends
    matched = _match(reference, ends, motion.known, tol, axis_tol)
    reached = np.flatnonzero(matched >= 0)
    for k in reached[_out_of_order(matched[reached])]:
        findings.append(Finding(int(lines[matched[k]]), "order", "reaches this CL point out of the order of the "
                                "CL path", cl_line=int(cl_lines[k])))
        matched[k] = -1
    pieces = _pieces(matched, m_blocks)
    _unreached(reference, matched, ends, lines, tol, findings)

    # deviation at the block ends and the interior samples of feed moves that follow the CL path
    curves = motion.curves
    owner, a, b = pieces.pairs(np.arange(m_blocks))
    segment = a != b  # a piece of one pose has no motion of its own
    # a CL move across a tool change cannot be cut as programmed: the tool that reaches its end
    # is not the one that left its start (the program moves between cuts there)
    tool_at = np.where(matched >= 0, program.tool[np.maximum(matched, 0)], -2)
    retooled = (tool_at[a] != tool_at[b]) & (tool_at[a] != -2) & (tool_at[b] != -2)
    cl_rapid = np.bincount(owner, (reference.rapid[b] | retooled) & segment, minlength=m_blocks) > 0
    cl_feed = np.bincount(owner, ~reference.rapid[b] & ~retooled & segment, minlength=m_blocks) > 0
    cl_feed[0] = False  # the first block comes from wherever the machine stands
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
    ok = np.isfinite(point_tip).all(axis=1)
    point_block, point_tip, point_axis = point_block[ok], point_tip[ok], point_axis[ok]
    tip_error, axis_error, nearest = _deviation(reference, pieces, point_block, point_tip, point_axis, tol,
                                                axis_tol)
    bound_tip, bound_axis = np.zeros(m_blocks), np.zeros(m_blocks)
    bound_tip[curves.moves[follows]] = motion.bound_tip[follows]
    bound_axis[curves.moves[follows]] = motion.bound_axis[follows]
    tip_total = tip_error + bound_tip[point_block]
    axis_total = axis_error + bound_axis[point_block]
    for k in _worst_per_block(point_block, tip_total - tol):
        findings.append(Finding(int(lines[point_block[k]]), "tip", f"tool tip {tip_total[k]:.4f} mm from the CL "
                                f"path (max {tol:g} mm)", cl_line=int(cl_lines[nearest[k]]),
                                value=float(tip_total[k]), limit=tol))
    for k in _worst_per_block(point_block, axis_total - axis_tol):
        findings.append(Finding(int(lines[point_block[k]]), "axis", f"tool axis {np.degrees(axis_total[k]):.4f} "
                                f"deg from the CL path (max {np.degrees(axis_tol):g} deg)",
                                cl_line=int(cl_lines[nearest[k]]), value=float(np.degrees(axis_total[k])),
                                limit=float(np.degrees(axis_tol))))
    feed_ratio, peak_ratio = _feed(program, reference, machine, matched, pieces, curves, follows, findings)
    rapid_dev, rapid_dip = _rapids(program, reference, motion, pieces, skip, rapid_tol, top, findings)
    return (float(tip_total.max(initial=0.0)), float(np.degrees(axis_total.max(initial=0.0))), feed_ratio,
            peak_ratio, int(np.count_nonzero(matched[skip:] >= 0)), rapid_dev, rapid_dip)


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


def _rapids(program: GcodeProgram, reference: Reference, motion: _Motion, pieces: _Pieces, skip: int,
            rapid_tol: float, top: float, findings: list[Finding]) -> tuple[float | None, float | None]:
    """Rapid findings against the CL path, from the block ends and samples of the rapid blocks.

    A rapid's tip may be on the CL rapid's straight line (within ``rapid_tol`` mm, never more
    than :data:`RAPID_DIP_TOL` below it), on a retract or approach ray (a CL pose's tool axis
    from its tip outward, within ``rapid_tol``), or above every feed point of the program (z at
    least ``top``, table frame); the sampling bound of each move counts against it. Returns the
    largest distance from where a rapid may be and the largest dip below its CL line (mm) of the
    points judged by their line, None without rapids."""
    ends, curves = motion.ends, motion.curves
    blocks = np.flatnonzero(program.rapid & motion.known & ends.reachable)
    blocks = blocks[blocks >= skip]
    inner = np.repeat(program.rapid[curves.moves], curves.n - 1)
    block = np.r_[blocks, curves.block[inner]]
    if block.size == 0:
        return None, None
    point = np.concatenate([ends.tip[blocks], curves.samples.tip[inner]])
    bound = np.r_[np.zeros(len(blocks)), np.repeat(motion.bound_tip, curves.n - 1)[inner]]
    known = np.isfinite(point).all(axis=1)  # an unreachable sample is a finding of its own
    block, point, bound = block[known], point[known], bound[known]
    owner, a, b = pieces.pairs(block)
    at, ref = point[owner], reference.tip
    line = distance_to_segment(at, ref[a], ref[b]) + bound[owner]
    dip = _below_line(at, ref[a], ref[b]) + bound[owner]
    ray = np.minimum(_from_ray(at, ref[a], reference.axis[a]), _from_ray(at, ref[b], reference.axis[b])) + bound[owner]
    count = len(block)
    on_line = np.full(count, np.inf)
    np.minimum.at(on_line, owner, np.where(dip <= RAPID_DIP_TOL, line, np.inf))
    on_ray, nearest_line, least_dip = np.full(count, np.inf), np.full(count, np.inf), np.full(count, np.inf)
    np.minimum.at(on_ray, owner, ray)
    np.minimum.at(nearest_line, owner, line)
    np.minimum.at(least_dip, owner, dip)
    above = point[:, 2] - bound >= top
    deviation = np.where(above, 0.0, np.minimum(on_line, on_ray))
    judged = ~above & (on_ray > rapid_tol)  # points that only their CL line can justify
    last = pieces.last[block]
    for k in _worst_per_block(block, deviation - rapid_tol):
        findings.append(Finding(int(program.line[block[k]]), "rapid", f"rapid tool tip {nearest_line[k]:.4f} mm "
                                f"from its CL line and {least_dip[k]:.4f} mm below it (max {rapid_tol:g} mm and "
                                f"none below), on no retract ray and below the highest feed point",
                                cl_line=int(reference.line[last[k]]), value=float(min(deviation[k], 1e300)),
                                limit=rapid_tol))
    return (float(np.max(np.where(np.isfinite(deviation), deviation, nearest_line))),
            float(np.max(np.where(judged, least_dip, 0.0), initial=0.0)))


def _run_dips(program: GcodeProgram, motion: _Motion, rapid_tol: float, findings: list[Finding]) -> float | None:
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


def _unreached(reference: Reference, matched: np.ndarray, ends: _Poses, lines: np.ndarray, tol: float,
               findings: list[Finding]) -> None:
    """A finding per CL pose no block end reaches, at the block between the reached poses around it
    whose move (the chord of its ends) passes nearest (the earlier one of equals)."""
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
    owner = np.repeat(np.arange(missing.size), count)
    block = np.clip(before[owner] + 1 + _ranks(count), 0, len(lines) - 1)
    target = reference.tip[missing[owner]]
    distance = distance_to_segment(target, ends.tip[np.maximum(block - 1, 0)], ends.tip[block])
    distance = np.nan_to_num(distance, nan=np.inf)
    order = np.lexsort((block, distance, owner))
    best = order[np.r_[True, owner[order][1:] != owner[order][:-1]]]
    for j, k in enumerate(missing):
        gap = float(distance[best[j]])
        near = f" (the move passes {gap:.4f} mm from it)" if math.isfinite(gap) else ""
        findings.append(Finding(int(lines[block[best[j]]]), "reach", "no block end reaches this CL point" + near,
                                cl_line=int(reference.line[k]), value=gap, limit=tol))


def _feed(program: GcodeProgram, reference: Reference, machine: Machine, matched: np.ndarray, pieces: _Pieces,
          curves: _Curves, follows: np.ndarray, findings: list[Finding]) -> tuple[float | None, float | None]:
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
    timed = follows & (program.duration[moves] > 0)
    step = np.linalg.norm(np.diff(curves.tip, axis=0), axis=1)  # consecutive points; across moves dropped
    within = np.ones(len(step), bool)
    within[(curves.start + curves.n)[:-1]] = False
    step = np.where(within, step, 0.0)
    minutes = program.duration[moves] / 60.0
    speed = np.add.reduceat(step, curves.start) / minutes if len(step) else np.zeros(0)  # mm/min
    peak = np.maximum.reduceat(step, curves.start) * curves.n / minutes if len(step) else np.zeros(0)
    owner, a, b = pieces.pairs(moves)
    travel = np.linalg.norm(reference.tip[b] - reference.tip[a], axis=1) >= STILL_TIP
    per_minute = np.where(travel & ~reference.inverse_time[b], reference.feed[b], np.nan)
    lowest = np.full(len(moves), np.inf)
    np.fmin.at(lowest, owner, per_minute)
    lowest[np.bincount(owner, travel & reference.inverse_time[b], minlength=len(moves)) > 0] = np.inf
    still = (np.bincount(owner, travel, minlength=len(moves)) == 0) & (np.bincount(owner, a != b,
                                                                                   minlength=len(moves)) > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(timed & np.isfinite(lowest), speed / lowest, np.nan)
        # the rounding of the written block ends, as a share of the length the feed allows
        ratio_slack = FEED_SLACK + FEED_LENGTH_SLACK / (lowest * minutes)
        peak_ratio = np.where(timed & np.isfinite(lowest), peak / lowest, np.nan)
        turn = np.degrees(np.linalg.norm(program.joints[moves, 3:] - program.joints[moves - 1, 3:], axis=1))
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
                       & (np.linalg.norm(np.diff(reference.tip, axis=0), axis=1) >= STILL_TIP)) + 1
    elapsed = np.r_[0.0, np.cumsum(np.nan_to_num(program.duration))]
    taken = elapsed[matched[k] + 1] - elapsed[matched[k - 1] + 1]
    with np.errstate(divide="ignore"):
        inverse_ratio = 60.0 / reference.feed[k] / taken
    for j in np.flatnonzero(inverse_ratio > 1 + FEED_SLACK):
        findings.append(Finding(int(program.line[matched[k[j]]]), "feed", f"the move takes {taken[j]:.4f} s, "
                                f"programmed {60.0 / reference.feed[k[j]]:.4f} s (inverse time)",
                                cl_line=int(reference.line[k[j]]), value=float(inverse_ratio[j]), limit=1.0))
    return _nanmax(np.r_[ratio, inverse_ratio, rotary_ratio]), _nanmax(peak_ratio)
