"""Identification: nonlinear least squares on the forward-kinematics residuals, identifiability
by the SVD of the scaled Jacobian, robust outlier flags.

Residuals are predicted minus measured tool tips (mm, table frame), times the square root of
each pose's weight; a measured tool axis adds its three components times
:data:`~.model.AXIS_LENGTH`. Parameters are fitted as ``(p - p_nominal) / SCALE``. Pure: no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from ..errors import UserError
from .model import AXIS_LENGTH, PARAMETERS, SCALE, UNREACHABLE_RESIDUAL, Poses, jacobian, predict

#: Directions of the column-normalised Jacobian with a singular value below this fraction of
#: the largest are exact dependencies (the measurements cannot tell the parameters apart at all).
RANK_RTOL = 1e-9

#: A direction whose standard deviation after the fit exceeds this many typical errors
#: (:data:`~.model.SCALE`) is determined no better than the nominal value already is: it is
#: held, not fitted to noise.
WEAK_STD = 0.5

#: Which parameter of an inseparable combination is held at its nominal value, first first: the
#: table-side dimensions (measured when the machine is set up) before the link dimensions, the
#: slider zeros last (they are what a calibration is usually for).
HOLD_ORDER = ("da", "dt", "spindle_nose", "theta1_offset", "theta2_offset", "r1", "r4", "R1", "R2", "D1_minus_d1",
              "D2_minus_d2", "L1", "L2", "L3", "rho1_offset", "rho2_offset", "rho3_offset")

#: A pose is an outlier when its residual norm exceeds the median by this many robust standard
#: deviations (1.4826 times the median absolute deviation of the norms).
OUTLIER_Z = 6.0

#: Rounds of fit, reject, refit with ``reject``.
MAX_REJECT_ROUNDS = 5


class FitError(UserError):
    """The least-squares fit did not converge: exit code 3, with the reason."""

    exit_code = 3


@dataclass(frozen=True)
class Direction:
    """One singular direction of the scaled Jacobian: relative singular value and its
    parameter combination (name -> component, largest first, the small ones left out)."""

    relative: float
    std: float  # in typical errors (SCALE units); NaN before a fit
    combination: dict[str, float]


@dataclass(frozen=True)
class Calibration:
    """Result of :func:`calibrate`. Parameters in mm and rad (see :mod:`.model`)."""

    nominal: np.ndarray  # (17,)
    fitted: np.ndarray  # (17,): nominal where not fitted
    std: np.ndarray  # (17,) standard deviation of the fitted values (NaN where held)
    status: dict[str, str]  # name -> fitted | fixed | held
    reasons: dict[str, str]  # name -> why it is held (held parameters only)
    residual_before: np.ndarray  # (N, 3) predicted - measured tip, nominal, mm
    residual_after: np.ndarray  # (N, 3) fitted, mm
    used: np.ndarray  # (N,) bool: poses in the final fit
    outlier: np.ndarray  # (N,) bool: flagged by the robust statistic (after the fit)
    robust_z: np.ndarray  # (N,) (norm - median) / (1.4826 MAD)
    sigma: float  # mm: noise estimated from the final fit's residuals
    directions: list[Direction]  # identifiability table of the final fit
    evaluations: int
    message: str
    free: list[str] = field(default_factory=list)

    def summary(self) -> dict[str, float]:
        """RMS and max tip residual norms (mm) before and after, over the poses used."""
        before = np.linalg.norm(self.residual_before[self.used], axis=1)
        after = np.linalg.norm(self.residual_after[self.used], axis=1)
        return {"rms_before": float(np.sqrt(np.mean(before**2))), "max_before": float(before.max()),
                "rms_after": float(np.sqrt(np.mean(after**2))), "max_after": float(after.max())}


def residuals(p: np.ndarray, poses: Poses) -> tuple[np.ndarray, np.ndarray]:
    """(tip, axis) residuals (N, 3) each: predicted minus measured; NaN rows where unreachable."""
    fk = predict(p, poses.joints, poses.tool_length)
    return fk.tip - poses.tip, fk.axis - poses.axis


class _Problem:
    """The weighted residual vector and its Jacobian in scaled variables u over free parameters."""

    def __init__(self, p0: np.ndarray, poses: Poses, free: np.ndarray) -> None:
        self.p0, self.poses, self.free = p0, poses, free
        self.root_w = np.sqrt(poses.weight)
        self.axis_rows = poses.has_axis

    def parameters(self, u: np.ndarray) -> np.ndarray:
        p = self.p0.copy()
        p[self.free] += SCALE[self.free] * u
        return p

    def _stack(self, tip: np.ndarray, axis: np.ndarray) -> np.ndarray:
        """Weighted rows: tips (N, 3[, P]) then the measured axes' rows, flattened to (M[, P])."""
        w = self.root_w.reshape((-1, 1) + (1,) * (tip.ndim - 2))
        parts = [tip * w]
        if self.axis_rows.any():
            parts.append(axis[self.axis_rows] * w[self.axis_rows] * AXIS_LENGTH)
        return np.concatenate(parts, axis=0).reshape(-1, *tip.shape[2:])

    def fun(self, u: np.ndarray) -> np.ndarray:
        p = self.parameters(u)
        fk = predict(p, self.poses.joints, self.poses.tool_length)
        tip = np.where(fk.reachable[:, None], fk.tip - self.poses.tip, UNREACHABLE_RESIDUAL)
        axis = np.where(fk.reachable[:, None], fk.axis - self.poses.axis, 0.0)
        return self._stack(tip, axis)

    def jac(self, u: np.ndarray) -> np.ndarray:
        p = self.parameters(u)
        fk = predict(p, self.poses.joints, self.poses.tool_length)
        d_tip, d_axis = jacobian(p, self.poses.joints, self.poses.tool_length, fk)
        scale = SCALE[self.free]
        return self._stack(d_tip[:, :, self.free] * scale, d_axis[:, :, self.free] * scale)


