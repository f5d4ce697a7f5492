"""Kinematics against independent routes over thousands of random poses (seeded numpy), on each
route of the working-mode kinematics (compiled loops and numpy)."""

from __future__ import annotations

import numpy as np
import pytest

import verne_post as vp
from tests.conftest import random_usable_joints
from tests.independent import coupling, platform_from_tool, rod_residuals
from verne_post.kinematics import (
    machine_fk_all,
    machine_ik_all,
    machine_ik_working,
    module_fk_all,
    module_fk_working,
    module_ik_all,
    module_ik_working,
    wrap_angle,
)

N_ROUND_TRIP = 10_000

pytestmark = pytest.mark.usefixtures("kinematics_route")


def _pair_of(alpha: np.ndarray, theta1: np.ndarray) -> np.ndarray:
    return np.where(alpha - theta1 >= 0, 1, -1)


def _joint_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    err = np.abs(a - b)
    err[:, 3:] = np.abs(wrap_angle(a[:, 3:] - b[:, 3:]))
    return err


def test_fk_then_ik_returns_the_joints(machine: vp.Machine) -> None:
    for tool_length, seed in ((0.0, 1), (76.2, 2)):
        joints = random_usable_joints(machine, N_ROUND_TRIP, seed, tool_length)
        fk = vp.forward_kinematics(machine, joints, tool_length=tool_length)
        geom = machine.kinematic_geometry(tool_length)
        ik = machine_ik_working(geom, fk.tip, fk.axis, pair=_pair_of(fk.alpha, joints[:, 3]),
                                theta2_at_pole=joints[:, 4])
        assert ik.reachable.all()
        assert _joint_error(ik.joints, joints).max() <= 1e-9


def test_ik_then_fk_returns_the_pose(machine: vp.Machine) -> None:
    joints = random_usable_joints(machine, N_ROUND_TRIP, 3, 50.0)
    poses = vp.forward_kinematics(machine, joints, tool_length=50.0)
    ik = vp.inverse_kinematics(machine, poses.tip, poses.axis, tool_length=50.0)
    assert np.all(ik.status == vp.Status.OK)
    back = vp.forward_kinematics(machine, ik.joints, tool_length=50.0)
    assert np.abs(back.tip - poses.tip).max() <= 1e-9
    angle = 2 * np.arcsin(np.linalg.norm(back.axis - poses.axis, axis=1) / 2)
    assert angle.max() <= 1e-9


def test_ik_satisfies_independent_model(machine: vp.Machine) -> None:
    """Joints from the IK close every rod of the machine built from the Table IV chain."""
    joints = random_usable_joints(machine, N_ROUND_TRIP, 4, 20.0)
    poses = vp.forward_kinematics(machine, joints, tool_length=20.0)
    ik = vp.inverse_kinematics(machine, poses.tip, poses.axis, tool_length=20.0)
    geom = machine.kinematic_geometry(20.0)
    platform, alpha = platform_from_tool(geom, poses.tip, poses.axis, ik.joints[:, 3], ik.joints[:, 4])
    np.testing.assert_allclose(alpha, ik.alpha, atol=1e-9)
    assert np.abs(rod_residuals(geom, platform, alpha, ik.joints[:, :3])).max() <= 1e-9 * geom.L1**2
    # ... and the machine's mode: sliders above their platform points, rods of leg I apart.
    assert np.all(ik.joints[:, 0] < platform[:, 2])
    assert np.all(geom.R1 * np.cos(alpha) > geom.r1)


