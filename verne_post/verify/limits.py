"""The machine's own limits on a read program: tool lengths, joint travel, singularity margins
and joint speeds, at the samples of its motion."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..api import JOINT_NAMES, joint_bounds
from ..machine import Machine
from .gcode_reader import GcodeProgram
from .reference import DELTA_TOL, JOINT_SPEED_SLACK, JOINT_WORDS, Finding
from .sampling import Poses

# --------------------------------------------------------------------------------------------
# tools


def tool_lengths(program: GcodeProgram, machine: Machine, findings: list[Finding]) -> np.ndarray:
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
# limits


def _quantity(joint: int, value: float) -> str:
    return f"{value:.4f} mm" if joint < 3 else f"{np.degrees(value):.4f} deg"


def worst_per_block(block: np.ndarray, excess: np.ndarray) -> np.ndarray:
    """Index of the largest positive ``excess`` in each block that has one."""
    bad = np.flatnonzero(excess > 0)
    order = bad[np.lexsort((-excess[bad], block[bad]))]
    return order[np.r_[True, block[order][1:] != block[order][:-1]]] if order.size else order


def limit_findings(machine: Machine, lines: np.ndarray, interior: np.ndarray, poses: Poses) -> list[Finding]:
    """Travel, reach, rod clearance and singularity margins of samples (G-code ``lines``; block
    ends and ``interior`` samples): the worst sample of each line and kind."""
    lower, upper = joint_bounds(machine)
    t = machine.singularity
    found = poses.margins
    out: list[Finding] = []

    def add(kind: str, excess: np.ndarray, text: Any, value: np.ndarray | None = None, limit: float | None = None
            ) -> None:
        for k in worst_per_block(lines, np.nan_to_num(excess, nan=-1.0)):
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
            add("limit", q[:, j] - upper[j], lambda k, j=j: f"{JOINT_WORDS[j]} = {_quantity(j, q[k, j])} exceeds "
                f"max {_quantity(j, upper[j])}", shown, float(upper[j] * scale))
        if np.isfinite(lower[j]):
            add("limit", lower[j] - q[:, j], lambda k, j=j: f"{JOINT_WORDS[j]} = {_quantity(j, q[k, j])} is "
                f"below min {_quantity(j, lower[j])}", shown, float(lower[j] * scale))
    add("rod_clearance", t.rod_clearance_min - found.rod_clearance,
        lambda k: f"leg I rods {found.rod_clearance[k]:.2f} mm apart (min {t.rod_clearance_min:.2f} mm: rods "
                  f"would cross)", found.rod_clearance, t.rod_clearance_min)
    for name, threshold in (("serial", t.serial_min), ("parallel", t.parallel_min), ("machine", t.machine_min)):
        value = getattr(found, name)
        add("singular", threshold - value, lambda k, name=name, value=value, threshold=threshold:
            f"too close to a {name} singularity (margin {value[k]:.4f}, min {threshold:.4f})", value, threshold)
    return out


def joint_speed(program: GcodeProgram, machine: Machine, findings: list[Finding]) -> dict[str, float | None]:
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
            findings.append(Finding(int(program.line[k]), "joint_speed", f"{JOINT_WORDS[j]} at {shown:.1f} {unit} "
                                    f"(max {top:.1f} {unit}) in {program.duration[k] * 1e3:.3f} ms",
                                    value=float(ratio[k, j]), limit=1.0))
    return {name: nanmax(ratio[:, j]) for j, name in enumerate(JOINT_NAMES)}


def nanmax(values: np.ndarray) -> float | None:
    finite = values[np.isfinite(values)]
    return float(finite.max()) if finite.size else None
