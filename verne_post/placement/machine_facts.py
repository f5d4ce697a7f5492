"""What a machine integrator wants to know of a machine file before the first run.

``verne-post machine check`` prints :func:`summary`; ``verne-post machine show`` prints
:func:`facts` as a table: the joint ranges, the reference pose's joints, the tool-tip workspace
for one tool length with the axis along the table normal above the table, and the limits that
set its edges. ``machine schema`` writes :func:`schema`. Units: mm and degrees, table frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..api import JOINT_NAMES, forward_kinematics, inverse_kinematics
from ..machine import Machine
from ..output.controller import Controller
from .workspace import Workspace, boundary_labels, workspace

_UNITS = ("mm", "mm", "mm", "deg", "deg")


def reference_joints(machine: Machine) -> np.ndarray:
    """(5,) the joints (mm, deg) of the reference pose: the spindle nose at the table origin, the
    axis along the table normal, no tool (what the machine file's geometry must reach)."""
    joints = inverse_kinematics(machine, np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), tool_length=0.0).joints[0]
    return np.round(np.r_[joints[:3], np.degrees(joints[3:])], 9) + 0.0  # never "-0.000"


def _joint_line(machine: Machine, name: str, unit: str) -> str:
    j = getattr(machine.joints, name)
    travel = "continuous" if j.continuous else f"{j.min:g} to {j.max:g} {unit}"
    offset = f", offset {j.offset:g} {unit}" if j.offset else ""
    return (f"{name}: {travel}, {j.velocity:g} {unit}/s, {j.acceleration:g} {unit}/s^2, {j.jerk:g} {unit}/s^3"
            f"{offset}")


def _position(joints: Any) -> str:
    return "not set" if joints is None else (f"rho {joints.rho1:g} {joints.rho2:g} {joints.rho3:g} mm, "
                                             f"theta1 {joints.theta1:g} deg, theta2 {joints.theta2:g} deg")


def summary(machine: Machine) -> list[str]:
    """Lines that say what the machine file sets: name, joints, reference pose, tools, positions,
    moves between cuts (mm, degrees)."""
    ref = reference_joints(machine)
    safe = machine.safe
    lines = [f"name: {machine.name}",
             *(f"joint {_joint_line(machine, name, unit)}" for name, unit in zip(JOINT_NAMES, _UNITS, strict=True)),
             f"reference pose (spindle nose at the table origin, axis along its normal): rho {ref[0]:.3f} "
             f"{ref[1]:.3f} {ref[2]:.3f} mm, theta1 {ref[3]:.3f} deg, theta2 {ref[4]:.3f} deg",
             "tools: " + (", ".join(f"{n}: {t.length:g} mm" for n, t in sorted(machine.tools.items())) or "none"),
             f"work offset: {' '.join(f'{v:g}' for v in machine.work_offset)} mm",
             f"home: {_position(machine.positions.home)}",
             f"tool change: {_position(machine.positions.tool_change)}",
             f"moves between cuts: axis turns over {safe.max_turn_in_rapid:g} deg retract, safe level "
             f"{safe.clearance:g} mm above the highest feed point, rapid tip speed "
             + ("at the joint limits" if safe.rapid_feed is None else f"at most {safe.rapid_feed:g} mm/min")]
    lines += _controller_lines(machine.controller.profile())
    if machine.calibration is not None:
        c = machine.calibration
        lines.append(f"calibrated: {c.poses} poses, residual RMS {c.rms_before:g} -> {c.rms_after:g} mm")
    return lines


def _controller_lines(profile: Controller) -> list[str]:
    """The controller profile in a few lines: what every program of this machine looks like."""
    numbers = profile.block_numbers
    structure = [
        "axes " + " ".join(f"{joint}={letter}" for joint, letter in zip(JOINT_NAMES, profile.axes, strict=True)),
        "comments " + ("( )" if profile.comment == "parentheses" else ";"),
        "% lines" if profile.percent else "no % lines",
        f"block numbers from {numbers[0]} by {numbers[1]}" if numbers else "no block numbers",
        f"at most {profile.max_line_length} characters a line",
    ]
    if profile.program_number is not None:
        structure.append(f"program number {profile.program_number}")
    if profile.optional_stop:
        structure.append(f"M{profile.m_codes.optional_stop} before every tool change but the first")
    return [f"controller: {profile.dialect}; " + ", ".join(structure),
            "  program start: " + " | ".join(profile.program_start),
            "  tool change: " + " | ".join(profile.tool_change_lines),
            "  program end: " + " | ".join(profile.end_lines)]


