"""Compiled per-pose loops of the working-mode kinematics, with numpy as the reference route.

The numpy functions in :mod:`.full`, :mod:`.module` and :mod:`.jacobian` make a dozen or more
passes over every array (one per arithmetic step, a temporary each): at a million poses most of
the time goes to memory traffic and temporaries, not arithmetic. :mod:`._loops` runs the same
formulas as one loop per pose, compiled by numba (https://numba.readthedocs.io, ``@njit``;
``cache=True`` keeps the machine code in ``__pycache__``, so only the first process compiles).

The route: numpy unless ``VERNE_POST_KERNELS=numba`` is set and numba is installed (``pip
install verne-post[fast]``); ``verne-post --version`` names the one that runs. The compiled route
is asked for, not the default, for two measured reasons (docs/benchmarks.md): numba's import
alone takes about 0.5 s per process, more than a plain post of a typical part spends in these
functions (it pays back in placement, bulk API calls and a batch worker's life); and a last-digit
change in a joint moves some inverse-time feed words of a program in their last digits (rapids
by up to 2e-4 relatively), while the default route writes the very bytes it always wrote.

The loops do their twins' arithmetic (same formulas, same fixed iteration counts); where they
differ is said in each loop. Results agree to about 1e-12 mm and rad on usable poses
(tests/test_kernels.py). Units and frames are the numpy functions'.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from functools import lru_cache

import numpy as np

from .geometry import Geometry
from .tolerances import ROOT_PIECES
from .trigpoly import _vincent

#: Environment variable choosing the route: ``numba`` (where importable); anything else is numpy.
ROUTE_VARIABLE = "VERNE_POST_KERNELS"


def geometry_constants(geom: Geometry) -> tuple[float, ...]:
    """The geometry's lengths (mm) and limits the loops take, as a plain tuple of floats."""
    g = geom
    return (g.D1_minus_d1, g.D2_minus_d2, g.R1, g.r1, g.L1, g.R2, g.r4, g.L2, g.L3, g.delta, g.da, g.dt,
            g.alpha_max)


@lru_cache(maxsize=1)
def _numba_kernels() -> dict[str, Callable[..., object]] | None:
    """The compiled loops, or None where they are not asked for or numba is not installed."""
    if os.environ.get(ROUTE_VARIABLE, "numpy").strip().lower() != "numba":
        return None
    try:
        from . import _loops
    except ImportError:
        return None
    return _loops.LOOPS


def route() -> str:
    """``numba <version>`` or ``numpy``: the route the working-mode kinematics take in this process."""
    if _numba_kernels() is not None:
        return f"numba {_numba_version()}"
    asked = os.environ.get(ROUTE_VARIABLE, "").strip().lower() == "numba"
    return "numpy (VERNE_POST_KERNELS=numba asks for numba, which is not installed)" if asked else "numpy"


def _numba_version() -> str:
    from . import _loops

    return _loops.NUMBA_VERSION


def kernel(name: str) -> Callable[..., object] | None:
    """The compiled loop ``name``, or None on the numpy route."""
    kernels = _numba_kernels()
    return None if kernels is None else kernels[name]


def ik_working(geom: Geometry, tip: np.ndarray, axis: np.ndarray, pair: np.ndarray, theta2_at_pole: np.ndarray
               ) -> tuple[np.ndarray, ...] | None:
    """Compiled fast route of ``machine_ik_working`` (tips (N, 3) mm and axes (N, 3), table frame,
    true joints), or None on the numpy route; returns what its twin ``full._newton_route`` does."""
    loop = kernel("ik_working")
    if loop is None:
        return None
    n = len(tip)
    out = (np.empty((n, 5)), np.empty(n), np.empty((n, 2)), np.empty((n, 3)), np.empty((n, 4)), np.empty(n, bool),
           np.empty(n, bool))
    loop(geometry_constants(geom), np.ascontiguousarray(tip, dtype=float), np.ascontiguousarray(axis, dtype=float),
         np.ascontiguousarray(pair, dtype=np.int64), np.ascontiguousarray(theta2_at_pole, dtype=float), *out)
    return out


def margins(geom: Geometry, joints: np.ndarray, platform: np.ndarray, alpha: np.ndarray) -> np.ndarray | None:
    """Compiled ``jacobian.margins`` (true joints (N, 5) mm/rad, platform (N, 3) mm, alpha (N,)
    rad): (N, 4) serial, parallel, machine, rod clearance (mm); None on the numpy route."""
    loop = kernel("margins")
    if loop is None:
        return None
    out = np.empty((len(alpha), 4))
    loop(geometry_constants(geom), np.ascontiguousarray(joints, dtype=float),
         np.ascontiguousarray(platform, dtype=float), np.ascontiguousarray(alpha, dtype=float), out)
    return out


