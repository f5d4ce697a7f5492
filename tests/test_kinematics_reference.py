"""The paper's worked examples and the reference values of VERNE-KINEMATICS.md."""

from __future__ import annotations

import numpy as np
import pytest

import verne_post as vp
from verne_post.kinematics import machine_fk_all, module_fk_all, module_ik_all, module_ik_working

# VERNE-KINEMATICS.md, identified geometry (radians, mm)
TABLE_III = np.array([  # alpha, xP, yP, zP
    [-0.224976, -199.8652, 355.6464, 1242.0943],
    [-0.139877, 298.3689, -297.8078, -120.1279],
    [1.811069, -393.6156, 322.6043, 958.4576],
    [2.698610, -115.8978, -189.8384, -0.0487],
])
TABLE_V = np.array([  # phi1, phi2, xu, yu, zu
    [-0.414976, -0.39, -338.6527, -298.1621, 462.2935],
    [-0.329877, -0.39, 478.8805, 380.2115, 1661.2427],
    [1.621069, -0.39, -220.8970, 497.9267, 1213.2198],
    [2.508610, -0.39, 219.3548, 838.4818, 2432.5301],
])
# The paper's printed tables (Table V case (c) x_u printed -22106.: erratum, it is -221.06).
PAPER_III = np.array([
    [-0.22, -199.80, 355.92, 1242], [-0.14, 298.35, -297.53, -120.22],
    [1.81, -393.6, 322.82, 958.21], [2.70, -115.62, -189.68, -0.26],
])
PAPER_V = np.array([
    [-0.41, -0.39, -338.06, -296.89, 461.6], [-0.33, -0.39, 478.52, 379.38, 1661.55],
    [1.62, -0.39, -221.06, 497.49, 1213.31], [2.51, -0.39, 219.2, 837.37, 2433.67],
])


def test_figure5_sixteen_solutions_one_working(geom: vp.Geometry) -> None:
    sol = module_ik_all(geom, np.array([[-240.0, -86.0, 1000.0]]))
    assert len(sol.alpha) == 16
    np.testing.assert_allclose(np.unique(np.round(sol.alpha, 6)), [-2.910714, -0.051789, 0.051789, 2.910714],
                               atol=1e-6)
    assert sol.working_mode.sum() == 1
    working = np.flatnonzero(sol.working_mode)[0]
    assert sol.alpha[working] == pytest.approx(0.051789, abs=1e-6)
    np.testing.assert_allclose(sol.rho[working], [368.3547, 85.1585, 178.7844], atol=1e-3)
    fast = module_ik_working(geom, np.array([[-240.0, -86.0, 1000.0]]))
    np.testing.assert_allclose(fast.rho[0], sol.rho[working], atol=1e-9)


def test_table_iii_assembly_modes(geom: vp.Geometry) -> None:
    sol = module_fk_all(geom, np.array([[674.0, 685.0, 250.0]]))
    found = np.column_stack([sol.alpha, sol.platform])
    assert len(found) == 4
    for reference, printed in zip(TABLE_III, PAPER_III, strict=True):
        match = np.argmin(np.abs(found[:, 0] - reference[0]))
        np.testing.assert_allclose(found[match], reference, atol=1e-3)
        assert abs(found[match, 0] - printed[0]) <= 0.01
        np.testing.assert_array_less(np.abs(found[match, 1:] - printed[1:]), 1.5)
    assert list(sol.working_mode) == [bool(a == pytest.approx(-0.224976, abs=1e-5)) for a in sol.alpha]


def test_table_v_full_machine(geom: vp.Geometry) -> None:
    sol = machine_fk_all(geom, np.array([[674.0, 685.0, 250.0, 0.19, 0.39]]))
    found = np.column_stack([sol.phi, sol.tip])
    assert len(found) == 4
    for reference, printed in zip(TABLE_V, PAPER_V, strict=True):
        match = np.argmin(np.abs(found[:, 0] - reference[0]))
        np.testing.assert_allclose(found[match], reference, atol=1e-3)
        np.testing.assert_array_less(np.abs(found[match, :2] - printed[:2]), 0.01 + 1e-9)
        np.testing.assert_array_less(np.abs(found[match, 2:] - printed[2:]), 1.5)
    assert sol.working_mode.sum() == 1


def test_working_fk_is_case_a(machine: vp.Machine) -> None:
    fk = vp.forward_kinematics(machine, [[674.0, 685.0, 250.0, 0.19, 0.39]])
    np.testing.assert_allclose(fk.tip[0], TABLE_V[0, 2:], atol=1e-3)
    np.testing.assert_allclose(fk.alpha[0], TABLE_III[0, 0], atol=1e-6)


def test_y_zero_special_case(geom: vp.Geometry) -> None:
    """yP = 0: alpha in {0, +-alpha1, pi} (Table I); rho1 takes both signs at alpha = 0 (Table II)."""
    sol = module_ik_all(geom, np.array([[-240.0, 0.0, 1000.0]]))
    alphas = np.unique(np.round(sol.alpha, 9))
    assert 0.0 in alphas
    at_zero = sol.rho[np.abs(sol.alpha) < 1e-12]
    assert len(np.unique(np.round(at_zero[:, 0], 6))) == 2
    assert sol.working_mode.sum() == 1
    assert sol.alpha[sol.working_mode][0] == 0.0
    residual = vp.kinematics.closure_residuals(geom, np.tile([-240.0, 0.0, 1000.0], (len(sol.alpha), 1)),
                                               sol.alpha, sol.rho)
    assert np.max(np.abs(residual)) <= 1e-9 * geom.L1**2


def test_coupling_ellipse_is_eq6(geom: vp.Geometry) -> None:
    """Points of the ellipse (eq. 7) for a given alpha satisfy eq. 6, and the IK gives that alpha back."""
    from tests.independent import coupling
    from verne_post.kinematics import coupling_ellipse

    rng = np.random.default_rng(31)
    alpha = rng.uniform(-0.6, 0.6, 2000)
    a, b = coupling_ellipse(geom, alpha)
    angle = rng.uniform(0, 2 * np.pi, 2000)
    platform = np.column_stack([a * np.cos(angle) - geom.D1_minus_d1, b * np.sin(angle), np.full(2000, 1500.0)])
    assert np.max(np.abs(coupling(geom, platform, alpha))) <= 1e-9 * geom.L1**4
    solutions = module_ik_all(geom, platform)
    for k in range(0, 2000, 50):
        found = solutions.alpha[solutions.pose_index == k]
        if found.size:
            assert np.min(np.abs(found - alpha[k])) <= 1e-6 or np.min(np.abs(found + alpha[k])) <= 1e-6
