"""Measurement files of ``verne-post calibrate``: one measured pose per CSV row.

Header ``rho1,rho2,rho3,theta1,theta2,tool_length,x,y,z`` plus optional ``i,j,k`` (a measured
tool axis) and ``weight``: joint readings of the controller (mm, degrees), the tool length (mm,
spindle nose to tip) and the measured tool tip in the table frame (mm). Every mistake is one
:class:`~verne_post.errors.InputError` naming the file and line; nothing is computed from a
file with one.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..api import JOINT_NAMES, forward_kinematics
from ..errors import InputError
from ..machine import MAX_MM, MAX_TOOL_LENGTH, Machine
from ..output.tables import read_table
from .model import Poses

REQUIRED = (*JOINT_NAMES, "tool_length", "x", "y", "z")
OPTIONAL = ("i", "j", "k", "weight")

#: A measured tip farther than this (mm) from where the machine file puts it is not a small
#: geometry error but a wrong row, frame or unit.
MAX_DEVIATION = 25.0
#: A measured axis whose length is off 1 by more than this is not a unit vector.
AXIS_NORM_TOL = 0.01
MAX_WEIGHT = 1e6


@dataclass(frozen=True)
class Measurements:
    """Measured poses (internal units: rho mm, theta rad; tips mm, table frame) with the file's
    line of each row."""

    poses: Poses
    lines: np.ndarray  # (N,) 1-based line in the file
    source: str
    notes: tuple[str, ...] = ()  # how the file was read (a spreadsheet's separators)


def read_measurements(path: str | os.PathLike[str], machine: Machine) -> Measurements:
    """Read and check a measurement CSV against ``machine`` (its travel and its kinematics)."""
    source = str(path)
    notes: list[str] = []
    columns, lines = read_table(path, REQUIRED, OPTIONAL, notes)
    n = len(lines)
    if n == 0:
        raise InputError("no measured poses (only a header)", source, _last_line(path))
    joints = np.column_stack([columns[c] for c in JOINT_NAMES])
    tool = columns["tool_length"]
    tip = np.column_stack([columns["x"], columns["y"], columns["z"]])
    has = {c: c in columns for c in ("i", "j", "k")}
    if any(has.values()) and not all(has.values()):
        raise InputError("columns i, j, k come together (a measured tool axis) or not at all", source,
                         _header_line(path))
    axis = (np.column_stack([columns["i"], columns["j"], columns["k"]]) if all(has.values())
            else np.full((n, 3), np.nan))
    weight = columns.get("weight", np.ones(n))
    weight = np.where(np.isnan(weight), 1.0, weight)

    problems: list[tuple[int, str]] = []  # (row, reason): the first row's is reported
    for k, name in enumerate(JOINT_NAMES):
        limits = getattr(machine.joints, name)
        unit = "mm" if k < 3 else "deg"
        low, high = (-MAX_MM, MAX_MM) if limits.continuous else (limits.min, limits.max)
        bad = np.flatnonzero((joints[:, k] < low) | (joints[:, k] > high))
        if bad.size:
            problems.append((int(bad[0]), f"{name} = {joints[bad[0], k]:g} {unit} is outside the travel "
                                          f"{low:g} to {high:g} {unit}"))
    bad = np.flatnonzero((tool < 0) | (tool > MAX_TOOL_LENGTH))
    if bad.size:
        problems.append((int(bad[0]), f"tool_length = {tool[bad[0]]:g} mm is outside 0 to {MAX_TOOL_LENGTH:g} mm"))
    bad = np.flatnonzero(np.any(np.abs(tip) > MAX_MM, axis=1))
    if bad.size:
        problems.append((int(bad[0]), f"tool tip beyond {MAX_MM:g} mm"))
    partial = np.any(np.isnan(axis), axis=1) & np.any(np.isfinite(axis), axis=1)
    bad = np.flatnonzero(partial)
    if bad.size:
        problems.append((int(bad[0]), "i, j, k: give all three or leave all three empty"))
    norm = np.linalg.norm(axis, axis=1)
    bad = np.flatnonzero(np.isfinite(norm) & (np.abs(norm - 1.0) > AXIS_NORM_TOL))
    if bad.size:
        problems.append((int(bad[0]), f"tool axis (i, j, k) has length {norm[bad[0]]:.4g}, not 1"))
    bad = np.flatnonzero(~((weight > 0) & (weight <= MAX_WEIGHT)))
    if bad.size:
        problems.append((int(bad[0]), f"weight = {weight[bad[0]]:g} is outside (0, {MAX_WEIGHT:g}]"))
    if problems:
        row, reason = min(problems)
        raise InputError(reason, source, int(lines[row]))

    radians = joints.copy()
    radians[:, 3:] = np.radians(joints[:, 3:])
    fk = forward_kinematics(machine, radians, tool_length=tool)
    bad = np.flatnonzero(~fk.reachable)
    if bad.size:
        raise InputError("the machine cannot be at these joint readings (the sliders admit no working assembly)",
                         source, int(lines[bad[0]]))
    deviation = np.linalg.norm(fk.tip - tip, axis=1)
    bad = np.flatnonzero(deviation > MAX_DEVIATION)
    if bad.size:
        raise InputError(f"measured tip is {deviation[bad[0]]:.1f} mm from where the machine file puts it (more than "
                         f"{MAX_DEVIATION:g} mm: wrong row, frame, units or tool length?)", source, int(lines[bad[0]]))
    axis = axis / np.where(np.isfinite(norm), norm, 1.0)[:, None]
    return Measurements(Poses(radians, tool, tip, axis, weight), lines, source, tuple(notes))


def _header_line(path: str | os.PathLike[str]) -> int | None:
    """1-based line of the header: the first line that is neither blank nor a # comment."""
    try:
        with open(path, encoding="utf-8", errors="replace") as handle:
            for number, line in enumerate(handle, 1):
                if line.strip() and not line.lstrip().startswith("#"):
                    return number
    except OSError:
        pass
    return None


def _last_line(path: str | os.PathLike[str]) -> int | None:
    try:
        with open(path, encoding="utf-8", errors="replace") as handle:
            return max(1, sum(1 for _ in handle))
    except OSError:
        return None


__all__ = ["OPTIONAL", "REQUIRED", "Measurements", "read_measurements"]
