"""Analytic Jacobians against central differences of the forward kinematics."""

from __future__ import annotations

import numpy as np

import verne_post as vp
from tests.conftest import random_usable_joints
from verne_post.kinematics import (
    Geometry,
    closure_residuals,
    joint_rates,
    machine_jacobian,
    margins,
    module_fk_working,
    module_jacobian,
)
from verne_post.kinematics.jacobian import closure_inverse


def test_machine_jacobian_matches_finite_differences(machine: vp.Machine) -> None:
    joints = random_usable_joints(machine, 2_000, 11, 60.0)
    geom = machine.kinematic_geometry(60.0)
    fk = vp.forward_kinematics(machine, joints, tool_length=60.0)
    jac = machine_jacobian(geom, joints, fk.platform, fk.alpha)
    numeric = np.empty_like(jac)
    for k, h in enumerate((1e-4, 1e-4, 1e-4, 1e-7, 1e-7)):
        step = np.zeros(5)
        step[k] = h
        plus = vp.forward_kinematics(machine, joints + step, tool_length=60.0)
        minus = vp.forward_kinematics(machine, joints - step, tool_length=60.0)
        numeric[:, :3, k] = (plus.tip - minus.tip) / (2 * h)
        numeric[:, 3:, k] = (plus.axis - minus.axis) / (2 * h)
    scale = np.abs(numeric).max(axis=(1, 2), keepdims=True)
    assert np.max(np.abs(jac - numeric) / scale) <= 1e-5


def _module_differences(geom: Geometry, rho: np.ndarray, h: float = 1e-4) -> np.ndarray:
    """(N, 4, 3): d(xP, yP, zP, alpha)/d(rho) by central differences of the module's FK."""
    columns = []
    for k in range(3):
        step = np.zeros(3)
        step[k] = h
        plus, minus = module_fk_working(geom, rho + step), module_fk_working(geom, rho - step)
        columns.append(np.column_stack([(plus.platform - minus.platform), plus.alpha - minus.alpha]) / (2 * h))
    return np.stack(columns, axis=2)


def test_module_jacobian_matches_finite_differences(machine: vp.Machine) -> None:
    geom = machine.kinematic_geometry()
    rho = random_usable_joints(machine, 2_000, 12)[:, :3]
    fk = module_fk_working(geom, rho)
    jac = module_jacobian(geom, fk.platform, fk.alpha, rho)
    np.testing.assert_allclose(jac, _module_differences(geom, rho), rtol=1e-4, atol=1e-7)


def test_closure_inverse_is_a_newton_step_and_the_module_jacobian(machine: vp.Machine) -> None:
    """closure_inverse: its Jacobian matches finite differences of the FK as module_jacobian's does,
    and a Newton step with its inverse takes a pose 1e-4 mm and 1e-6 rad off the closure equations
    back to them (to the square of that)."""
    geom = machine.kinematic_geometry()
    rho = random_usable_joints(machine, 2_000, 14)[:, :3]
    fk = module_fk_working(geom, rho)
    inverse, jac = closure_inverse(geom, fk.platform, fk.alpha, rho)
    np.testing.assert_allclose(np.moveaxis(jac, 2, 0), _module_differences(geom, rho), rtol=1e-4, atol=1e-7)
    off = np.c_[fk.platform, fk.alpha] + np.random.default_rng(3).normal(0.0, [1e-4, 1e-4, 1e-4, 1e-6], (len(rho), 4))
    residual = closure_residuals(geom, off[:, :3], off[:, 3], rho).T  # (4, N)
    stepped = off - 0.5 * np.einsum("ijn,jn->ni", inverse, residual)
    np.testing.assert_allclose(stepped, np.c_[fk.platform, fk.alpha], rtol=0.0, atol=1e-7)


def test_joint_rates_invert_the_jacobian(machine: vp.Machine) -> None:
    joints = random_usable_joints(machine, 2_000, 13)
    geom = machine.kinematic_geometry()
    fk = vp.forward_kinematics(machine, joints)
    jac = machine_jacobian(geom, joints, fk.platform, fk.alpha)
    rates = np.random.default_rng(14).normal(size=(len(joints), 5))
    twist = np.einsum("nij,nj->ni", jac, rates)
    np.testing.assert_allclose(joint_rates(jac, twist[:, :3], twist[:, 3:]), rates, atol=1e-6)


def test_margins_vanish_at_singularities(machine: vp.Machine) -> None:
    """The serial margin is |cos| of a rod against its guideway: a horizontal rod gives 0."""
    geom = machine.kinematic_geometry()
    platform = np.array([[-240.0, -86.0, 1000.0]])
    ik = vp.module_ik_working(geom, platform)
    found = margins(geom, np.c_[ik.rho, [[0.0, 0.0]]], platform, ik.alpha)
    assert 0 < found.serial[0] < 1 and 0 < found.parallel[0] < 1
    # Raise slider 1 until the leg I mid-rod is horizontal: rho1 = zP (eq. 10 radicand at 0).
    level = np.array([[platform[0, 2], ik.rho[0, 1], ik.rho[0, 2]]])
    rods = geom.L1**2 - (geom.R1**2 + geom.r1**2 - 2 * geom.R1 * geom.r1 * np.cos(ik.alpha[0]))
    assert rods > 0
    serial = margins(geom, np.c_[level, [[0.0, 0.0]]], platform, ik.alpha).serial[0]
    assert serial < found.serial[0]
    assert found.rod_clearance[0] == geom.R1 * np.cos(ik.alpha[0]) - geom.r1
