"""Identification: least squares on the forward-kinematics residuals with a weak prior toward
the machine file, a robust first pass, outlier flags and the covariance of the result.

Residuals are predicted minus measured tool tips (mm, table frame), times the square root of
each pose's weight; a measured tool axis adds its three components times
:data:`~.model.AXIS_LENGTH`. Parameters are fitted as ``u = (p - p_file) / SCALE``, and the
residual vector ends with ``sigma * u``: a prior of one typical error on every parameter,
weighed against the measuring noise ``sigma`` (estimated from the residuals). Where the tips
determine a direction to a small fraction of a typical error the prior changes nothing; where
they say nothing (the common slider zero against da) it keeps the file's values. No parameter
is held unless asked (``fix``). Pure: no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import chi2
from scipy.stats import f as f_dist

from ..errors import UserError
from .directions import RANK_RTOL, Direction, directions, explain
from .model import AXIS_LENGTH, PARAMETERS, SCALE, UNREACHABLE_RESIDUAL, Poses, Prediction, jacobian, predict

#: Noise (mm) assumed by the first pass, before the residuals give it.
SIGMA_GUESS = 0.003

#: The robust first pass: soft-L1 loss with its knee at this many noise standard deviations.
ROBUST_KNEE = 2.5

#: Probability that a clean data set has any pose flagged (the threshold on each pose's
#: standardised residual is the quantile of OUTLIER_ALPHA / poses).
OUTLIER_ALPHA = 1e-3

#: Rounds of fit, reject, refit with ``reject``.
MAX_REJECT_ROUNDS = 5

#: Residual degrees of freedom (equations less the directions the poses determine) needed to
#: estimate the noise at all.
MIN_DOF = 3


class FitError(UserError):
    """The least-squares fit did not converge: exit code 3, with the reason."""

    exit_code = 3


class TooFewPosesError(UserError):
    """Too few poses to estimate the measuring noise (bad input: exit code 2)."""


@dataclass(frozen=True)
class Calibration:
    """Result of :func:`calibrate`. Parameters in mm and rad (see :mod:`.model`)."""

    nominal: np.ndarray  # (17,)
    fitted: np.ndarray  # (17,): nominal where fixed
    std: np.ndarray  # (17,) posterior standard deviation of the values (NaN where fixed)
    status: dict[str, str]  # name -> fitted | fixed
    notes: list[str]  # what the measurements leave open, in the shop's words
    residual_before: np.ndarray  # (N, 3) predicted - measured tip, nominal, mm
    residual_after: np.ndarray  # (N, 3) fitted, mm
    used: np.ndarray  # (N,) bool: poses in the final fit
    outlier: np.ndarray  # (N,) bool: flagged on the robust fit's residuals
    score: np.ndarray  # (N,) standardised tip residual (noise standard deviations, leverage corrected)
    threshold: float  # score above which a pose is flagged
    sigma: float  # mm: noise estimated from the final fit's residuals
    directions: list[Direction]  # identifiability table of the final fit
    evaluations: int
    message: str
    robust: bool = False  # the values are the robust fit's (outliers flagged, not rejected)
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
    """Weighted residuals and their Jacobian in scaled variables u over the free parameters,
    data rows (tips, then measured axes) followed by the prior's rows ``prior * u``."""

    def __init__(self, p0: np.ndarray, poses: Poses, free: np.ndarray, prior: float) -> None:
        self.p0, self.poses, self.free, self.prior = p0, poses, free, prior
        self.root_w = np.sqrt(poses.weight)
        self.axis_rows = poses.has_axis
        self.rows = 3 * len(poses) + 3 * int(self.axis_rows.sum())
        # The platform's tilt at the start: the trial geometries are near it (a fast FK), and
        # the last prediction is kept, for the Jacobian asks for the point the residuals did.
        start = predict(p0, poses.joints, poses.tool_length)
        self.alpha_guess = np.where(start.reachable, start.alpha, 0.0)
        self._last: tuple[bytes, Prediction] | None = None

    def predict(self, u: np.ndarray) -> Prediction:
        key = u.tobytes()
        if self._last is None or self._last[0] != key:
            self._last = (key, predict(self.parameters(u), self.poses.joints, self.poses.tool_length,
                                       self.alpha_guess))
        return self._last[1]

    def parameters(self, u: np.ndarray) -> np.ndarray:
        p = self.p0.copy()
        p[self.free] += SCALE[self.free] * u
        return p

    def _stack(self, tip: np.ndarray, axis: np.ndarray) -> np.ndarray:
        """Weighted rows: tips (N, 3[, P]) then the measured axes' rows, flattened to (M[, P])."""
        w = self.root_w.reshape((-1, 1) + (1,) * (tip.ndim - 2))
        parts = [tip * w, axis[self.axis_rows] * w[self.axis_rows] * AXIS_LENGTH]
        return np.concatenate(parts, axis=0).reshape(-1, *tip.shape[2:])

    def data(self, u: np.ndarray) -> np.ndarray:
        fk = self.predict(u)
        tip = np.where(fk.reachable[:, None], fk.tip - self.poses.tip, UNREACHABLE_RESIDUAL)
        axis = np.where(fk.reachable[:, None], fk.axis - self.poses.axis, 0.0)
        return self._stack(tip, axis)

    def data_jac(self, u: np.ndarray) -> np.ndarray:
        p = self.parameters(u)
        d_tip, d_axis = jacobian(p, self.poses.joints, self.poses.tool_length, self.predict(u))
        scale = SCALE[self.free]
        return self._stack(d_tip[:, :, self.free] * scale, d_axis[:, :, self.free] * scale)

    def fun(self, u: np.ndarray) -> np.ndarray:
        return np.r_[self.data(u), self.prior * u]

    def jac(self, u: np.ndarray) -> np.ndarray:
        return np.vstack([self.data_jac(u), self.prior * np.eye(len(u))])