def directions(jac: np.ndarray, names: list[str], sigma: float | None
                ) -> tuple[np.ndarray, np.ndarray, list[Direction]]:
    """Relative singular values of the column-normalised Jacobian, the right singular vectors, and
    the identifiability table; ``std`` from the unnormalised SVD when the noise ``sigma`` is known."""
    norms = np.linalg.norm(jac, axis=0)
    norms[norms == 0] = 1.0
    _, s, vt = np.linalg.svd(jac / norms, full_matrices=False)
    relative = s / s[0]
    std = np.full(len(s), np.nan)
    if sigma is not None:
        _, s_raw, _ = np.linalg.svd(jac, full_matrices=False)
        with np.errstate(divide="ignore"):
            std = sigma / s_raw
    table = []
    for k in range(len(s)):
        v = vt[k] / np.max(np.abs(vt[k]))
        combination = {names[j]: round(float(v[j]), 3) for j in np.argsort(-np.abs(v)) if abs(v[j]) >= 0.1}
        table.append(Direction(float(relative[k]), float(std[k]), combination))
    return relative, vt, table


def hold_for(vector: np.ndarray, names: list[str]) -> str:
    """The parameter to hold for a dependent direction: of those taking part in it (component
    at least 0.3 of the largest), the first in :data:`HOLD_ORDER`."""
    weight = np.abs(vector) / np.max(np.abs(vector))
    involved = [names[j] for j in np.flatnonzero(weight >= 0.3)]
    return min(involved, key=HOLD_ORDER.index)


def describe(vector: np.ndarray, names: list[str]) -> str:
    v = vector / np.max(np.abs(vector))
    return " ".join(f"{v[j]:+.2f} {names[j]}" for j in np.argsort(-np.abs(v)) if abs(v[j]) >= 0.1)


def _robust_z(norms: np.ndarray, used: np.ndarray) -> np.ndarray:
    """(norm - median) / (1.4826 MAD) with median and MAD of the poses ``used`` (a dropped pose
    is measured against the others)."""
    median = np.median(norms[used])
    mad = 1.4826 * np.median(np.abs(norms[used] - median))
    return (norms - median) / max(mad, 1e-12)


