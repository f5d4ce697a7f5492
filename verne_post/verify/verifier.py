"""verne-post verify: what a joint-space program makes the VERNE do, certified from its text.

The program is read back from its text as the controller runs it (:mod:`.gcode_reader`, not the
writer's arrays), and the tool tip and axis at every block end and along the joint-space line
between block ends (the controller interpolates the joints linearly) come from the forward
kinematics (:func:`.api.forward_kinematics`): a route independent of the inverse kinematics
that made the joints. Checked, each finding naming the G-code line (and the CL line):

- the program (here): what the controller would refuse (G1 without a feed, ...), no M2/M30 (cut
  off); tool lengths (:mod:`.limits`): DELTA of each ``(TOOL n LENGTH l DELTA d)`` = spindle nose + LENGTH;
- at every sample (:mod:`.sampling` makes them, :mod:`.limits` judges them): joint travel
  (sliders, tilt, limited rotary), reach, leg I rod clearance and singularity margins;
- the joint velocities the G1 block durations imply (rapids run at the controller's speeds);
- against the CL path (``against``, :mod:`.cl_path`): every CL point reached by a block end (``tol``,
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

import math
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..bodies.world import ProgramBodies
from ..cl.toolpath import Toolpath
from ..errors import InputError
from ..machine import Machine
from .cl_path import mismatch, path_findings, rapid_block_dips
from .collisions import collision_findings
from .gcode_reader import GcodeProgram, ReadState, read_gcode
from .limits import joint_speed, limit_findings, tool_lengths
from .reference import DEFAULT_AXIS_TOL, DEFAULT_RAPID_TOL, DEFAULT_TOL, Finding, Reference
from .sampling import Motion


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
    # not below it; a retract or approach ray along a CL pose's axis; or outside the feed points' box)
    rapid_deviation: float | None = None
    # mm: with the CL path, the largest dip below a rapid's CL line; without, below the lower end
    # of each run of rapid blocks
    rapid_dip: float | None = None
    bodies_checked: bool = False  # every block checked for bodies that meet (the setup and the tools known)

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
        parts.append("ALL LIMITS HELD, NO BODIES MEET" if self.bodies_checked else "ALL LIMITS HELD")
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
            "bodies_checked": self.bodies_checked,
            "smallest_margins": {k: _number(v) for k, v in self.smallest_margins.items()},
        }


def _number(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


def verify_program(text: str | Iterable[str], machine: Machine, *, source: str = "<program>",
                   against: Toolpath | Reference | None = None,
                   work_offset: tuple[float, float, float] | None = None, tol: float | None = None,
                   axis_tol: float | None = None, rapid_tol: float | None = None,
                   bodies: ProgramBodies | None = None) -> Verification:
    """Verify program text (one string or its lines) for ``machine``; see the module docstring.
    ``bodies``: the setup (part frame, placed at that work offset) and the tools' shapes, to check
    for collisions.

    ``against``: the CL path, as read (part frame: the work offset is ``work_offset``, else the
    program header's, else the machine's) or as a :class:`Reference` (table frame). ``tol`` mm
    and ``axis_tol`` degrees: else the program header's, else 0.005 mm and 0.05 degrees.
    Raises :class:`~verne_post.errors.InputError` for text that is not a program it can read.
    """
    program = read_gcode(text, source, controller=machine.controller.profile())
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
                         box=None if reference is None else feed_box(reference), bodies=bodies)


def feed_box(reference: Reference) -> np.ndarray:
    """(2, 3) mm, table frame: the lo and hi corners of the bounding box of a CL path's feed
    points (of every point, if it has no feed); an empty path's box is empty (lo +inf, hi -inf),
    so that every point is outside it."""
    feed = reference.tip[~reference.rapid] if (~reference.rapid).any() else reference.tip
    if not len(feed):
        return np.array([[math.inf] * 3, [-math.inf] * 3])
    return np.array([feed.min(axis=0), feed.max(axis=0)])


def verify_blocks(program: GcodeProgram, machine: Machine, reference: Reference | None, tol: float,
                  axis_tol: float, work_offset: Iterable[float] = (0.0, 0.0, 0.0), *, overlap: bool = False,
                  final: bool = True, rapid_tol: float = DEFAULT_RAPID_TOL, box: np.ndarray | None = None,
                  bodies: ProgramBodies | None = None) -> Verification:
    """The checks of :func:`verify_program` on a program already read (tol mm, axis_tol deg,
    rapid_tol mm; ``box``: the bounding box of the whole CL path's feed points, (2, 3) mm, table
    frame, outside which (above it, or beside it and not below its bottom) a rapid may go
    anywhere; default: the reference's). With ``bodies`` (the setup and the tools' shapes) every
    block is checked for bodies that meet (:mod:`verne_post.verify.collisions`).

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
    lengths = tool_lengths(program, machine, findings)
    motion = Motion.of(program, machine, lengths, tol, np.radians(axis_tol))
    block, interior, samples = motion.all_samples()
    findings += limit_findings(machine, program.line[block], interior, samples)
    speed_ratio = joint_speed(program, machine, findings)
    if bodies is not None:
        findings += collision_findings(program, machine, bodies, lengths, motion.ends.tip,
                                       np.asarray(tuple(work_offset), dtype=float), motion.ends.alpha)
    tip_dev = axis_dev = feed_ratio = peak_ratio = None
    reached = None
    rapid_dev: float | None
    rapid_dip: float | None
    skip = int(overlap)
    if reference is not None:
        tip_dev, axis_dev, feed_ratio, peak_ratio, reached, rapid_dev, rapid_dip = path_findings(
            program, machine, reference, motion, tol, np.radians(axis_tol), findings, skip, rapid_tol,
            feed_box(reference) if box is None else box)
    else:
        rapid_dev, rapid_dip = None, rapid_block_dips(program, motion, rapid_tol, findings)
    if overlap:  # what the part before found at its last block
        findings = [f for f in findings if f.line != program.line[0]]
    x, y, z = work_offset
    unique: dict[tuple[int, str], Finding] = {}
    for finding in findings:  # one per line and kind: the first (worst or earliest) stays
        unique.setdefault((finding.line, finding.kind), finding)
    margins = samples.margins
    return Verification(
        source=program.source, against=None if reference is None else reference.source,
        findings=_in_order(unique.values()), blocks=len(program) - skip,
        samples=len(block) - skip, tol=tol, axis_tol=axis_tol,
        work_offset=(float(x), float(y), float(z)),
        tip_deviation=tip_dev, axis_deviation=axis_dev,
        cl_points=None if reference is None else len(reference.tip) - skip, cl_points_reached=reached,
        feed_ratio=feed_ratio, peak_feed_ratio=peak_ratio, joint_speed_ratio=speed_ratio,
        smallest_margins={name: _nanmin(getattr(margins, name)) for name in
                          ("serial", "parallel", "machine", "rod_clearance")},
        rapid_tol=rapid_tol, rapid_deviation=rapid_dev, rapid_dip=rapid_dip,
        bodies_checked=bodies is not None and machine.bodies.check,
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
                 box: np.ndarray | None = None, bodies: ProgramBodies | None = None) -> None:
        self.machine, self.source, self.tol, self.axis_tol, self.work_offset = (machine, source, tol, axis_tol,
                                                                                 work_offset)
        self.rapid_tol, self.box = rapid_tol, box  # mm; the whole program's feed points' box (table frame)
        self.bodies = bodies  # the setup and the tools' shapes: collisions checked
        self.controller = machine.controller.profile()  # how each part's text is read
        self.state: ReadState | None = None
        self.last: GcodeProgram | None = None  # the last block so far (one row)
        self.pending: Reference | None = None  # poses not yet verified: the last one reached, and any after
        self.parts: list[Verification] = []

    def read(self, text: str, reference: Reference | None = None, final: bool = False) -> None:
        """Verify the next part of the program (whole lines) against ``reference``, the next CL
        poses; ``final`` for the last part."""
        program = read_gcode(text, self.source, self.state, final, self.controller)
        self.state = program.state
        if reference is not None and self.pending is not None:
            reference = self.pending.then(reference)
        if len(program) == 0 and not final:
            self.parts.append(verify_blocks(program, self.machine, None, self.tol, self.axis_tol, self.work_offset,
                                            final=False, rapid_tol=self.rapid_tol, box=self.box,
                                            bodies=self.bodies))
            self.pending = reference
            return
        overlap = self.last is not None
        if overlap:
            program = _joined_program(self.last, program)
        self.parts.append(verify_blocks(program, self.machine, reference, self.tol, self.axis_tol, self.work_offset,
                                        overlap=overlap, final=final, rapid_tol=self.rapid_tol, box=self.box,
                                        bodies=self.bodies))
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
        strays = [key for key, finding in unique.items() if finding.kind == "mismatch"]
        if strays:  # one finding for the program, with the counts of every part
            line = unique[strays[0]].line
            for key in strays:
                del unique[key]
            unique[(line, "mismatch")] = mismatch(line, sum(part.cl_points_reached or 0 for part in parts),
                                                  sum(part.cl_points or 0 for part in parts))

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
            findings=_in_order(unique.values()),
            blocks=sum(part.blocks for part in parts), samples=sum(part.samples for part in parts), tol=self.tol,
            axis_tol=self.axis_tol, work_offset=self.work_offset,
            tip_deviation=most("tip_deviation"), axis_deviation=most("axis_deviation"),
            cl_points=total("cl_points"), cl_points_reached=total("cl_points_reached"),
            feed_ratio=most("feed_ratio"), peak_feed_ratio=most("peak_feed_ratio"),
            joint_speed_ratio=per_name("joint_speed_ratio", max), smallest_margins=per_name("smallest_margins", min),
            rapid_tol=self.rapid_tol, rapid_deviation=most("rapid_deviation"), rapid_dip=most("rapid_dip"),
            bodies_checked=bool(parts) and all(part.bodies_checked for part in parts),
        )


_BLOCK_FIELDS = ("joints", "rapid", "inverse_time", "feed", "duration", "line", "tool", "tool_length")


def _last_block(program: GcodeProgram) -> GcodeProgram:
    return replace(program, **{name: getattr(program, name)[-1:] for name in _BLOCK_FIELDS})


def _joined_program(first: GcodeProgram, then: GcodeProgram) -> GcodeProgram:
    """``then`` with the blocks of ``first`` before its own."""
    return replace(then, **{name: np.concatenate([getattr(first, name), getattr(then, name)])
                            for name in _BLOCK_FIELDS})


def _in_order(findings: Iterable[Finding]) -> tuple[Finding, ...]:
    """By line, a program that does not follow its CL path first: that explains the rest."""
    return tuple(sorted(findings, key=lambda f: (f.kind != "mismatch", f.line, f.kind)))


def _nanmin(values: np.ndarray) -> float | None:
    finite = values[np.isfinite(values)]
    return float(finite.min()) if finite.size else None