def fk_working(geom: Geometry, joints: np.ndarray, alpha_guess: np.ndarray | None) -> tuple[np.ndarray, ...] | None:
    """Compiled secant route of ``module_fk_working`` and ``tool_pose`` for true joints (N, 5) mm/rad,
    or true sliders (N, 3) mm without the tool pose: (platform (N, 3) mm, alpha (N,) rad, good (N,),
    tip (N, 3) mm, axis (N, 3), table frame), NaN where the secant route found no verified
    working assembly; None on the numpy route."""
    loop = kernel("fk_working")
    if loop is None:
        return None
    n = len(joints)
    poses = n if joints.shape[1] == 5 else 0
    out = (np.empty((n, 3)), np.empty(n), np.empty(n, bool), np.empty((poses, 3)), np.empty((poses, 3)))
    guess = np.zeros(n) if alpha_guess is None else np.ascontiguousarray(np.broadcast_to(alpha_guess, (n,)),
                                                                          dtype=float)
    loop(geometry_constants(geom), np.ascontiguousarray(joints, dtype=float), guess, alpha_guess is not None, *out)
    return out


def inverse_kinematics(geom: Geometry, lower: np.ndarray, upper: np.ndarray,
                       thresholds: tuple[float, float, float, float], tip: np.ndarray, axis: np.ndarray,
                       theta2_at_pole: np.ndarray, hint: np.ndarray, has_hint: bool) -> tuple[np.ndarray, ...] | None:
    """Compiled ``api.inverse_kinematics`` in one pass, or None on the numpy route. tip (N, 3) mm,
    unit axis (N, 3), table frame; joint bounds (5,) mm/rad; thresholds: serial, parallel,
    machine, rod clearance (mm); theta2 at the pole (N,) true rad and the hint (N,) as read, rad.
    Returns the chosen solutions' (joints (N, 5), alpha (N,), phi (N, 2), pair (N,) int8, status
    (N,) int8, margins (4, N), platform (N, 3)) and exact (N,): the poses left to the stepwise
    route (their rows not filled)."""
    loop = kernel("inverse_kinematics")
    if loop is None:
        return None
    n = len(tip)
    offsets = np.array((*geom.rho_offset, *geom.theta_offset), dtype=float)
    out = (np.empty((n, 5)), np.empty(n), np.empty((n, 2)), np.empty(n, np.int8), np.empty(n, np.int8),
           np.empty((4, n)), np.empty((n, 3)), np.empty(n, bool))
    loop(geometry_constants(geom), offsets, geom.has_offsets, np.asarray(lower, float), np.asarray(upper, float),
         np.array(thresholds, dtype=float), np.ascontiguousarray(tip, dtype=float),
         np.ascontiguousarray(axis, dtype=float), np.ascontiguousarray(theta2_at_pole, dtype=float),
         np.ascontiguousarray(hint, dtype=float), has_hint, _root_pieces(geom.alpha_max), *out)
    return out


@lru_cache(maxsize=8)
def _root_pieces(alpha_max: float) -> tuple[np.ndarray, ...]:
    """The pieces of (-alpha_max, alpha_max) (rad) in which the compiled certificate counts eq. 31's
    roots, as full._only_working_root cuts them: the edges (rad), their cos, sin and tan(edge / 2),
    and (pieces, 7, 7) Vincent's transform of a sextic onto each piece (cached: not to be written to)."""
    edges = np.linspace(-alpha_max, alpha_max, ROOT_PIECES + 1)
    t = np.tan(0.5 * edges)
    return (edges, np.cos(edges), np.sin(edges), t,
            np.stack([_vincent(6, float(t[j]), float(t[j + 1])) for j in range(ROOT_PIECES)]))


def settled(geom: Geometry, coefficients: np.ndarray, alpha: np.ndarray, joints: np.ndarray, candidates: np.ndarray
            ) -> np.ndarray | None:
    """Compiled test of ``full.machine_ik_working``'s candidates for the exact route: (N,) True
    where Newton's root alpha (rad) is surely eq. 31's only working root in (-alpha_max,
    alpha_max) and a leg does not reach there (no working solution); None on the numpy route.
    coefficients (N, 4) = (xP, A, B, X1^2) mm, mm^2; joints (N, 5) true mm, rad."""
    loop = kernel("settled")
    if loop is None:
        return None
    out = np.empty(len(alpha), bool)
    loop(geometry_constants(geom), coefficients, alpha, joints, candidates, _root_pieces(geom.alpha_max), out)
    return out