def test_module_round_trip(machine: vp.Machine) -> None:
    """Platform position -> sliders -> platform position, where the working mode is unique.

    At the fringe of leg I's reach (|alpha| > ~0.45, leg I nearly horizontal) a platform
    position can have two working-mode solutions; the fast path returns the smaller |alpha|
    there, checked in test_fast_paths_agree_with_all_solutions.
    """
    geom = machine.kinematic_geometry()
    rng = np.random.default_rng(5)
    platform = np.column_stack([rng.uniform(-500, 600, 40_000), rng.uniform(-550, 550, 40_000),
                                rng.uniform(800, 2100, 40_000)])
    ik = module_ik_working(geom, platform)
    keep = ik.reachable & np.all((ik.rho > 0) & (ik.rho < 1300), axis=1)
    keep &= geom.R1 * np.cos(ik.alpha) - geom.r1 > 10.0
    everything = module_ik_all(geom, platform[keep])
    unique = np.bincount(everything.pose_index[everything.working_mode], minlength=int(keep.sum())) == 1
    platform, rho, alpha = platform[keep][unique], ik.rho[keep][unique], ik.alpha[keep][unique]
    assert len(platform) >= N_ROUND_TRIP
    fk = module_fk_working(geom, rho)
    assert fk.reachable.all()
    assert np.abs(fk.platform - platform).max() <= 1e-9
    assert np.abs(fk.alpha - alpha).max() <= 1e-9
    back = module_ik_working(geom, fk.platform)
    assert np.abs(back.rho - rho).max() <= 1e-9
    assert np.abs(rod_residuals(geom, platform, alpha, rho)).max() <= 1e-9 * geom.L1**2


def test_warm_started_fk_agrees_with_all_solutions(machine: vp.Machine) -> None:
    """With a guess of alpha (as along a path: the neighbours' alpha, or a poor one), the working
    FK lands on the all-solutions route's working assembly; each pose stops iterating on its own."""
    geom = machine.kinematic_geometry(30.0)
    joints = random_usable_joints(machine, 4_000, 11, 30.0)
    everything = module_fk_all(geom, joints[:, :3])
    working = everything.working_mode
    assert np.array_equal(np.bincount(everything.pose_index[working], minlength=len(joints)), np.ones(len(joints)))
    order = np.argsort(everything.pose_index[working])
    alpha, platform = everything.alpha[working][order], everything.platform[working][order]
    rng = np.random.default_rng(12)
    for spread in (1e-9, 1e-4, 1e-2, 0.1):  # rad, off the true alpha
        fast = module_fk_working(geom, joints[:, :3], alpha_guess=alpha + rng.normal(0.0, spread, len(alpha)))
        assert fast.reachable.all()
        np.testing.assert_allclose(fast.platform, platform, atol=1e-8)
        np.testing.assert_allclose(fast.alpha, alpha, atol=1e-11)


def test_fast_paths_agree_with_all_solutions(machine: vp.Machine) -> None:
    geom = machine.kinematic_geometry(30.0)
    joints = random_usable_joints(machine, 2_000, 6, 30.0)
    # module FK
    everything = module_fk_all(geom, joints[:, :3])
    working = everything.working_mode
    assert np.array_equal(np.bincount(everything.pose_index[working], minlength=len(joints)), np.ones(len(joints)))
    fast = module_fk_working(geom, joints[:, :3])
    np.testing.assert_allclose(everything.platform[working], fast.platform, atol=1e-8)
    # module IK
    ik_all = module_ik_all(geom, fast.platform)
    fast_ik = module_ik_working(geom, fast.platform)
    working = ik_all.working_mode
    order = np.lexsort((np.abs(ik_all.alpha[working]), ik_all.pose_index[working]))
    index, first = np.unique(ik_all.pose_index[working][order], return_index=True)
    assert np.array_equal(index, np.arange(len(joints)))
    np.testing.assert_allclose(ik_all.rho[working][order][first], fast_ik.rho, atol=1e-8)
    # machine IK, both pairs
    fk = vp.forward_kinematics(machine, joints, tool_length=30.0)
    solutions = machine_ik_all(geom, fk.tip, fk.axis, theta2_at_pole=joints[:, 4])
    for pair in (1, -1):
        fast_ik = machine_ik_working(geom, fk.tip, fk.axis, pair=pair, theta2_at_pole=joints[:, 4])
        chosen = solutions.working_mode & (solutions.pair == pair)
        index = solutions.pose_index[chosen]
        assert np.array_equal(np.sort(index), np.flatnonzero(fast_ik.reachable))
        err = _joint_error(solutions.joints[chosen], fast_ik.joints[index])
        assert err.max() <= 1e-8


