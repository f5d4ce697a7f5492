"""The compiled loops of the working-mode kinematics against the numpy route they replace.

Each function is called on the same inputs with VERNE_POST_KERNELS=numpy and with numba: the
numpy route is the reference that the independent tests (tests/test_kinematics_properties.py,
run on both routes) pin to the paper, the all-solutions route and brute-force scans. Inputs:
thousands of seeded random usable poses, the same poses moved far out of reach, poses on the
table normal (the pole), both angle pairs, a geometry with joint zero offsets and a tool, and
non-finite numbers.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import pytest

import verne_post as vp
from tests.conftest import random_usable_joints
from verne_post.kinematics import (
    kernels,
    machine_fk_working,
    machine_ik_working,
    margins,
    module_fk_working,
    wrap_angle,
)
from verne_post.options import PostOptions
from verne_post.pipeline import post

pytest.importorskip("numba")  # the test extra installs it

N = 5_000


def _both(monkeypatch: pytest.MonkeyPatch, function: Callable[..., object], *args: object, **kwargs: object
          ) -> tuple[object, object]:
    """``function(*args, **kwargs)`` on the numpy route, then on the numba route."""
    found = []
    for name in ("numpy", "numba"):
        monkeypatch.setenv(kernels.ROUTE_VARIABLE, name)
        kernels._numba_kernels.cache_clear()
        assert kernels.route().split()[0] == name
        found.append(function(*args, **kwargs))
    kernels._numba_kernels.cache_clear()
    return found[0], found[1]


def _geometries(machine: vp.Machine) -> list[vp.Geometry]:
    plain = machine.kinematic_geometry(0.0)
    offsets = replace(machine.kinematic_geometry(76.2), rho_offset=(0.7, -1.1, 0.4), theta_offset=(0.002, -0.003))
    return [plain, offsets]


def _assert_close(numpy_route: object, numba_route: object, usable: np.ndarray, mm: float = 1e-9) -> None:
    """Equal reach and NaN pattern everywhere; within ``mm`` (and rad) on the usable rows, 1e-6 on
    the other reachable ones (near a singularity a last-digit change is amplified)."""
    for field in fields(numpy_route):
        a, b = getattr(numpy_route, field.name), getattr(numba_route, field.name)
        if a.dtype == bool:
            assert np.array_equal(a, b), field.name
            continue
        assert np.array_equal(np.isnan(a), np.isnan(b)), field.name
        both = np.isfinite(a) & np.isfinite(b)
        error = np.where(both, np.abs(a - b), 0.0)
        error = error.reshape(len(usable), -1).max(axis=1)
        assert error[usable].max(initial=0.0) <= mm, field.name
        assert error.max(initial=0.0) <= 1e-6, field.name


def _poses(machine: vp.Machine, geom: vp.Geometry, seed: int) -> tuple[np.ndarray, ...]:
    """Tool poses (tip mm, axis, table frame), each one's angle pair and theta2 (rad), and which are
    usable: N usable ones, the same N moved 0-400 mm (most out of reach), and 200 on the pole."""
    rng = np.random.default_rng(seed)
    joints = random_usable_joints(machine, N, seed, geom.tool_length)
    fk = vp.forward_kinematics(machine, joints, tool_length=geom.tool_length)
    pair = np.where(wrap_angle(fk.alpha - joints[:, 3]) >= 0, 1, -1)
    pole_tip = fk.tip[:200] + rng.normal(0.0, 50.0, (200, 3))
    pole_axis = np.tile([0.0, 0.0, 1.0], (200, 1))
    tip = np.concatenate([fk.tip, fk.tip + rng.normal(0.0, 150.0, fk.tip.shape), pole_tip])
    axis = np.concatenate([fk.axis, fk.axis, pole_axis])
    pair = np.concatenate([pair, -pair, rng.choice([-1, 1], 200)])
    theta2 = np.concatenate([joints[:, 4], rng.uniform(-4.0, 4.0, N + 200)])
    usable = np.concatenate([np.ones(N, bool), np.zeros(N + 200, bool)])
    return tip, axis, pair, theta2, usable


def test_the_compiled_ik_gives_the_numpy_routes_joints(machine: vp.Machine, monkeypatch: pytest.MonkeyPatch
                                                       ) -> None:
    for seed, geom in enumerate(_geometries(machine)):
        tip, axis, pair, theta2, usable = _poses(machine, geom, seed + 11)
        for fallback in (True, False):
            numpy_route, numba_route = _both(monkeypatch, machine_ik_working, geom, tip, axis, pair=pair,
                                             theta2_at_pole=theta2, exact_fallback=fallback)
            assert numpy_route.reachable[usable].all()
            assert 0.2 < numpy_route.reachable[~usable].mean() < 0.9  # both kinds of pose are there
            _assert_close(numpy_route, numba_route, usable)


def test_the_compiled_margins_are_the_numpy_routes(machine: vp.Machine, monkeypatch: pytest.MonkeyPatch) -> None:
    for geom in _geometries(machine):
        joints = random_usable_joints(machine, N, 21, geom.tool_length)
        # readings (offsets subtracted) of the same platform poses: margins take readings
        fk = vp.forward_kinematics(machine, joints, tool_length=geom.tool_length)
        numpy_route, numba_route = _both(monkeypatch, margins, geom, joints, fk.platform, fk.alpha)
        _assert_close(numpy_route, numba_route, np.ones(N, bool), mm=1e-12)


def test_the_compiled_fk_gives_the_numpy_routes_poses(machine: vp.Machine, monkeypatch: pytest.MonkeyPatch
                                                      ) -> None:
    rng = np.random.default_rng(31)
    for geom in _geometries(machine):
        joints = random_usable_joints(machine, N, 32, geom.tool_length)
        far = joints + rng.normal(0.0, 300.0, joints.shape) * [1, 1, 1, 0.01, 0.01]
        every = np.concatenate([joints, far])
        usable = np.arange(len(every)) < N
        exact = machine_fk_working(geom, every)
        guesses = (None, exact.alpha + rng.normal(0.0, 1e-3, len(every)),  # warm, as along a path
                   np.where(rng.random(len(every)) < 0.1, np.nan, 0.05), np.full(len(every), np.inf))
        for guess in guesses:
            numpy_route, numba_route = _both(monkeypatch, machine_fk_working, geom, every, guess)
            assert numpy_route.reachable[usable].all()
            assert (~numpy_route.reachable).mean() > 0.02  # poses without an assembly are there
            _assert_close(numpy_route, numba_route, usable)
            numpy_route, numba_route = _both(monkeypatch, module_fk_working, geom, every[:, :3], guess)
            _assert_close(numpy_route, numba_route, usable)


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")  # the numpy route on NaN and inf
def test_non_finite_poses_and_joints_are_unreachable_on_both_routes(machine: vp.Machine,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    geom = machine.kinematic_geometry(0.0)
    tip = np.array([[np.nan, 0.0, -100.0], [0.0, np.inf, -100.0], [0.0, 0.0, -100.0], [0.0, 0.0, -100.0]])
    axis = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [np.nan, 0.0, 1.0], [0.0, -np.inf, 1.0]])
    for found in _both(monkeypatch, machine_ik_working, geom, tip, axis):
        assert not found.reachable.any()
        assert np.isnan(found.joints).all()
    joints = np.array([[np.nan, 600.0, 600.0, 0.0, 0.0], [600.0, np.inf, 600.0, 0.0, 0.0],
                       [600.0, 600.0, 600.0, np.nan, 0.0]])
    numpy_route, numba_route = _both(monkeypatch, machine_fk_working, geom, joints)
    assert np.array_equal(numpy_route.reachable, numba_route.reachable)
    assert not numba_route.reachable[:2].any()
    assert np.isnan(numba_route.tip[2]).all() and np.isnan(numpy_route.tip[2]).all()


def test_a_program_posted_on_the_compiled_route_has_the_same_axis_words(machine: vp.Machine, tmp_path: Path,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """The swarf example posted and verified on both routes: every block's X Y Z A C words are the
    same; the inverse-time feed words may move where a joint's last digit moves a planned time."""
    example = Path(__file__).parent.parent / "examples" / "nx_swarf_inch_crlf.cls"
    texts = []
    for name in ("numpy", "numba"):
        monkeypatch.setenv(kernels.ROUTE_VARIABLE, name)
        kernels._numba_kernels.cache_clear()
        output = tmp_path / f"{name}.nc"
        posted = post(example, machine, PostOptions(workers=1), output)
        assert not posted.violations and posted.verification is not None and posted.verification.ok
        texts.append(output.read_text().splitlines())
    kernels._numba_kernels.cache_clear()
    numpy_lines, numba_lines = texts
    assert len(numpy_lines) == len(numba_lines)
    feed = re.compile(r" F([0-9.]+)")
    moved = 0
    for a, b in zip(numpy_lines, numba_lines, strict=True):
        assert feed.sub("", a) == feed.sub("", b)
        fa, fb = feed.search(a), feed.search(b)
        if fa and fb and fa.group(1) != fb.group(1):
            moved += 1
            assert abs(float(fa.group(1)) / float(fb.group(1)) - 1.0) <= 1e-3
    assert moved <= len(numpy_lines) // 50