@dataclass(frozen=True)
class _Fit:
    u: np.ndarray
    data: np.ndarray  # weighted data residuals (M,)
    jac: np.ndarray  # (M, P) data rows
    sigma: float
    evaluations: int
    message: str


def _solve(problem: _Problem, u0: np.ndarray, max_evaluations: int, loss: str = "linear", knee: float = 1.0
           ) -> tuple[np.ndarray, int, str]:
    found = least_squares(problem.fun, u0, jac=problem.jac, method="trf", loss=loss, f_scale=knee, x_scale=1.0,
                          xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=max_evaluations)
    if found.status <= 0 or not np.all(np.isfinite(found.x)):
        raise FitError(f"the fit did not converge after {found.nfev} evaluations: {found.message}")
    if np.any(np.abs(found.fun[: problem.rows]) >= UNREACHABLE_RESIDUAL):
        raise FitError("the fit did not converge: at the best geometry found some measured poses have no working "
                       "assembly (the measurements do not fit this machine)")
    return found.x, int(found.nfev), str(found.message)


def _noise(data: np.ndarray, jac: np.ndarray, prior: float) -> float:
    """Noise estimate (mm): residual sum of squares over the equations the fit leaves free
    (rows less the effective number of parameters, sum s^2 / (s^2 + prior^2))."""
    s = np.linalg.svd(jac, compute_uv=False)
    dof = len(data) - float(np.sum(s**2 / (s**2 + prior**2)))
    return float(np.sqrt(np.sum(data**2) / max(dof, 1.0)))


def _least_squares_fit(problem: _Problem, max_evaluations: int) -> _Fit:
    """The fit with the prior weighed against a guessed noise, then against the noise found."""
    u, evaluations, _ = _solve(problem, np.zeros(len(problem.free)), max_evaluations)
    problem.prior = _noise(problem.data(u), problem.data_jac(u), problem.prior)
    u, more, message = _solve(problem, u, max_evaluations)
    data, jac = problem.data(u), problem.data_jac(u)
    return _Fit(u, data, jac, _noise(data, jac, problem.prior), evaluations + more, message)