def test_every_root_closes(machine: vp.Machine) -> None:
    """All solutions of all three polynomial routes satisfy eq. 2 to 1e-9 relative."""
    geom = machine.kinematic_geometry(40.0)
    rng = np.random.default_rng(7)
    scale = 1e-9 * geom.L1**2
    platform = np.column_stack([rng.uniform(-700, 700, 3000), rng.uniform(-700, 700, 3000),
                                rng.uniform(300, 2400, 3000)])
    sol = module_ik_all(geom, platform)
    assert len(sol.alpha) > 3000
    assert np.abs(rod_residuals(geom, platform[sol.pose_index], sol.alpha, sol.rho)).max() <= scale
    rho = rng.uniform(-200, 1500, (3000, 3))
    fk = module_fk_all(geom, rho)
    assert len(fk.alpha) > 3000
    assert np.abs(rod_residuals(geom, fk.platform, fk.alpha, rho[fk.pose_index])).max() <= scale
    joints = np.column_stack([rng.uniform(0, 1300, (3000, 3)), rng.uniform(-1.5, 1.5, 3000),
                              rng.uniform(-3, 3, 3000)])
    poses = machine_fk_all(geom, joints)
    mfk = poses.pose_index
    tip, axis = poses.tip, poses.axis
    ik = machine_ik_all(geom, tip, axis)
    assert len(ik.alpha) > len(tip)
    p, a = platform_from_tool(geom, tip[ik.pose_index], axis[ik.pose_index], ik.joints[:, 3], ik.joints[:, 4])
    assert np.abs(rod_residuals(geom, p, a, ik.joints[:, :3])).max() <= scale
    # Every FK assembly mode is found again among the IK solutions of its tool pose.
    for k in range(0, len(tip), 97):
        same = ik.pose_index == k
        assert np.min(np.max(np.abs(ik.joints[same, :3] - joints[mfk[k], :3]), axis=1)) <= 1e-6


def _legs_close(geom: vp.Geometry, platform: np.ndarray, alpha: float) -> bool:
    """Every leg can reach the platform at this alpha (radicands of eq. 10-12 clearly positive)."""
    x1, x2, y = platform[0] + geom.D1_minus_d1, platform[0] + geom.D2_minus_d2, platform[1]
    c = np.cos(alpha)
    return bool(geom.L1**2 - geom.R1**2 - geom.r1**2 + 2 * geom.R1 * geom.r1 * c - x1**2 - y**2 > 1
                and geom.L2**2 - x2**2 - (y - geom.R2 * c + geom.r4) ** 2 > 1
                and geom.L3**2 - x2**2 - (y + geom.R2 * c - geom.r4) ** 2 > 1)


def _scan_roots(values: np.ndarray, grid: np.ndarray) -> list[np.ndarray]:
    """Grid points just before a sign change, per row (finite values only)."""
    sign = np.sign(values)
    change = (sign[:, :-1] * sign[:, 1:] < 0) & np.isfinite(values[:, :-1]) & np.isfinite(values[:, 1:])
    return [grid[np.flatnonzero(row)] for row in change]


def test_brute_force_scan_finds_no_missed_root(machine: vp.Machine) -> None:
    geom = machine.kinematic_geometry()
    rng = np.random.default_rng(8)
    grid = np.linspace(-np.pi, np.pi, 40_001)
    step = grid[1] - grid[0]
    # Module IK: roots of eq. 6 in alpha where every leg closes.
    platform = np.column_stack([rng.uniform(-600, 600, 150), rng.uniform(-500, 500, 150), rng.uniform(600, 2200, 150)])
    values = coupling(geom, platform[:, None, :], grid[None, :])
    solutions = module_ik_all(geom, platform)
    for k, roots in enumerate(_scan_roots(values, grid)):
        found = solutions.alpha[solutions.pose_index == k]
        for root in roots:
            if _legs_close(geom, platform[k], root):
                assert np.min(np.abs(wrap_angle(found - root))) <= 2 * step
    # Module FK: for each alpha the three sphere equations (eq. 9, 4, 5) meet in two points;
    # eq. 13 must vanish at a solution. Scan both points over alpha.
    rho = rng.uniform(0, 1300, (150, 3))
    solutions = module_fk_all(geom, rho)
    for branch in (1.0, -1.0):
        values = np.stack([_eq13_on_sphere_branch(geom, r, grid, branch) for r in rho])
        for k, roots in enumerate(_scan_roots(values, grid)):
            found = solutions.alpha[solutions.pose_index == k]
            for root in roots:
                assert found.size and np.min(np.abs(wrap_angle(found - root))) <= 2 * step


