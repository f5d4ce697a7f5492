"""Second-order time-optimal path parametrisation (TOPP2) of one path on a grid: two engines.

The problem, in the path parameter s on gridpoints s_0 < ... < s_N: find the squared path
speeds x_i = sdot(s_i)^2 (1/s^2), x_0 = x_N = 0, that minimise the time under

* ``0 <= x_i <= xmax_i`` (velocity caps),
* ``|u| <= umax_i`` on each interval, u = (x_{i+1} - x_i) / (2 (s_{i+1} - s_i)) the path
  acceleration (1/s^2), at both of its gridpoints,
* ``|q1_i,j u + q2_i,j x_i| <= 1`` per joint j at both gridpoints of each interval (joint
  accelerations, rows already divided by their limits): the "interpolation" discretisation of
  Pham & Pham, "A new approach to time-optimal path parameterization based on reachability
  analysis", IEEE T-RO 2018, which both engines solve by reachability analysis (TOPP-RA).

Engines (same problem, same answer to solver tolerance; ``benchmarks/timing.py`` runs both):

* ``copp``: copp-py's ``topp2_ra`` (Rust core, MIT licence, https://copp.pro), a few
  microseconds per gridpoint.
* ``toppra``: the reference, toppra's TOPPRA with its seidel solver (per-gridpoint Python).

Each returns x (N + 1,), or raises :class:`ToppError` with the gridpoint where the solver
found no solution (the caller retries or reports). Nothing here knows about machines, files or
units beyond the above.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any, Literal

import numpy as np

ENGINES = ("copp", "toppra")
Engine = Literal["copp", "toppra"]
Solver = Callable[[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray, np.ndarray], np.ndarray]


class ToppError(Exception):
    """The engine found no time law; ``index`` is the gridpoint where it broke down (None: unknown)."""

    def __init__(self, message: str, index: int | None) -> None:
        super().__init__(message)
        self.index = index


def solver(engine: Engine) -> Solver:
    """The TOPP2 function of an engine: ``f(grid, xmax, umax, q1, q2) -> x``."""
    if engine == "copp":
        return _copp
    if engine == "toppra":
        return _toppra
    raise ValueError(f"unknown TOPP engine {engine!r}: use one of {', '.join(ENGINES)}")


def _copp(grid: np.ndarray, xmax: np.ndarray, umax: np.ndarray | None, q1: np.ndarray, q2: np.ndarray
          ) -> np.ndarray:
    import copp_py as copp

    n = len(grid)
    if umax is not None:  # |u| <= umax as one more row beside the joints' (rows a * x + b * u)
        q1 = np.column_stack([q1, 1.0 / umax])
        q2 = np.column_stack([q2, np.zeros(n)])
    rows = q1.shape[1]
    # copp-py adds all the rows of a station in one call fast, more rows to a station slowly:
    # so one call for the upper bounds, one for the lower.
    constraints = copp.Constraints(rows, capacity=n)
    constraints.append_s(grid)
    # copp-py wants caps > 0; the ends are held at rest by the boundary values anyway.
    constraints.add_constraint_1st(np.maximum(xmax, 1e-300).reshape(n, 1), 0)
    ones = np.ones((n, rows))
    constraints.add_constraint_2nd(q2, q1, ones, 0)
    constraints.add_constraint_2nd(q2, q1, -ones, 0, is_negative=True)
    try:
        problem = copp.solver.topp2_ra.Problem(constraints, (0, n - 1), (0.0, 0.0))
        x = np.asarray(copp.solver.topp2_ra.solve(problem), dtype=float)
    except copp.CoppError as error:  # "... empty at index 1998 during the backward pass ..."
        found = re.search(r"index (\d+)", str(error))
        raise ToppError(f"copp-py: {error}", int(found.group(1)) if found else None) from error
    bad = np.flatnonzero(~np.isfinite(x))
    if x.shape != (n,) or len(bad):
        raise ToppError("copp-py returned a non-finite profile", int(bad[0]) if len(bad) else None)
    return x


class _Unused:
    """toppra's TOPPRA wants a geometric path; every constraint here is precomputed on the grid."""

    path_interval = np.array([0.0, 1.0])

    def __init__(self, dof: int) -> None:
        self.dof = dof

    def __call__(self, positions: Any, order: int = 0) -> np.ndarray:
        raise AssertionError("the constraints are precomputed: the path is never evaluated")


def _toppra(grid: np.ndarray, xmax: np.ndarray, umax: np.ndarray | None, q1: np.ndarray, q2: np.ndarray
            ) -> np.ndarray:
    import toppra.algorithm
    from toppra.constraint import DiscretizationType, LinearConstraint, canlinear_colloc_to_interpolate

    dof = q1.shape[1]

    class PathBound(LinearConstraint):  # type: ignore[misc]
        def __init__(self) -> None:
            super().__init__()
            self.dof = dof

        def compute_constraint_params(self, path: Any, gridpoints: np.ndarray, *args: Any, **kwargs: Any) -> tuple:
            xbound = np.stack([np.zeros(len(gridpoints)), xmax], axis=1)
            ubound = None if umax is None else np.stack([-umax, umax], axis=1)
            return None, None, None, None, None, ubound, xbound

    class AccelerationBound(LinearConstraint):  # type: ignore[misc]
        def __init__(self) -> None:
            super().__init__()
            self.dof = dof
            self.set_discretization_type(DiscretizationType.Interpolation)
            self.identical = True

        def compute_constraint_params(self, path: Any, gridpoints: np.ndarray, *args: Any, **kwargs: Any) -> tuple:
            f = np.vstack([np.eye(dof), -np.eye(dof)])
            return canlinear_colloc_to_interpolate(q1, q2, np.zeros_like(q1), f, np.ones(2 * dof), None, None,
                                                   gridpoints, identical=True)

    try:
        instance = toppra.algorithm.TOPPRA([PathBound(), AccelerationBound()], _Unused(dof), gridpoints=grid,
                                           solver_wrapper="seidel")
        _, sd, _, controllable = instance.compute_parameterization(0.0, 0.0, return_data=True)
    except Exception as error:  # any toppra failure is reported, never planned around
        raise ToppError(f"toppra: {type(error).__name__}: {error}", None) from error
    if sd is not None and np.all(np.isfinite(sd)):
        return np.asarray(sd, dtype=float) ** 2
    # Where it broke down: the last gridpoint whose controllable set was lost in the backward
    # pass, else the first non-finite speed of the forward pass.
    index = None
    if controllable is not None:
        lost = np.flatnonzero(~np.all(np.isfinite(controllable), axis=1))
        index = int(lost.max()) if len(lost) else None
    if sd is not None:
        lost = np.flatnonzero(~np.isfinite(sd))
        index = int(lost.min()) if len(lost) else index
    raise ToppError("toppra: instance not controllable or numerically ill-conditioned", index)