def calibrate(p0: np.ndarray, poses: Poses, fix: tuple[str, ...] = (), reject: bool = False,
              max_evaluations: int = 200) -> Calibration:
    """Fit the parameters (17,) mm/rad starting from ``p0`` to the measured ``poses``.

    ``fix`` names parameters held at their ``p0`` value. Exact dependencies (found before the
    fit) and combinations determined worse than :data:`WEAK_STD` typical errors (after it) are
    held too, one parameter each, chosen by :data:`HOLD_ORDER`. With ``reject``, poses flagged
    as outliers are dropped and the fit repeated until none is flagged. Raises :class:`FitError`
    when the solver does not converge.
    """
    unknown = [n for n in fix if n not in PARAMETERS]
    if unknown:
        raise UserError(f"--fix: unknown parameter '{unknown[0]}' (one of {', '.join(PARAMETERS)})")
    used = np.ones(len(poses), bool)
    before_tip, _ = residuals(p0, poses)
    for _round in range(MAX_REJECT_ROUNDS + 1):
        # What is held is decided afresh for each set of poses.
        status = {n: ("fixed" if n in fix else "fitted") for n in PARAMETERS}
        reasons: dict[str, str] = {n: "fixed by --fix" for n in fix}
        p, jac, sigma, free, evaluations, message = _fit_used(p0, poses, used, status, reasons, max_evaluations)
        after_tip, _ = residuals(p, poses)
        z = _robust_z(np.linalg.norm(after_tip, axis=1), used)
        outlier = z > OUTLIER_Z
        if not reject or not np.any(outlier & used):
            break
        used = used & ~outlier
    names = [PARAMETERS[k] for k in free]
    _, _, table = directions(jac, names, sigma)
    std = np.full(len(PARAMETERS), np.nan)
    try:
        covariance = sigma**2 * np.linalg.inv(jac.T @ jac)
        std[free] = np.sqrt(np.diag(covariance)) * SCALE[free]
    except np.linalg.LinAlgError:
        pass
    return Calibration(p0.copy(), p, std, status, reasons, before_tip, after_tip, used, outlier, z, sigma, table,
                       evaluations, message, names)


def _fit_used(p0: np.ndarray, poses: Poses, used: np.ndarray, status: dict[str, str], reasons: dict[str, str],
              max_evaluations: int) -> tuple[np.ndarray, np.ndarray, float, np.ndarray, int, str]:
    """Fit on the poses ``used``; updates ``status``/``reasons`` with the parameters it holds."""
    subset = poses.take(used)
    # Exact dependencies first, at the start values.
    while True:
        free = np.array([k for k, n in enumerate(PARAMETERS) if status[n] == "fitted"])
        problem = _Problem(p0, subset, free)
        _check_count(problem, free)
        names = [PARAMETERS[k] for k in free]
        relative, vt, _ = directions(problem.jac(np.zeros(len(free))), names, None)
        if relative[-1] >= RANK_RTOL:
            break
        hold = hold_for(vt[-1], names)
        status[hold] = "held"
        reasons[hold] = f"cannot be told apart from the others of {describe(vt[-1], names)} (exact dependency)"
    # Then fit, and hold what the fit determines no better than the nominal value already is.
    while True:
        free = np.array([k for k, n in enumerate(PARAMETERS) if status[n] == "fitted"])
        problem = _Problem(p0, subset, free)
        _check_count(problem, free)
        found = least_squares(problem.fun, np.zeros(len(free)), jac=problem.jac, method="trf", x_scale=1.0,
                              xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=max_evaluations)
        if found.status <= 0 or not np.all(np.isfinite(found.x)):
            raise FitError(f"the fit did not converge after {found.nfev} evaluations: {found.message}")
        p = problem.parameters(found.x)
        jac = problem.jac(found.x)
        dof = max(len(found.fun) - len(free), 1)
        sigma = float(np.sqrt(np.sum(found.fun**2) / dof))
        if np.any(np.abs(found.fun) >= UNREACHABLE_RESIDUAL):
            raise FitError("the fit did not converge: at the best geometry found some measured poses have no working "
                           "assembly (the measurements do not fit this machine)")
        names = [PARAMETERS[k] for k in free]
        # The noise for this test without the poses that stand out: an outlier must not make
        # well-determined parameters look weak.
        tip_rows = found.fun[: 3 * len(subset)].reshape(-1, 3)
        clean = _robust_z(np.linalg.norm(tip_rows, axis=1), np.ones(len(subset), bool)) <= OUTLIER_Z
        clean_rows = 3 * int(clean.sum())
        clean_sigma = float(np.sqrt(np.sum(tip_rows[clean] ** 2) / max(clean_rows - len(free), 1)))
        relative, vt, table = directions(jac, names, clean_sigma)
        weak = [k for k, d in enumerate(table) if not d.std <= WEAK_STD]
        if not weak:
            return p, jac, sigma, free, found.nfev, str(found.message)
        k = weak[-1]
        hold = hold_for(vt[k], names)
        status[hold] = "held"
        reasons[hold] = (f"the measurements determine {describe(vt[k], names)} only to {table[k].std:.2g} typical "
                         "errors (weakly identifiable)")


def _check_count(problem: _Problem, free: np.ndarray) -> None:
    rows = 3 * len(problem.poses) + 3 * int(problem.axis_rows.sum())
    if rows <= len(free):
        raise UserError(f"{len(problem.poses)} poses give {rows} equations for {len(free)} free parameters: "
                        f"at least {len(free) // 3 + 1} poses are needed (many more for a useful fit)")


__all__ = ["Calibration", "Direction", "FitError", "calibrate", "residuals"]