def _eq13_on_sphere_branch(geom: vp.Geometry, rho: np.ndarray, alpha: np.ndarray, branch: float) -> np.ndarray:
    c, s = np.cos(alpha), np.sin(alpha)
    centres = np.stack([
        np.stack([np.full_like(c, -geom.D1_minus_d1), 0 * c, np.full_like(c, rho[0])], -1),
        np.stack([np.full_like(c, -geom.D2_minus_d2), geom.R2 * c - geom.r4, rho[1] + geom.R2 * s], -1),
        np.stack([np.full_like(c, -geom.D2_minus_d2), geom.r4 - geom.R2 * c, rho[2] - geom.R2 * s], -1),
    ], 1)
    radii2 = np.stack([geom.L1**2 - geom.R1**2 - geom.r1**2 + 2 * geom.R1 * geom.r1 * c,
                       np.full_like(c, geom.L2**2), np.full_like(c, geom.L3**2)], -1)
    u, v = centres[:, 1] - centres[:, 0], centres[:, 2] - centres[:, 0]
    normal = np.cross(u, v)
    # Solve p.u = b2, p.v = b3 in the plane, then the height along the normal.
    b2 = 0.5 * (radii2[:, 0] - radii2[:, 1] + np.sum(u * u, -1))
    b3 = 0.5 * (radii2[:, 0] - radii2[:, 2] + np.sum(v * v, -1))
    gram = np.stack([np.stack([np.sum(u * u, -1), np.sum(u * v, -1)], -1),
                     np.stack([np.sum(u * v, -1), np.sum(v * v, -1)], -1)], -2)
    lam = np.linalg.solve(gram, np.stack([b2, b3], -1)[..., None])[..., 0]
    p = lam[:, :1] * u + lam[:, 1:] * v
    with np.errstate(invalid="ignore"):
        height = np.sqrt((radii2[:, 0] - np.sum(p * p, -1)) / np.sum(normal * normal, -1))
    point = centres[:, 0] + p + branch * height[:, None] * normal
    return point[:, 1] * (geom.R1 * c - geom.r1) - geom.R1 * s * (rho[0] - point[:, 2])


def test_machine_ik_scan(machine: vp.Machine) -> None:
    """Roots of eq. 31 (in alpha) found by a scan of the independent model are all found."""
    geom = machine.kinematic_geometry()
    joints = random_usable_joints(machine, 150, 9)
    fk = vp.forward_kinematics(machine, joints)
    solutions = machine_ik_all(geom, fk.tip, fk.axis)
    grid = np.linspace(-np.pi, np.pi, 40_001)
    step = grid[1] - grid[0]
    for pair in (1, -1):
        phi1 = pair * np.arccos(np.clip(fk.axis[:, 2], -1, 1))
        for k in range(len(joints)):
            theta2 = -np.arctan2(fk.axis[k, 0], -fk.axis[k, 1]) - (np.pi if pair < 0 else 0.0)
            theta1 = grid - phi1[k]
            platform, alpha = platform_from_tool(geom, np.repeat(fk.tip[k:k + 1], grid.size, 0),
                                                 np.repeat(fk.axis[k:k + 1], grid.size, 0), theta1,
                                                 np.full(grid.size, theta2))
            values = coupling(geom, platform, alpha)
            found = solutions.alpha[(solutions.pose_index == k) & (solutions.pair == pair)]
            for root in _scan_roots(values[None], grid)[0]:
                if _legs_close(geom, platform[np.searchsorted(grid, root)], root):
                    assert found.size and np.min(np.abs(wrap_angle(found - root))) <= 2 * step