def _scores(problem: _Problem, fit_u: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Each pose's tip residual in noise standard deviations, leverage corrected
    (sqrt(r^T (I - H_ii)^-1 r) / sigma: chi with 3 degrees of freedom on clean data), and the
    score above which a pose is an outlier. The noise comes from the poses below a first,
    median-based cut (an outlier does not inflate it); the threshold allows for that estimate's
    own scatter (F distribution), so that a clean set of any size is flagged with probability
    :data:`OUTLIER_ALPHA`. Returns the scores, the threshold and that noise (mm)."""
    n = len(problem.poses)
    data = problem.data(fit_u)[: 3 * n].reshape(n, 3)
    jac = problem.data_jac(fit_u)
    tip_jac = jac[: 3 * n].reshape(n, 3, -1)
    inverse = np.linalg.inv(jac.T @ jac + problem.prior**2 * np.eye(jac.shape[1]))
    hat = np.einsum("nip,pq,njq->nij", tip_jac, inverse, tip_jac)
    # A pose the fit leans on alone (leverage near 1) says little about itself: floor at 1 %.
    values, vectors = np.linalg.eigh(np.eye(3) - hat)
    rest_inv = np.einsum("nij,nj,nkj->nik", vectors, 1.0 / np.maximum(values, 0.01), vectors)
    t = np.einsum("ni,nij,nj->n", data, rest_inv, data)
    first = t / max(float(np.median(t)) / chi2.median(3), 1e-30) > chi2.isf(OUTLIER_ALPHA / n, 3)
    clean = t[~first] if (~first).any() else t
    sigma2 = max(float(np.mean(clean)) / 3.0, 1e-30)
    threshold = float(np.sqrt(3.0 * f_dist.isf(OUTLIER_ALPHA / n, 3, 3 * len(clean))))
    return np.sqrt(t / sigma2), threshold, float(np.sqrt(sigma2))


def calibrate(p0: np.ndarray, poses: Poses, fix: tuple[str, ...] = (), reject: bool = False,
              max_evaluations: int = 200) -> Calibration:
    """Fit the parameters (17,) mm/rad starting from ``p0`` to the measured ``poses``.

    ``fix`` names parameters held at their ``p0`` value; every other one is fitted, the prior
    toward ``p0`` deciding only the directions the tips do not determine (reported in
    ``notes``). A robust pass (soft-L1) flags the poses that stand out; with ``reject`` they
    are dropped and the fit repeated until none is, without it the values are the robust
    pass's. Raises :class:`FitError` when the solver does not converge and
    :class:`~verne_post.errors.UserError` when the poses are too few to estimate the noise.
    """
    unknown = [n for n in fix if n not in PARAMETERS]
    if unknown:
        raise UserError(f"--fix: unknown parameter '{unknown[0]}' (one of {', '.join(PARAMETERS)})")
    status = {n: ("fixed" if n in fix else "fitted") for n in PARAMETERS}
    free = np.array([k for k, n in enumerate(PARAMETERS) if status[n] == "fitted"], dtype=int)
    used = np.ones(len(poses), bool)
    before_tip, _ = residuals(p0, poses)
    evaluations = 0
    for _round in range(MAX_REJECT_ROUNDS + 1):
        problem = _Problem(p0, poses.take(used), free, SIGMA_GUESS)
        _check_count(problem)
        fit = _least_squares_fit(problem, max_evaluations)
        evaluations += fit.evaluations
        # The knee at the noise of the poses that do not stand out: an outlier must not widen it.
        robust_u, more, _ = _solve(problem, fit.u, max_evaluations, "soft_l1", ROBUST_KNEE * _scores(problem, fit.u)[2])
        evaluations += more
        score_used, threshold, _ = _scores(problem, robust_u)
        flagged = score_used > threshold
        if not reject or not flagged.any() or flagged.all():
            break
        used[np.flatnonzero(used)[flagged]] = False
    score = np.full(len(poses), np.nan)
    score[used] = score_used
    outlier = ~used  # dropped by --reject
    outlier[np.flatnonzero(used)[flagged]] = True
    robust = bool(flagged.any() and not flagged.all())
    u = robust_u if robust else fit.u
    if robust:  # covariance and noise of the poses the robust fit believes
        kept = _Problem(p0, problem.poses.take(~flagged), free, problem.prior)
        data, jac = kept.data(u), kept.data_jac(u)
        sigma = _noise(data, jac, problem.prior)
    else:
        data, jac, sigma = fit.data, fit.jac, fit.sigma
    p = problem.parameters(u)
    covariance = sigma**2 * np.linalg.inv(jac.T @ jac + sigma**2 * np.eye(len(free)))
    std = np.full(len(PARAMETERS), np.nan)
    std[free] = np.sqrt(np.diag(covariance)) * SCALE[free]
    free_list = [int(k) for k in free]
    table = directions(jac, free_list, sigma)
    notes = [explain(d) for d in table if d.weak]
    after_tip, _ = residuals(p, poses)
    # Poses dropped by --reject are scored against the final fit's noise.
    dropped = ~used
    if dropped.any():
        score[dropped] = np.linalg.norm(after_tip[dropped] * np.sqrt(poses.weight[dropped, None]), axis=1) / sigma
    return Calibration(p0.copy(), p, std, status, notes, before_tip, after_tip, used, outlier, score, threshold,
                       sigma, table, evaluations, fit.message, robust, [PARAMETERS[k] for k in free_list])


def _check_count(problem: _Problem) -> None:
    """Refuse poses too few to estimate the noise: rows less the directions they determine."""
    n = len(problem.poses)
    jac = problem.data_jac(np.zeros(len(problem.free)))
    s = np.linalg.svd(jac, compute_uv=False)
    rank = int(np.sum(s > RANK_RTOL * s[0])) if s.size and s[0] > 0 else 0
    if problem.rows - rank < MIN_DOF:
        # Many poses determine every free parameter but the common slider zero against da.
        names = {PARAMETERS[k] for k in problem.free}
        most = len(names) - int({"da", "rho1_offset", "rho2_offset", "rho3_offset"} <= names)
        need = max(n + 1, -(-(most + MIN_DOF) // 3))
        raise TooFewPosesError(f"{n} poses give {problem.rows} equations for the {rank} parameter directions they "
                               f"determine: too few to estimate the measuring noise; measure at least {need} poses "
                               "(80 for a useful fit, planned with --plan)")


__all__ = ["Calibration", "FitError", "TooFewPosesError", "calibrate", "residuals"]
