"""The library's front door: kinematics of a :class:`Machine` with its limits and margins.

Units: tips in mm and axes as unit vectors in the table frame; joints (N, 5) = rho1..3 in mm
and theta1, theta2 in radians (degrees only at the CLI, YAML and file interfaces).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from enum import IntEnum

import numpy as np

from .kinematics import (
    MachineFKSolutions,
    MachineIK,
    MachineIKSolutions,
    Margins,
    kernels,
    machine_fk_all,
    machine_fk_working,
    machine_ik_all,
    machine_ik_working,
    margins,
    unwrap_near,
)
from .kinematics.full import true_theta2
from .kinematics.rows import all_of, any_of, norms, take_rows
from .machine import Machine


class Status(IntEnum):
    """Per-pose outcome; a pose gets the most severe that applies (unreachable first)."""

    OK = 0
    UNREACHABLE = 1
    OUT_OF_LIMITS = 2
    SINGULAR = 3

    @property
    def label(self) -> str:
        return self.name.lower().replace("_", " ")


JOINT_NAMES = ("rho1", "rho2", "rho3", "theta1", "theta2")


def joint_bounds(machine: Machine) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper), each (5,), in mm and rad; +-inf for a continuous rotary."""
    lower, upper = [], []
    for name in JOINT_NAMES:
        j = getattr(machine.joints, name)
        scale = 1.0 if name.startswith("rho") else np.pi / 180.0
        lower.append(-np.inf if j.continuous else j.min * scale)
        upper.append(np.inf if j.continuous else j.max * scale)
    return np.array(lower), np.array(upper)


def placeable(machine: Machine, joints: np.ndarray) -> np.ndarray:
    """(N, 5) mm, rad: ``joints`` with NaN rows where a joint is beyond its travel by more than the
    travel itself (kilometres of slider from a corrupt coordinate): no bodies are placed there,
    the limit check reports those poses, and their metres-long moves would be bisected without end."""
    lower, upper = joint_bounds(machine)
    span = np.where(np.isfinite(upper - lower), upper - lower, np.inf)
    absurd = any_of((joints < lower - span) | (joints > upper + span))
    return np.where(absurd[:, None], np.nan, joints)


def within_limits(machine: Machine, joints: np.ndarray) -> np.ndarray:
    """True where every joint of (N, 5) (mm, rad) is inside the machine's travel."""
    lower, upper = joint_bounds(machine)
    return all_of((joints >= lower) & (joints <= upper))