def test_degenerate_rho2_equals_rho3(machine: vp.Machine) -> None:
    """Eq. 23 with rho2 = rho3 on a symmetric machine (L2 = L3): solved, not a crash."""
    geom = machine.kinematic_geometry().__class__(**{**machine.geometry.model_dump(), "L3": machine.geometry.L2})
    rho = np.array([[600.0, 700.0, 700.0], [500.0, 650.0, 650.0]])
    sol = module_fk_all(geom, rho)
    assert sol.working_mode.sum() == 2
    assert np.abs(rod_residuals(geom, sol.platform, sol.alpha, rho[sol.pose_index])).max() <= 1e-9 * geom.L1**2
    working = sol.working_mode
    np.testing.assert_allclose(sol.alpha[working], 0.0, atol=1e-12)
    np.testing.assert_allclose(sol.platform[working, 1], 0.0, atol=1e-9)
    fast = module_fk_working(geom, rho)
    np.testing.assert_allclose(fast.platform, sol.platform[working], atol=1e-8)


def test_pole_takes_theta2_from_the_hint(machine: vp.Machine) -> None:
    tip = np.array([[10.0, 20.0, 30.0]])
    axis = np.array([[0.0, 0.0, 1.0]])
    for hint in (0.0, 1.0, -2.5, 7.0):
        ik = vp.inverse_kinematics(machine, tip, axis, theta2_hint=hint)
        assert ik.joints[0, 4] == hint
        fk = vp.forward_kinematics(machine, ik.joints)
        np.testing.assert_allclose(fk.tip, tip, atol=1e-9)
        np.testing.assert_allclose(fk.axis, axis, atol=1e-12)


def test_a_theta2_hint_a_pose_chooses_as_that_pose_alone_with_its_hint(machine: vp.Machine) -> None:
    """inverse_kinematics with one theta2 hint a pose (rad) gives, pose by pose, what a call with
    that pose and its hint alone gives: among them poses whose first choice is singular and whose
    other pair is ok (the choice looks again there, with those poses' hints)."""
    rng = np.random.default_rng(71)
    joints = np.array([0.0, 0.0, 0.0, -np.pi / 2, -np.pi]) + rng.random((40_000, 5)) * [1300, 1300, 1300, np.pi,
                                                                                         2 * np.pi]
    fk = vp.forward_kinematics(machine, joints)
    tip, axis = fk.tip[fk.reachable], fk.axis[fk.reachable]
    plus, minus = vp.inverse_kinematics_pairs(machine, tip, axis)
    second_look = np.flatnonzero(((plus.status == vp.Status.SINGULAR) & (minus.status == vp.Status.OK))
                                 | ((minus.status == vp.Status.SINGULAR) & (plus.status == vp.Status.OK)))
    assert second_look.size >= 20
    rows = np.concatenate([second_look[:60], rng.choice(len(tip), 60, replace=False)])
    hints = rng.uniform(-7.0, 7.0, len(rows))
    together = vp.inverse_kinematics(machine, tip[rows], axis[rows], hints)
    for k, row in enumerate(rows):
        alone = vp.inverse_kinematics(machine, tip[row:row + 1], axis[row:row + 1], float(hints[k]))
        assert alone.status[0] == together.status[k] and alone.pair[0] == together.pair[k]
        np.testing.assert_array_equal(alone.joints[0], together.joints[k])


def test_the_working_mode_ik_finds_every_pose_the_all_solutions_route_solves(machine: vp.Machine) -> None:
    """Tool poses over a box wider than the VERNE's reach, tilted up to 100 degrees, both angle
    pairs: the working-mode IK (Newton, then the all-solutions route unless eq. 31 has surely no
    other root, see full._only_working_root) reaches exactly the poses where the all-solutions
    route (every root of the sextic) has a working-mode solution of that pair, at the same joints."""
    rng = np.random.default_rng(12)
    n = 20_000
    for length in (0.0, 100.0):
        geom = machine.kinematic_geometry(length)
        tip = rng.uniform([-700.0, -700.0, -300.0], [700.0, 700.0, 700.0], size=(n, 3))
        tilt, turn = rng.uniform(0.0, np.radians(100.0), n), rng.uniform(-np.pi, np.pi, n)
        axis = np.column_stack([np.sin(tilt) * np.cos(turn), np.sin(tilt) * np.sin(turn), np.cos(tilt)])
        solutions = machine_ik_all(geom, tip, axis)
        reached = 0
        for pair in (1, -1):
            fast = machine_ik_working(geom, tip, axis, pair=pair)
            chosen = solutions.working_mode & (solutions.pair == pair)
            order = np.lexsort((np.abs(solutions.alpha[chosen]), solutions.pose_index[chosen]))
            index, first = np.unique(solutions.pose_index[chosen][order], return_index=True)
            assert np.array_equal(index, np.flatnonzero(fast.reachable))
            assert _joint_error(solutions.joints[chosen][order][first], fast.joints[index]).max() <= 1e-8
            reached += index.size
        # both kinds are many: poses in reach and out of it
        assert 0.1 * n < reached < 1.9 * n, reached


