"""Synthetic tool paths made into joint polylines with the machine's IK (tests and benchmarks).

Tips in mm and axes in the table frame; joints (N, 5) in mm and rad, theta2 continuous.
"""

from __future__ import annotations

import numpy as np

import verne_post as vp

TOOL = 60.0  # mm


def axis_from(tilt: np.ndarray, azimuth: np.ndarray) -> np.ndarray:
    """Unit axes (N, 3) at ``tilt`` from the table normal towards ``azimuth`` (rad)."""
    return np.stack([np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), np.cos(tilt)], axis=1)


def joints_along(machine: vp.Machine, tip: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Working-mode IK along the path, theta2 kept continuous; ValueError if it leaves the workspace."""
    chunks = []
    hint = float(vp.inverse_kinematics(machine, tip[:1], axis[:1], tool_length=TOOL).joints[0, 4])
    for part in np.array_split(np.arange(len(tip)), max(1, len(tip) // 50)):
        ik = vp.inverse_kinematics(machine, tip[part], axis[part], theta2_hint=hint, tool_length=TOOL)
        if not (ik.status == vp.Status.OK).all():
            raise ValueError("synthetic path leaves the usable workspace")
        chunks.append(ik.joints)
        hint = float(ik.joints[-1, 4])
    joints = np.concatenate(chunks)
    joints[:, 4] = np.unwrap(joints[:, 4])
    if np.abs(np.diff(joints[:, 3:], axis=0)).max() >= 0.2:
        raise ValueError("synthetic path changes solution branch")
    return joints


def helix(machine: vp.Machine, n: int = 1001, turns: float = 2.0, pitch: float = 5.0
          ) -> tuple[np.ndarray, np.ndarray]:
    """A helix of radius 40 mm around the table axis (``pitch`` mm a turn), tool tilted 20..40
    deg and leaning along it: (joints, tips)."""
    a = np.linspace(0.0, 2 * np.pi * turns, n)
    tip = np.stack([40.0 * np.cos(a), 40.0 * np.sin(a), 60.0 + pitch * a / (2 * np.pi)], axis=1)
    tilt = np.radians(20.0 + 20.0 * 0.5 * (1 - np.cos(a / turns)))
    return joints_along(machine, tip, axis_from(tilt, a + 0.3)), tip


def zigzag_tip(n: int, rows: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows of 60 mm, 8 mm apart, joined by half circles, sampled evenly along the path (mm)."""
    row, turn = 60.0, np.pi * 4.0
    total = rows * row + (rows - 1) * turn
    u = np.linspace(0.0, total, n)
    period = row + turn
    k = np.minimum(np.floor(u / period), rows - 1)
    v = u - k * period
    side = np.where(k % 2 == 0, 1.0, -1.0)  # direction of travel along x on row k
    on_row = v <= row
    x = np.where(on_row, side * (v - row / 2), side * (row / 2 + 4.0 * np.sin((v - row) / 4.0)))
    y = np.where(on_row, 8.0 * k, 8.0 * k + 4.0 - 4.0 * np.cos((v - row) / 4.0))
    return np.stack([x, y - 4.0 * (rows - 1), 70.0 + 0.05 * x], axis=1), u / total


def zigzag(machine: vp.Machine, n: int = 800, rows: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """60 mm rows joined by half circles (8 mm step), tool tilt 20..40 deg and swinging."""
    tip, phase = zigzag_tip(n, rows)
    tilt = np.radians(30.0 + 10.0 * np.sin(2 * np.pi * phase))
    azimuth = np.radians(30.0) + 0.5 * np.sin(4 * np.pi * phase)
    return joints_along(machine, tip, axis_from(tilt, azimuth)), tip


def feed_pieces(machine: vp.Machine, seed: int = 9, longest: int = 400
                ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Feed sequences (joints, tip, feed mm/s): pieces of a helix and a zigzag of 2 to ``longest``
    blocks at random feeds from 5 to 200 mm/s."""
    rng = np.random.default_rng(seed)
    out = []
    for joints, tip in (helix(machine, n=1201), zigzag(machine, n=900)):
        start = 0
        while start < len(joints) - 3:
            stop = min(len(joints), start + int(rng.integers(3, longest)))
            out.append((joints[start:stop], tip[start:stop], rng.uniform(5.0, 200.0, stop - start - 1)))
            start = stop
    return out
