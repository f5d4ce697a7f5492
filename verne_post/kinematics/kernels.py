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
