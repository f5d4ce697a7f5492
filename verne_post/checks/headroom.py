"""How far a pose is from each limit of the machine, as fractions that can be compared.

Every constraint of the checks (slider, tilt and rotary travel, leg I rod clearance, the
serial, parallel and machine singularity margins) gets a *headroom*: 0 at its limit (the
threshold of the machine file), 1 as far from it as the machine ever gets, negative beyond
the limit. Joints count from the nearer end of their travel over half the travel (1 in the
middle); rod clearance over its largest value R1 - r1 (platform level); the singularity
margins over the best value the machine reaches anywhere in its joint space. So "0.3" means
the same thing for a slider and for the conditioning of the parallel module: 30 % of the way
from the limit to the best this machine can do. A pose passes every check exactly when its
smallest headroom is >= 0.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..api import JOINT_NAMES, joint_bounds
from ..kinematics import Margins, margins, module_ik_working
from ..machine import Geometry, GeometryConfig, Machine

MARGIN_NAMES = ("rod_clearance", "serial", "parallel", "machine")
#: Column names of :func:`headroom`; "reach" is the pseudo-constraint of an unreachable pose.
CONSTRAINTS = (*JOINT_NAMES, *MARGIN_NAMES)
REACH = len(CONSTRAINTS)
LABELS = ("slider rho1 travel", "slider rho2 travel", "slider rho3 travel", "tilt theta1 travel",
          "rotary theta2 travel", "leg I rod clearance", "serial singularity (rod along its guideway)",
          "parallel singularity", "machine singularity (two working solutions merge)", "reach")
UNREACHABLE = -1.0  # headroom given to a pose the machine cannot reach at all


@lru_cache(maxsize=8)
def _best_singularity_margins(geometry: GeometryConfig) -> np.ndarray:
    """Largest serial, parallel and machine margins over a fixed grid of platform positions
    around the VERNE's reach (base frame, mm) and tilts theta1 up to 80 degrees (theta2 changes
    no margin); the module IK is closed-form, so this takes milliseconds."""
    geom = Geometry(**geometry.model_dump())
    axes = (np.linspace(-700.0, 700.0, 29), np.linspace(-700.0, 700.0, 29), np.linspace(600.0, 2200.0, 33))
    platform = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    with np.errstate(invalid="ignore", divide="ignore"):
        module = module_ik_working(geom, platform)
    ok = np.flatnonzero(module.reachable)
    theta1 = np.radians(np.linspace(-80.0, 80.0, 9))
    rows, t1 = np.repeat(ok, len(theta1)), np.tile(theta1, len(ok))
    joints = np.column_stack([module.rho[rows], t1, np.zeros(len(rows))])
    found = margins(geom, joints, platform[rows], module.alpha[rows])
    return np.array([np.max(found.serial), np.max(found.parallel), np.max(found.machine)])


def scales(machine: Machine) -> tuple[np.ndarray, np.ndarray]:
    """(limit, best) per margin of MARGIN_NAMES: headroom = (value - limit) / (best - limit)."""
    t = machine.singularity
    g = machine.geometry
    best = _best_singularity_margins(machine.geometry)
    limit = np.array([t.rod_clearance_min, t.serial_min, t.parallel_min, t.machine_min])
    return limit, np.r_[g.R1 - g.r1, best]


def headroom(machine: Machine, joints: np.ndarray, found: Margins) -> np.ndarray:
    """(N, 9) headroom per constraint of CONSTRAINTS for joints (N, 5) mm/rad and their margins;
    NaN rows where the pose is unreachable; +inf for a continuous rotary."""
    lower, upper = joint_bounds(machine)
    half = (upper - lower) / 2.0
    with np.errstate(invalid="ignore"):
        travel = np.where(np.isfinite(half), 1.0 - np.abs(joints - (lower + upper) / 2.0) / half, np.inf)
    limit, best = scales(machine)
    values = np.column_stack([getattr(found, name) for name in MARGIN_NAMES])
    out = np.column_stack([travel, (values - limit) / (best - limit)])
    out[~np.all(np.isfinite(joints), axis=1)] = np.nan
    return out


def smallest(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(smallest headroom (N,), its constraint index (N,)); unreachable rows: (UNREACHABLE, REACH)."""
    reachable = ~np.isnan(values).any(axis=1)
    filled = np.where(reachable[:, None], values, np.inf)
    which = np.argmin(filled, axis=1)
    value = filled[np.arange(len(values)), which]
    return np.where(reachable, value, UNREACHABLE), np.where(reachable, which, REACH)


def describe(machine: Machine, joints: np.ndarray, which: int) -> str:
    """Label of constraint ``which`` for one pose, naming the end of travel it is near."""
    if which < len(JOINT_NAMES) and np.isfinite(joints[which]):
        lower, upper = joint_bounds(machine)
        near_max = joints[which] > (lower[which] + upper[which]) / 2.0
        return f"{LABELS[which]} ({'max' if near_max else 'min'})"
    return LABELS[which]


__all__ = ["CONSTRAINTS", "LABELS", "REACH", "UNREACHABLE", "describe", "headroom", "scales", "smallest"]
