"""Measurement planning: N poses that make the parameters identifiable (``calibrate --plan``).

Candidates are random tool tips in the measuring volume (table frame, mm) with random tool
axes and one of the given tools each, turned into joint readings by the inverse kinematics and
kept where the machine's own checks pass at those readings (working assembly, travel, rod
clearance and every singularity margin: the status ``ok`` of :func:`verne_post.api.classify`)
and the forward kinematics puts the tip in the volume. Of those, N are chosen greedily by
D-optimality: each step adds the pose that most increases log det of the posterior
information ``J^T J / noise^2 + I`` in scaled variables (the prior of one typical error that the
fit uses), started from the poses already measured when they are given. Pure: no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..api import Status, classify, forward_kinematics, inverse_kinematics_pair, pose_margins
from ..errors import InputError
from ..machine import Machine
from .directions import Direction, directions
from .model import PARAMETERS, SCALE, Poses, jacobian, parameters_of, predict

#: Candidate poses drawn per planned pose (at least :data:`MIN_CANDIDATES`).
CANDIDATES_PER_POSE = 60
MIN_CANDIDATES = 3000
#: Rounds of random joint readings drawn to find the candidates.
MAX_ROUNDS = 20
#: Measuring noise (mm per coordinate) the plan's expected standard deviations assume.
PLAN_NOISE = 0.003
#: Height (mm) of the default measuring volume above the table's face.
DEFAULT_HEIGHT = 400.0

VOLUME_FORMS = "box:x0,y0,z0,x1,y1,z1 or cylinder:cx,cy,z0,z1,r"


@dataclass(frozen=True)
class Volume:
    """Where a probe can measure the tip: a box (two opposite corners) or a cylinder about the
    table normal (centre x, y, z from z0 to z1, radius r), table frame, mm."""

    kind: str  # box | cylinder
    values: tuple[float, ...]
    spec: str

    def contains(self, tip: np.ndarray) -> np.ndarray:
        """(N,) bool for tips (N, 3) mm, table frame."""
        if self.kind == "box":
            lo = np.minimum(self.values[:3], self.values[3:])
            hi = np.maximum(self.values[:3], self.values[3:])
            return np.all((tip >= lo) & (tip <= hi), axis=1)
        cx, cy, z0, z1, r = self.values
        radial = np.hypot(tip[:, 0] - cx, tip[:, 1] - cy)
        return (radial <= r) & (tip[:, 2] >= min(z0, z1)) & (tip[:, 2] <= max(z0, z1))

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` points (n, 3) uniform in the volume, mm, table frame."""
        u = rng.random((n, 3))
        if self.kind == "box":
            lo, hi = np.array(self.values[:3]), np.array(self.values[3:])
            return lo + (hi - lo) * u
        cx, cy, z0, z1, r = self.values
        radius, angle = r * np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
        return np.column_stack([cx + radius * np.cos(angle), cy + radius * np.sin(angle), z0 + (z1 - z0) * u[:, 2]])


def parse_volume(spec: str) -> Volume:
    """``box:x0,y0,z0,x1,y1,z1`` or ``cylinder:cx,cy,z0,z1,r`` (mm, table frame)."""
    kind, _, rest = spec.partition(":")
    kind = kind.strip().lower()
    count = {"box": 6, "cylinder": 5}.get(kind)
    if count is None:
        raise InputError(f"--volume '{spec}': give {VOLUME_FORMS} (mm, table frame)")
    try:
        values = tuple(float(v) for v in rest.split(","))
    except ValueError:
        raise InputError(f"--volume '{spec}': numbers expected ({VOLUME_FORMS})") from None
    if len(values) != count or not all(np.isfinite(values)):
        raise InputError(f"--volume '{spec}': {count} finite numbers expected ({VOLUME_FORMS})")
    if kind == "box" and any(values[k] == values[k + 3] for k in range(3)):
        raise InputError(f"--volume '{spec}': the box is flat (two corners share a coordinate)")
    if kind == "cylinder" and (values[4] <= 0 or values[2] == values[3]):
        raise InputError(f"--volume '{spec}': the cylinder needs a radius above 0 and z0 != z1")
    return Volume(kind, values, spec)


def default_volume(machine: Machine) -> Volume:
    """The space above the table's face, as wide as the table, :data:`DEFAULT_HEIGHT` high."""
    table = machine.bodies.table
    values = (0.0, 0.0, table.top, table.top + DEFAULT_HEIGHT, table.diameter / 2)
    spec = "cylinder:" + ",".join(f"{v:g}" for v in values)
    return Volume("cylinder", values, spec)


@dataclass(frozen=True)
class Plan:
    """Planned poses: joint readings (N, 5) rho mm / theta rad, tool lengths (N,) mm, the tool
    tips the machine file predicts (N, 3) mm in the table frame, and what the plan identifies."""

    joints: np.ndarray
    tool_length: np.ndarray
    tip: np.ndarray
    free: list[str]
    volume: Volume
    std: dict[str, float]  # expected posterior std of each free parameter (mm, rad) at PLAN_NOISE
    directions: list[Direction]  # of all poses (measured and planned) at PLAN_NOISE