@dataclass(frozen=True)
class Facts:
    """The workspace for one tool length (mm) with the axis along the table normal, above the
    table (tool tip z >= 0, table frame): the extents of the usable tool tips (every limit and
    margin held; mm, table frame, None if there are none) and the limits that set its edges, each
    with a tool tip (mm, table frame) on the edge it sets."""

    tool_length: float
    extents: dict[str, tuple[float, float] | None]
    edges: tuple[tuple[str, tuple[float, float, float]], ...]
    workspace: Workspace


def facts(machine: Machine, tool_length: float, step: float = 10.0) -> Facts:
    """:class:`Facts` from the workspace sections (grid ``step`` mm) through the table centre."""
    ws = workspace(machine, tool_length=tool_length, step=step)
    tips, edges = [], {}
    for section in ws.sections:
        v, u = np.nonzero(section.headroom >= 0)
        tips.append(_in_table_frame(section.plane, section.u[u], section.v[v], section.level))
        for label, a, b in boundary_labels(section):
            tip = _in_table_frame(section.plane, np.array([a]), np.array([b]), section.level)[0]
            if tip[2] >= 0 and label not in edges:
                edges[label] = (float(tip[0]), float(tip[1]), float(tip[2]))
    points = np.concatenate(tips) if tips else np.zeros((0, 3))
    points = points[points[:, 2] >= 0]  # the tool tip above the table
    extents: dict[str, tuple[float, float] | None] = {
        axis: (float(points[:, k].min()), float(points[:, k].max())) if len(points) else None
        for k, axis in enumerate("xyz")}
    return Facts(tool_length, extents, tuple(edges.items()), ws)


def _in_table_frame(plane: str, u: np.ndarray, v: np.ndarray, level: float) -> np.ndarray:
    """(N, 3) tool tips (mm, table frame) of points ``u``, ``v`` (mm) of a section of ``plane``."""
    fixed = np.full(len(u), level)
    return np.column_stack({"xz": (u, fixed, v), "yz": (fixed, u, v), "xy": (u, v, fixed)}[plane])


def facts_table(machine: Machine, found: Facts) -> list[str]:
    """:func:`facts` as lines of text (mm, degrees); each joint with its letter in the programs."""
    ref = reference_joints(machine)
    letters = machine.controller.profile().axes
    rows = [f"{'joint':14} {'min':>10} {'max':>10} {'velocity':>10} {'accel.':>10} {'jerk':>10} {'reference':>10}"]
    for k, (name, unit) in enumerate(zip(JOINT_NAMES, _UNITS, strict=True)):
        j = getattr(machine.joints, name)
        low, high = ("-", "-") if j.continuous else (f"{j.min:g}", f"{j.max:g}")
        rows.append(f"{f'{name} ({letters[k]}) {unit}':14} {low:>10} {high:>10} {j.velocity:>10g} "
                    f"{j.acceleration:>10g} {j.jerk:>10g} {ref[k]:>10.3f}")
    rows.append(f"workspace with a {found.tool_length:g} mm tool, axis along the table normal, above the table, "
                f"every limit and margin held (sections through the table centre):")
    for axis, span in found.extents.items():
        rows.append(f"  {axis}: " + ("none" if span is None else f"{span[0]:.0f} to {span[1]:.0f} mm"))
    if found.edges:
        rows.append("its edges are set by:")
        rows += [f"  {label}: at {x:.0f} {y:.0f} {z:.0f} mm" for label, (x, y, z) in found.edges]
    for which in ("home", "tool_change"):
        position = getattr(machine.positions, which)
        if position is not None:
            tip = forward_kinematics(machine, position.joints()[None], tool_length=found.tool_length).tip[0]
            tip = np.round(tip, 1) + 0.0  # never "-0.0"
            rows.append(f"{which.replace('_', ' ')}: tool tip at {tip[0]:.1f} {tip[1]:.1f} {tip[2]:.1f} mm "
                        f"(table frame) with this tool")
    return rows


def schema() -> dict[str, Any]:
    """The JSON Schema of a machine file (draft 2020-12), from the validated model: every key
    with its bounds, units in the descriptions, unknown keys refused."""
    out = Machine.model_json_schema()
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": "verne-post machine file",
            **{k: v for k, v in out.items() if k != "title"}}