def test_roots_are_counted_in_an_interval_as_every_root_of_the_polynomial_says() -> None:
    """roots_within against numpy's roots of 20,000 random sextics on random intervals: where it
    says 0 or 1, that is how many real roots lie inside; it is sure on most."""
    from verne_post.kinematics.trigpoly import roots_within
    rng = np.random.default_rng(3)
    num = rng.normal(size=(20_000, 7)) * rng.uniform(0.1, 10.0, size=(20_000, 1))
    sure = 0
    for lo, hi in ((-0.4, 0.4), (-0.4, -0.1), (0.0, 0.25), (0.1, 0.9)):
        counted = roots_within(num, lo, hi)
        for row in np.flatnonzero(counted >= 0)[:3000]:
            roots = np.roots(num[row, ::-1])
            real = roots[np.abs(roots.imag) <= 1e-9].real
            assert np.count_nonzero((real > lo) & (real < hi)) == counted[row], (row, lo, hi, real)
        sure += int(np.count_nonzero(counted >= 0))
    assert sure > 0.5 * 4 * len(num), sure


def test_a_root_of_eq_31_is_called_the_only_one_only_where_numpy_finds_no_other(machine: vp.Machine) -> None:
    """full._only_working_root against every root of the sextic by numpy's eigenvalues, on random
    platform coefficients: where it says a root of the signed eq. 31 is the only one in
    (-alpha_max, alpha_max), no other root there makes the signed form vanish; where there is
    another, it says so; it is sure on most rows with one root."""
    from verne_post.kinematics.full import _coupling, _only_working_root
    from verne_post.kinematics.trigpoly import TrigPoly
    g = machine.kinematic_geometry(0.0)
    k, two_rr = g.L1**2 - g.R1**2 - g.r1**2, 2.0 * g.R1 * g.r1
    rng = np.random.default_rng(4)
    n = 4_000
    a, b = rng.uniform(-400.0, 400.0, n), rng.uniform(-900.0, 900.0, n)
    x1sq = rng.uniform(0.0, 1.05 * (k + two_rr), n)

    def signed(alpha: np.ndarray, rows: np.ndarray) -> np.ndarray:
        c, s = np.cos(alpha), np.sin(alpha)
        with np.errstate(invalid="ignore"):
            return ((a[rows] * c + b[rows] * s) * np.sqrt(g.R1**2 + g.r1**2 - two_rr * c)
                    + g.R1 * s * np.sqrt(k + two_rr * c - x1sq[rows]))

    num = _coupling(g, np.sqrt(x1sq), a, b, *TrigPoly.cos_sin(n)).num
    rows, roots, others = [], [], []
    for row in range(n):
        found = np.roots(num[row, ::-1])
        alpha = 2.0 * np.arctan(found[np.abs(found.imag) <= 1e-9].real)
        alpha = alpha[np.abs(alpha) < g.alpha_max]
        f = np.abs(signed(alpha, np.full(len(alpha), row)))
        scale = np.abs(a[row]) + np.abs(b[row]) + g.R1
        working = alpha[f <= 1e-6 * scale * g.R1]
        if working.size:
            rows.append(row)
            roots.append(working[0])
            others.append(working.size > 1)
    rows, roots, others = np.array(rows), np.array(roots), np.array(others)
    only = _only_working_root(g, a[rows], b[rows], x1sq[rows], roots)
    assert not np.any(only & others)
    assert others.sum() > 20 and only.sum() > 0.5 * (~others).sum(), (others.sum(), only.sum(), (~others).sum())