def test_the_compiled_atan2_is_within_two_ulp_of_libm() -> None:
    """The IK loop's atan2 (no libm call, so its loop runs in SIMD lanes) against libm's (numpy's
    arctan2), on 200,000 pairs over 20 decades of ratio, every quadrant and signed zeros; the
    pole's (0, 0), which it leaves to libm, gives NaN."""
    from verne_post.kinematics._loops import _atan2

    rng = np.random.default_rng(41)
    y = rng.normal(size=200_000) * 10.0 ** rng.uniform(-10, 10, 200_000)
    x = rng.normal(size=200_000) * 10.0 ** rng.uniform(-10, 10, 200_000)
    y[:500], x[500:1000], y[1000:1500] = 0.0, 0.0, -0.0
    x[1500:2000] = -y[1500:2000]  # on the diagonals, where the reduction switches
    found = np.array([_atan2(a, b) for a, b in zip(y.tolist(), x.tolist(), strict=True)])
    expected = np.arctan2(y, x)
    assert np.all(np.abs(found - expected) <= 2 * np.spacing(np.abs(expected)))
    assert np.array_equal(np.signbit(found), np.signbit(expected))
    assert np.isnan(_atan2(0.0, 0.0))


def test_the_compiled_root_certificate_settles_the_poses_the_numpy_one_does(machine: vp.Machine,
                                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """The compiled test of the IK's candidates for the exact route (kernels.settled) against the
    numpy route's (the residual test and full._only_working_root, which
    tests/test_kinematics_properties.py checks against every root): the same poses settled, on
    both pairs of poses mostly moved out of reach."""
    from verne_post.kinematics import full

    monkeypatch.setenv(kernels.ROUTE_VARIABLE, "numba")
    kernels._numba_kernels.cache_clear()
    try:
        for seed, geom in enumerate(_geometries(machine)):
            tip, axis, pair, theta2, _ = _poses(machine, geom, seed + 51)
            for flip in (1, -1):
                joints, alpha, _, _, coefficients, _, candidates = kernels.ik_working(geom, tip, axis, flip * pair,
                                                                                      theta2)
                settled = kernels.settled(geom, coefficients, alpha, joints, candidates)
                rows = np.flatnonzero(candidates)
                _, a, b, x1sq = coefficients[rows].T
                residual, yg = full._signed_coupling(geom, a, b, x1sq, alpha[rows])
                root = ((np.abs(residual) <= 1e-9 * (np.abs(yg) + geom.R1)) & (np.abs(alpha[rows]) < geom.alpha_max)
                        & ~np.all(np.isfinite(joints[rows, :3]), axis=-1))
                expected = np.zeros(len(tip), bool)
                expected[rows[root]] = full._only_working_root(geom, a[root], b[root], x1sq[root], alpha[rows][root])
                assert expected.sum() > 500  # the kind of pose the certificate is for is there
                assert np.array_equal(settled, expected)
    finally:
        kernels._numba_kernels.cache_clear()


@pytest.mark.parametrize("offsets", [False, True])
def test_the_compiled_inverse_kinematics_makes_the_numpy_routes_choice(machine: vp.Machine, offsets: bool,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """api.inverse_kinematics on the compiled route (both pairs, then one loop a pose for the
    statuses, margins and the choice) against the numpy route: the same pair and status at every
    pose, joints within 1e-9 mm and rad where usable, margins to 1e-9; without a theta2 hint, with
    one and with one a pose; usable poses, poses moved far out of reach and poses on the pole;
    with a tool and with joint zero offsets."""
    if offsets:
        zeros = {name: getattr(machine.joints, name).model_copy(update={"offset": offset}) for name, offset in
                 (("rho1", 0.7), ("rho2", -1.3), ("rho3", 0.4), ("theta1", 0.3), ("theta2", -2.0))}
        machine = machine.model_copy(update={"joints": machine.joints.model_copy(update=zeros)})
    tool = 76.2 if offsets else 0.0
    geom = machine.kinematic_geometry(tool)
    tip, axis, _, theta2, usable = _poses(machine, geom, 61 + offsets)
    for hint in (None, 0.4, theta2 + np.random.default_rng(62).normal(0.0, 1.0, len(theta2))):
        numpy_route, numba_route = _both(monkeypatch, vp.inverse_kinematics, machine, tip, axis, hint,
                                         tool_length=tool)
        assert np.array_equal(numpy_route.status, numba_route.status)
        assert np.array_equal(numpy_route.pair, numba_route.pair)
        assert numba_route.status.dtype == numpy_route.status.dtype and numba_route.pair.dtype == np.int8
        assert len(set(numpy_route.status.tolist())) == 4  # ok, unreachable, beyond limits, singular all there
        for name in ("joints", "alpha", "phi", "platform"):
            a, b = getattr(numpy_route, name), getattr(numba_route, name)
            assert np.array_equal(np.isnan(a), np.isnan(b)), name
            assert np.nanmax(np.abs(a - b)[usable]) <= 1e-9, name
        for a, b in zip(fields(numpy_route.margins), fields(numba_route.margins), strict=True):
            x, y = getattr(numpy_route.margins, a.name), getattr(numba_route.margins, b.name)
            assert np.array_equal(np.isnan(x), np.isnan(y)), a.name
            assert np.nanmax(np.abs(x - y)) <= 1e-9, a.name