def _candidates(machine: Machine, count: int, tools: np.ndarray, volume: Volume, rng: np.random.Generator
                ) -> tuple[np.ndarray, np.ndarray]:
    """Joint readings (K, 5) mm/rad whose status is ok and whose tip lies in ``volume``, and
    their tools (K,): random tips in the volume and tool axes on the upper half sphere, through
    the inverse kinematics (either angle pair), then checked by the forward kinematics."""
    kept_joints, kept_tools, total = [], [], 0
    for _ in range(MAX_ROUNDS):
        tip = volume.sample(2 * count, rng)
        axis = rng.normal(size=(2 * count, 3))
        axis[:, 2] = np.abs(axis[:, 2])
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        tool = tools[rng.integers(len(tools), size=len(tip))]
        pair = rng.choice([-1, 1], size=len(tip))
        joints = np.full((len(tip), 5), np.nan)
        for length in np.unique(tool):
            rows = tool == length
            ik = inverse_kinematics_pair(machine, tip[rows], axis[rows], pair[rows], tool_length=float(length),
                                         with_margins=False)
            joints[rows] = np.where((ik.status == Status.OK)[:, None], ik.joints, np.nan)
        solved = np.all(np.isfinite(joints), axis=1)
        joints, tool = joints[solved], tool[solved]
        fk = forward_kinematics(machine, joints, tool_length=tool)
        found = pose_margins(machine, joints, fk.platform, fk.alpha, fk.reachable, tool)
        ok = (classify(machine, joints, fk.reachable, found) == Status.OK) & volume.contains(fk.tip)
        kept_joints.append(joints[ok])
        kept_tools.append(tool[ok])
        total += int(ok.sum())
        if total >= count:
            break
    return np.concatenate(kept_joints)[:count], np.concatenate(kept_tools)[:count]


def plan_poses(machine: Machine, n: int, tools: list[float], fix: tuple[str, ...] = (), seed: int = 0,
               volume: Volume | None = None, measured: Poses | None = None) -> Plan:
    """``n`` measurement poses for ``machine`` with tools of the given lengths (mm), tips in
    ``volume`` (default :func:`default_volume`), added to the poses ``measured`` if given."""
    volume = volume or default_volume(machine)
    rng = np.random.default_rng(seed)
    joints, tool = _candidates(machine, max(MIN_CANDIDATES, CANDIDATES_PER_POSE * n), np.asarray(tools, float),
                               volume, rng)
    if len(joints) < n:
        raise InputError(f"--volume {volume.spec}: only {len(joints)} poses that pass every check of the machine put "
                         f"the tip in it, {n} asked (a larger volume, other tools or fewer poses)")
    free = [k for k, name in enumerate(PARAMETERS) if name not in fix]
    p0 = parameters_of(machine)
    fk = predict(p0, joints, tool)
    d_tip, _ = jacobian(p0, joints, tool, fk)
    blocks = d_tip[:, :, free] * SCALE[free] / PLAN_NOISE  # (K, 3, P): in noise units
    information = np.eye(len(free))  # the prior: one typical error
    if measured is not None and len(measured):
        given, _ = jacobian(p0, measured.joints, measured.tool_length, predict(p0, measured.joints,
                                                                                measured.tool_length))
        rows = (given[:, :, free] * SCALE[free] / PLAN_NOISE).reshape(-1, len(free))
        information += rows.T @ rows
    chosen: list[int] = []
    available = np.ones(len(blocks), bool)
    for _ in range(n):
        inverse = np.linalg.inv(information)
        # log det(M + B^T B) - log det(M) = log det(I + B M^-1 B^T) (3 x 3 per candidate)
        gain = np.einsum("kip,pq,kjq->kij", blocks, inverse, blocks) + np.eye(3)
        score = np.where(available, np.linalg.slogdet(gain)[1], -np.inf)
        best = int(np.argmax(score))
        chosen.append(best)
        available[best] = False
        information += blocks[best].T @ blocks[best]
    rows = np.array(chosen, dtype=int)
    covariance = np.linalg.inv(information)
    std = {PARAMETERS[k]: float(np.sqrt(covariance[i, i]) * SCALE[k]) for i, k in enumerate(free)}
    # The directions of the whole set: J^T J = (information - I) noise^2.
    values, vectors = np.linalg.eigh(information - np.eye(len(free)))
    root = (np.sqrt(np.maximum(values, 0.0))[:, None] * vectors.T) * PLAN_NOISE
    return Plan(joints[rows], tool[rows], fk.tip[rows], [PARAMETERS[k] for k in free], volume, std,
                directions(root, free, PLAN_NOISE))


__all__ = ["VOLUME_FORMS", "Plan", "Volume", "default_volume", "parse_volume", "plan_poses"]