@dataclass(frozen=True)
class IKResult:
    """Working-mode inverse kinematics of N tool poses."""

    joints: np.ndarray  # (N, 5) rho1..3 mm, theta1, theta2 rad (NaN where unreachable)
    alpha: np.ndarray  # (N,) platform tilt, rad
    phi: np.ndarray  # (N, 2) tool-axis angles (phi1, phi2), rad
    pair: np.ndarray  # (N,) angle pair used: +1 or -1
    status: np.ndarray  # (N,) Status values
    margins: Margins  # (N,) each, NaN where unreachable (or not computed)
    platform: np.ndarray  # (N, 3) platform centre P, mm, base frame

    def take(self, mask: np.ndarray, other: IKResult) -> IKResult:
        """Rows of ``self`` where ``mask``, of ``other`` elsewhere."""
        return _fieldwise(lambda a, b: np.where(mask.reshape(mask.shape + (1,) * (a.ndim - 1)), a, b), self, other)

    def rows(self, index: np.ndarray) -> IKResult:
        """The solutions of poses ``index`` (an index array or mask)."""
        return _fieldwise(lambda a: take_rows(a, index), self)

    def scatter(self, index: np.ndarray, part: IKResult) -> IKResult:
        """A copy with rows ``index`` replaced by ``part``."""
        def put(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            out = a.copy()
            out[index] = b
            return out

        return _fieldwise(put, self, part)

    def with_joints(self, joints: np.ndarray) -> IKResult:
        return replace(self, joints=joints)


def pose_margins(machine: Machine, joints: np.ndarray, platform: np.ndarray, alpha: np.ndarray,
                 reachable: np.ndarray, tool_length: float | np.ndarray = 0.0) -> Margins:
    """Margins of N poses (NaN where not reachable); joints mm/rad, platform mm, alpha rad.

    ``tool_length`` (mm) is one value or one per pose.
    """
    n = len(alpha)
    lengths = np.broadcast_to(np.asarray(tool_length, dtype=float), (n,))
    out = [np.full(n, np.nan) for _ in Margins.__dataclass_fields__]
    for length in np.unique(lengths[reachable]):
        rows = reachable & (lengths == length)
        found = margins(machine.kinematic_geometry(float(length)), np.compress(rows, joints, axis=0),
                        np.compress(rows, platform, axis=0), alpha[rows])
        for array, name in zip(out, Margins.__dataclass_fields__, strict=True):
            array[rows] = getattr(found, name)
    return Margins(*out)


def classify(machine: Machine, joints: np.ndarray, reachable: np.ndarray, found: Margins) -> np.ndarray:
    """Status (N,) int8: unreachable, else out of limits (travel, leg I rod clearance), else singular."""
    status = np.full(len(reachable), Status.OK, dtype=np.int8)
    t = machine.singularity
    status[(found.serial < t.serial_min) | (found.parallel < t.parallel_min) | (found.machine < t.machine_min)] = (
        Status.SINGULAR)
    status[reachable & (~within_limits(machine, np.nan_to_num(joints)) | (found.rod_clearance < t.rod_clearance_min))
           ] = Status.OUT_OF_LIMITS
    status[~reachable] = Status.UNREACHABLE
    return status


def _fieldwise(function: Callable[..., np.ndarray], *results: IKResult) -> IKResult:
    """Apply ``function`` to each array field (margins included) of one or more results."""
    fields = {f: function(*(getattr(r, f) for r in results)) for f in IKResult.__dataclass_fields__ if f != "margins"}
    found = Margins(*(function(*(getattr(r.margins, f) for r in results)) for f in Margins.__dataclass_fields__))
    return IKResult(**fields, margins=found)


def concatenate(results: list[IKResult]) -> IKResult:
    """The rows of several results one after the other."""
    return _fieldwise(lambda *arrays: np.concatenate(arrays), *results)


def assess(machine: Machine, result: IKResult, tool_length: float | np.ndarray = 0.0) -> IKResult:
    """``result`` with its margins and status computed (tool length mm, one or per pose)."""
    reachable = result.status != Status.UNREACHABLE
    found = pose_margins(machine, result.joints, result.platform, result.alpha, reachable, tool_length)
    return replace(result, margins=found, status=classify(machine, result.joints, reachable, found))


def _status(machine: Machine, ik: MachineIK, pair: np.ndarray | int, tool_length: float, with_margins: bool
            ) -> IKResult:
    """IKResult of a kinematic solution; without margins only reach, travel and rod clearance count."""
    n = len(ik.alpha)
    g = machine.geometry
    nan = np.full(n, np.nan)
    found = Margins(nan, nan, nan, g.R1 * np.cos(ik.alpha) - g.r1)
    result = IKResult(ik.joints, ik.alpha, ik.phi, np.broadcast_to(np.asarray(pair, np.int8), (n,)).copy(),
                      classify(machine, ik.joints, ik.reachable, found), found, ik.platform)
    return assess(machine, result, tool_length) if with_margins else result


def _as_poses(tip: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    tip = np.atleast_2d(np.asarray(tip, dtype=float))
    axis = np.atleast_2d(np.asarray(axis, dtype=float))
    if tip.shape != axis.shape or tip.shape[-1] != 3:
        raise ValueError("tip and axis must both be (N, 3)")
    norm = norms(axis)[:, None]
    if np.any(norm == 0) or not np.all(np.isfinite(norm)) or not np.all(np.isfinite(tip)):
        raise ValueError("tool tip and axis must be finite and the axis of non-zero length")
    return tip, axis / norm


def inverse_kinematics_pair(machine: Machine, tip: np.ndarray, axis: np.ndarray, pair: np.ndarray | int, *,
                            tool_length: float = 0.0, theta2_at_pole: np.ndarray | float = 0.0,
                            with_margins: bool = True) -> IKResult:
    """Working-mode IK with the given tool-axis angle pair (+1 / -1, one or per pose).

    tip (N, 3) mm, axis (N, 3), table frame; ``theta2_at_pole`` (rad) is used where the axis is
    along the table normal. ``with_margins=False`` skips the singularity margins (faster;
    then the status knows reach, travel limits and rod clearance only).
    """
    tip, axis = _as_poses(tip, axis)
    ik = machine_ik_working(machine.kinematic_geometry(tool_length), tip, axis, pair=pair,
                            theta2_at_pole=theta2_at_pole)
    return _status(machine, ik, pair, tool_length, with_margins)


def inverse_kinematics_pairs(machine: Machine, tip: np.ndarray, axis: np.ndarray, *, tool_length: float = 0.0,
                             theta2_at_pole: np.ndarray | float = 0.0, with_margins: bool = True
                             ) -> tuple[IKResult, IKResult]:
    """Working-mode IK for both tool-axis angle pairs (+1, -1); see :func:`inverse_kinematics_pair`."""
    plus, minus = (inverse_kinematics_pair(machine, tip, axis, p, tool_length=tool_length,
                                           theta2_at_pole=theta2_at_pole, with_margins=with_margins) for p in (1, -1))
    return plus, minus


def inverse_kinematics(machine: Machine, tip: np.ndarray, axis: np.ndarray,
                       theta2_hint: np.ndarray | float | None = None, *, tool_length: float = 0.0) -> IKResult:
    """Working-mode IK of N tool poses: tip (N, 3) mm, axis (N, 3) unit, both in the table frame.

    Of the two angle pairs, the one with the better status is taken (ok, then singular, then
    out of limits); between equals the one whose theta2 is nearest ``theta2_hint`` (rad), or
    without a hint the one with the smaller |theta1|. theta2 is returned unwrapped to within
    pi of the hint; on the pole (axis along the table normal) theta2 = hint (0 without one).
    """
    if kernels.kernel("inverse_kinematics") is not None:
        return _inverse_kinematics_compiled(machine, tip, axis, theta2_hint, tool_length)
    return _inverse_kinematics_stepwise(machine, tip, axis, theta2_hint, tool_length)


def _inverse_kinematics_stepwise(machine: Machine, tip: np.ndarray, axis: np.ndarray,
                                 theta2_hint: np.ndarray | float | None, tool_length: float) -> IKResult:
    """:func:`inverse_kinematics` in whole-array steps (the numpy route's, and the compiled one's
    for the poses it leaves to the all-solutions route)."""
    hint = 0.0 if theta2_hint is None else theta2_hint
    # Both pairs without margins (reach, travel, rod clearance), margins for the chosen pair
    # only; where those make it singular, the other pair's margins decide.
    plus, minus = inverse_kinematics_pairs(machine, tip, axis, tool_length=tool_length, theta2_at_pole=hint,
                                           with_margins=False)
    hints = np.broadcast_to(np.asarray(hint, dtype=float), (len(plus.alpha),))

    def cost(r: IKResult, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """The solutions' cost; ``rows``: the poses they are of."""
        theta1, theta2 = r.joints[:, 3], r.joints[:, 4]
        preference = np.abs(theta1) if theta2_hint is None else np.abs(unwrap_near(theta2, hints[rows]) - hints[rows])
        penalty = np.array([0.0, 1e9, 1e6, 1e3])[r.status]  # by Status: ok, unreachable, limits, singular
        return penalty + np.nan_to_num(preference, nan=0.0)

    use_plus = cost(plus) <= cost(minus)
    chosen = assess(machine, plus.take(use_plus, minus), tool_length)
    other = plus.take(~use_plus, minus)
    retry = np.flatnonzero((chosen.status == Status.SINGULAR) & (other.status == Status.OK))
    if retry.size:
        alternative = assess(machine, other.rows(retry), tool_length)
        better = cost(alternative, retry) < cost(chosen.rows(retry), retry)
        chosen = chosen.scatter(retry[better], alternative.rows(better))
    joints = chosen.joints.copy()
    joints[:, 4] = unwrap_near(joints[:, 4], hint)
    return chosen.with_joints(joints)


def _inverse_kinematics_compiled(machine: Machine, tip: np.ndarray, axis: np.ndarray,
                                 theta2_hint: np.ndarray | float | None, tool_length: float) -> IKResult:
    """:func:`inverse_kinematics` on the compiled route: one loop (kernels.inverse_kinematics)
    solves both pairs a block of poses at a time and makes the choice pose by pose, without the
    stepwise route's dozens of passes over every array; the rare poses that need the
    all-solutions route go the stepwise way."""
    given = (tip, axis)  # the stepwise route normalises the axes itself
    tip, axis = _as_poses(tip, axis)
    geom = machine.kinematic_geometry(tool_length)
    hint = np.broadcast_to(np.asarray(0.0 if theta2_hint is None else theta2_hint, dtype=float), (len(tip),))
    t = machine.singularity
    *found, exact = kernels.inverse_kinematics(  # type: ignore[misc]
        geom, *joint_bounds(machine), (t.serial_min, t.parallel_min, t.machine_min, t.rod_clearance_min), tip, axis,
        true_theta2(geom, hint), hint, theta2_hint is not None)
    result = IKResult(*found[:5], Margins(*found[5]), found[6])  # type: ignore[call-arg]
    rows = np.flatnonzero(exact)
    if rows.size:
        stepwise = _inverse_kinematics_stepwise(machine, *(np.atleast_2d(a)[rows] for a in given),
                                                None if theta2_hint is None else hint[rows], tool_length)
        for whole, part in ((result, stepwise), (result.margins, stepwise.margins)):  # in place: the arrays are new
            for name in type(whole).__dataclass_fields__:
                if name != "margins":
                    getattr(whole, name)[rows] = getattr(part, name)
    return result


def inverse_kinematics_all(machine: Machine, tip: np.ndarray, axis: np.ndarray, *, tool_length: float = 0.0,
                           theta2_at_pole: float = 0.0) -> MachineIKSolutions:
    """Every IK solution (both angle pairs, all working modes) of N poses, table frame, mm."""
    tip, axis = _as_poses(tip, axis)
    return machine_ik_all(machine.kinematic_geometry(tool_length), tip, axis, theta2_at_pole=theta2_at_pole)


@dataclass(frozen=True)
class FKResult:
    """Working-mode forward kinematics of N joint sets."""

    tip: np.ndarray  # (N, 3) mm, table frame (NaN where the sliders admit no working assembly)
    axis: np.ndarray  # (N, 3) unit, table frame
    alpha: np.ndarray  # (N,) rad
    platform: np.ndarray  # (N, 3) mm, base frame
    reachable: np.ndarray  # (N,) bool


def forward_kinematics(machine: Machine, joints: np.ndarray, *, tool_length: float | np.ndarray = 0.0,
                       alpha_guess: np.ndarray | None = None) -> FKResult:
    """Tool tip (mm) and axis in the table frame, machine's assembly mode, for joints (N, 5) mm/rad.

    ``tool_length`` (mm) is one value or one per joint set; ``alpha_guess`` (rad, per joint
    set) starts the platform-tilt iteration near a known neighbour (along a path).
    """
    joints = np.atleast_2d(np.asarray(joints, dtype=float))
    lengths = np.broadcast_to(np.asarray(tool_length, dtype=float), (len(joints),))
    each = np.unique(lengths)
    if len(each) == 1:  # one tool: no rows to gather and scatter (each pose's numbers are its own)
        fk = machine_fk_working(machine.kinematic_geometry(float(each[0])), joints, alpha_guess)
        return FKResult(fk.tip, fk.axis, fk.alpha, fk.platform, fk.reachable)
    out = FKResult(np.empty((len(joints), 3)), np.empty((len(joints), 3)), np.empty(len(joints)),
                   np.empty((len(joints), 3)), np.empty(len(joints), bool))
    for length in each:
        rows = lengths == length
        guess = None if alpha_guess is None else np.asarray(alpha_guess)[rows]
        fk = machine_fk_working(machine.kinematic_geometry(float(length)), np.compress(rows, joints, axis=0), guess)
        for name, value in (("tip", fk.tip), ("axis", fk.axis), ("alpha", fk.alpha), ("platform", fk.platform),
                            ("reachable", fk.reachable)):
            getattr(out, name)[rows] = value
    return out


def forward_kinematics_all(machine: Machine, joints: np.ndarray, *, tool_length: float = 0.0) -> MachineFKSolutions:
    """Every assembly mode of N joint sets (mm, rad): tips mm and axes in the table frame."""
    return machine_fk_all(machine.kinematic_geometry(tool_length), np.atleast_2d(np.asarray(joints, dtype=float)))
