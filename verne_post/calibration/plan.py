"""Measurement planning: N poses that make the parameters identifiable (``calibrate --plan``).

Candidates are random joint readings inside the machine's travel, one of the given tools each,
kept where the machine's own checks pass (working assembly, travel, rod clearance and every
singularity margin: the status ``ok`` of :func:`verne_post.api.classify`). Of those, N are
chosen greedily by D-optimality: each step adds the pose that most increases
log det(J^T J) of the scaled identification Jacobian (tips, mm, table frame) over the free
parameters. Pure: no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..api import Status, classify, forward_kinematics, pose_margins
from ..machine import Machine
from .fit import RANK_RTOL, describe, directions, hold_for
from .model import PARAMETERS, SCALE, jacobian, parameters_of, predict

#: Candidate poses drawn per planned pose (at least :data:`MIN_CANDIDATES`).
CANDIDATES_PER_POSE = 60
MIN_CANDIDATES = 3000
#: Ridge (in scaled units) that makes the first greedy steps well defined.
RIDGE = 1e-6


@dataclass(frozen=True)
class Plan:
    """Planned poses: joint readings (N, 5) rho mm / theta rad, tool lengths (N,) mm, the tool
    tips the machine file predicts (N, 3) mm in the table frame, and what the plan identifies."""

    joints: np.ndarray
    tool_length: np.ndarray
    tip: np.ndarray
    free: list[str]
    held: dict[str, str]
    std_per_um: dict[str, float]  # predicted std of each free parameter (mm or rad) per um of tip noise


def _candidates(machine: Machine, count: int, tools: np.ndarray, rng: np.random.Generator
                ) -> tuple[np.ndarray, np.ndarray]:
    """Random joint readings (K, 5) mm/rad within travel whose status is ok, and their tools (K,)."""
    lower, upper = [], []
    for name in ("rho1", "rho2", "rho3", "theta1", "theta2"):
        j = getattr(machine.joints, name)
        scale = 1.0 if name.startswith("rho") else np.pi / 180.0
        lower.append(-np.pi if j.continuous else j.min * scale)
        upper.append(np.pi if j.continuous else j.max * scale)
    kept_joints, kept_tools, total = [], [], 0
    for _ in range(50):  # about a quarter of the joint box is usable: a few rounds suffice
        joints = np.array(lower) + (np.array(upper) - np.array(lower)) * rng.random((2 * count, 5))
        tool = tools[rng.integers(len(tools), size=len(joints))]
        fk = forward_kinematics(machine, joints, tool_length=tool)
        found = pose_margins(machine, joints, fk.platform, fk.alpha, fk.reachable, tool)
        ok = classify(machine, joints, fk.reachable, found) == Status.OK
        kept_joints.append(joints[ok])
        kept_tools.append(tool[ok])
        total += int(ok.sum())
        if total >= count:
            break
    return np.concatenate(kept_joints)[:count], np.concatenate(kept_tools)[:count]


def plan_poses(machine: Machine, n: int, tools: list[float], fix: tuple[str, ...] = (), seed: int = 0) -> Plan:
    """``n`` measurement poses for ``machine`` with tools of the given lengths (mm)."""
    rng = np.random.default_rng(seed)
    joints, tool = _candidates(machine, max(MIN_CANDIDATES, CANDIDATES_PER_POSE * n), np.asarray(tools, float), rng)
    p0 = parameters_of(machine)
    fk = predict(p0, joints, tool)
    d_tip, _ = jacobian(p0, joints, tool, fk)
    status = {name: "fixed" if name in fix else "fitted" for name in PARAMETERS}
    held = {name: "fixed by --fix" for name in fix}
    while True:  # exact dependencies over the whole candidate set: no choice of poses lifts them
        free = [k for k, name in enumerate(PARAMETERS) if status[name] == "fitted"]
        names = [PARAMETERS[k] for k in free]
        jac = (d_tip[:, :, free] * SCALE[free]).reshape(-1, len(free))
        relative, vt, _ = directions(jac, names, None)
        if relative[-1] >= RANK_RTOL:
            break
        hold = hold_for(vt[-1], names)
        status[hold] = "held"
        held[hold] = f"cannot be told apart from the others of {describe(vt[-1], names)} by tip positions"
    blocks = d_tip[:, :, free] * SCALE[free]  # (K, 3, P)
    information = RIDGE * np.eye(len(free))
    chosen: list[int] = []
    available = np.ones(len(blocks), bool)
    for _ in range(min(n, len(blocks))):
        inverse = np.linalg.inv(information)
        # log det(M + B^T B) - log det(M) = log det(I + B M^-1 B^T) (3 x 3 per candidate)
        gain = np.einsum("kip,pq,kjq->kij", blocks, inverse, blocks) + np.eye(3)
        score = np.where(available, np.linalg.slogdet(gain)[1], -np.inf)
        best = int(np.argmax(score))
        chosen.append(best)
        available[best] = False
        information += blocks[best].T @ blocks[best]
    rows = np.array(chosen)
    covariance = np.linalg.inv(information - RIDGE * np.eye(len(free))) if len(rows) * 3 > len(free) else None
    std = {} if covariance is None else {
        PARAMETERS[k]: float(np.sqrt(covariance[i, i]) * SCALE[k] * 1e-3) for i, k in enumerate(free)}
    return Plan(joints[rows], tool[rows], fk.tip[rows], [PARAMETERS[k] for k in free], held, std)


__all__ = ["Plan", "plan_poses"]
