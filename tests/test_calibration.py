"""Joint zero offsets and kinematic calibration (``verne-post calibrate``).

Measurements are made with the project's forward kinematics of a machine whose geometry and
slider zeros are perturbed by known amounts, plus seeded Gaussian noise; the expected values
are those perturbations, never numbers produced by the calibration under test.
"""

from __future__ import annotations

import numpy as np
import pytest

import verne_post as vp
from tests.conftest import random_usable_joints
from tests.independent import platform_from_tool, rod_residuals
from verne_post.kinematics import machine_ik_all, module_fk_working, module_ik_working, wrap_angle

#: Joint zero offsets used below: rho mm, theta degrees (large enough to matter, small enough
#: to keep the random poses usable).
OFFSETS_MM = (0.12, -0.08, 0.15)
OFFSETS_DEG = (0.03, -0.05)


def with_offsets(machine: vp.Machine, rho: tuple[float, float, float] = OFFSETS_MM,
                 theta: tuple[float, float] = OFFSETS_DEG) -> vp.Machine:
    """``machine`` with joint offsets (mm, degrees), through the validated model."""
    data = machine.model_dump()
    for name, value in zip(("rho1", "rho2", "rho3", "theta1", "theta2"), (*rho, *theta), strict=True):
        data["joints"][name]["offset"] = value
    return vp.Machine.model_validate(data)


def test_offsets_reach_the_kinematic_geometry(machine: vp.Machine) -> None:
    geom = with_offsets(machine).kinematic_geometry(60.0)
    assert geom.rho_offset == OFFSETS_MM
    assert geom.theta_offset == pytest.approx(np.radians(OFFSETS_DEG))
    assert not machine.kinematic_geometry().has_offsets


def test_fk_with_offsets_is_the_true_joints_fk(machine: vp.Machine) -> None:
    """FK of readings = the independent model at reading + offset (true slider heights and angles)."""
    shifted = with_offsets(machine)
    readings = random_usable_joints(machine, 3000, seed=11, tool_length=60.0)
    fk = vp.forward_kinematics(shifted, readings, tool_length=60.0)
    assert fk.reachable.all()
    true = readings + np.array([*OFFSETS_MM, *np.radians(OFFSETS_DEG)])
    geom = machine.kinematic_geometry(60.0)
    platform, alpha = platform_from_tool(geom, fk.tip, fk.axis, true[:, 3], true[:, 4])
    np.testing.assert_allclose(platform, fk.platform, atol=1e-7)
    residual = rod_residuals(geom, platform, alpha, true[:, :3])
    assert np.max(np.abs(residual)) < 1e-5  # mm^2 on L^2 ~ 1e6 mm^2
    # and the readings themselves, taken as true, do not close the rods: the offsets are applied
    assert np.max(np.abs(rod_residuals(geom, platform, alpha, readings[:, :3]))) > 10.0


def test_ik_fk_round_trip_with_offsets(machine: vp.Machine) -> None:
    shifted = with_offsets(machine)
    for tool_length, seed in ((0.0, 21), (100.0, 22)):
        readings = random_usable_joints(machine, 4000, seed=seed, tool_length=tool_length)
        fk = vp.forward_kinematics(shifted, readings, tool_length=tool_length)
        ik = vp.inverse_kinematics(shifted, fk.tip, fk.axis, theta2_hint=readings[:, 4], tool_length=tool_length)
        ok = ik.status == vp.Status.OK
        assert ok.mean() > 0.97  # the offsets move a few poses over a margin, no more
        error = np.abs(ik.joints - readings)[ok]
        error[:, 3:] = np.abs(wrap_angle(ik.joints[ok, 3:] - readings[ok, 3:]))
        assert error[:, :3].max() < 1e-6 and error[:, 3:].max() < 1e-9
        # without the offsets the same tool poses give joints off by the offsets
        plain = vp.inverse_kinematics(machine, fk.tip[ok], fk.axis[ok], theta2_hint=readings[ok, 4],
                                      tool_length=tool_length)
        np.testing.assert_allclose(plain.joints[:, :3] - ik.joints[ok, :3], np.tile(OFFSETS_MM, (ok.sum(), 1)),
                                   atol=1e-6)


def test_module_and_all_solutions_routes_apply_the_offsets(machine: vp.Machine) -> None:
    shifted = with_offsets(machine)
    geom, plain = shifted.kinematic_geometry(), machine.kinematic_geometry()
    readings = random_usable_joints(machine, 200, seed=5)
    fk = module_fk_working(geom, readings[:, :3])
    back = module_ik_working(geom, fk.platform)
    # The module IK returns the working root nearest alpha = 0: on the fringe of leg I's reach
    # that can be another working assembly than the one the FK found (skipped, a few poses).
    same_root = np.abs(back.rho - readings[:, :3]).max(axis=1) < 1.0
    assert same_root.mean() > 0.95
    np.testing.assert_allclose(back.rho[same_root], readings[same_root, :3], atol=1e-6)
    # the plain geometry reads the same platforms as the true slider heights
    np.testing.assert_allclose(module_ik_working(plain, fk.platform[same_root]).rho - back.rho[same_root],
                               np.tile(OFFSETS_MM, (same_root.sum(), 1)), atol=1e-6)
    full = vp.forward_kinematics(shifted, readings[:20])
    solutions = machine_ik_all(geom, full.tip, full.axis)
    for k in range(20):  # each pose's readings are among its solutions
        mine = solutions.joints[solutions.pose_index == k]
        distance = np.abs(mine[:, :3] - readings[k, :3]).max(axis=1) + np.abs(
            wrap_angle(mine[:, 3:] - readings[k, 3:])).max(axis=1)
        assert distance.min() < 1e-6


def test_zero_offsets_leave_results_bit_identical(machine: vp.Machine) -> None:
    zero = with_offsets(machine, (0.0, 0.0, 0.0), (0.0, 0.0))
    joints = random_usable_joints(machine, 500, seed=3)
    a, b = vp.forward_kinematics(machine, joints), vp.forward_kinematics(zero, joints)
    assert np.array_equal(a.tip, b.tip) and np.array_equal(a.axis, b.axis)
    ia = vp.inverse_kinematics(machine, a.tip, a.axis)
    ib = vp.inverse_kinematics(zero, a.tip, a.axis)
    assert np.array_equal(ia.joints, ib.joints, equal_nan=True)
