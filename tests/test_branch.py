"""Branch choice, rotary continuity and the pole, on synthetic paths (table frame, mm, rad)."""

from __future__ import annotations

import numpy as np

import verne_post as vp
from verne_post.machine import JointLimits
from verne_post.motion.branch import solve_path


def _cone_path(n: int, tilt_deg: float, turns: float) -> tuple[np.ndarray, np.ndarray]:
    """Tool axis sweeping ``turns`` around the table normal at a fixed tilt; tip on a circle."""
    azimuth = np.linspace(0.0, 2 * np.pi * turns, n)
    tilt = np.radians(tilt_deg)
    axis = np.column_stack([np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), np.full(n, np.cos(tilt))])
    tip = np.column_stack([40 * np.cos(azimuth), 40 * np.sin(azimuth), np.full(n, 30.0)])
    return tip, axis


def test_one_pair_per_cut_and_continuous_theta2(machine: vp.Machine) -> None:
    tip, axis = _cone_path(400, 30.0, 2.5)
    path = solve_path(machine, tip, axis, tool_length=60.0)
    assert np.all(path.result.status == vp.Status.OK)
    assert len(np.unique(path.result.pair)) == 1
    theta2 = path.result.joints[:, 4]
    assert np.max(np.abs(np.diff(theta2))) < np.radians(5)  # no 360-degree jumps
    assert abs(theta2[-1] - theta2[0]) > 2 * 2 * np.pi  # it really turned 2.5 times
    fk = vp.forward_kinematics(machine, path.result.joints, tool_length=60.0)
    np.testing.assert_allclose(fk.tip, tip, atol=1e-9)
    np.testing.assert_allclose(fk.axis, axis, atol=1e-9)


def test_limited_rotary_is_shifted_by_whole_turns(machine: vp.Machine) -> None:
    limited = machine.model_copy(update={"joints": machine.joints.model_copy(update={
        "theta2": JointLimits(min=-200.0, max=200.0, velocity=300, acceleration=1000, jerk=10000)})})
    tip, axis = _cone_path(200, 30.0, 0.8)
    # Start the sweep so that the natural unwrapped theta2 leaves the range...
    offset = np.radians(150)
    rotation = np.array([[np.cos(offset), -np.sin(offset), 0], [np.sin(offset), np.cos(offset), 0], [0, 0, 1]])
    tip, axis = tip @ rotation.T, axis @ rotation.T
    sequence = np.zeros(len(tip), int)
    path = solve_path(limited, tip, axis, sequence, tool_length=60.0)
    theta2 = np.degrees(path.result.joints[:, 4])
    assert theta2.min() >= -200 and theta2.max() <= 200
    assert np.all(path.result.status == vp.Status.OK)
    # ... and a cut that needs more than the range is reported as out of limits.
    tip, axis = _cone_path(300, 30.0, 1.5)
    path = solve_path(limited, tip, axis, tool_length=60.0)
    assert np.any(path.result.status == vp.Status.OUT_OF_LIMITS)


def test_crossing_the_pole_keeps_the_table_still(machine: vp.Machine) -> None:
    """A straight pass whose axis tilts through the table normal: theta2 stays put, theta1
    passes through zero (the other angle pair after the pole), no half turn of the table."""
    n = 201
    lean = np.radians(np.linspace(-10, 10, n))
    axis = np.column_stack([np.sin(lean), np.zeros(n), np.cos(lean)])
    tip = np.column_stack([np.linspace(-20, 20, n), np.full(n, 5.0), np.full(n, 30.0)])
    path = solve_path(machine, tip, axis, tool_length=60.0, cone=np.radians(machine.pole.cone))
    theta = path.result.joints[:, 3:]
    assert np.all(path.result.status == vp.Status.OK)
    assert np.ptp(theta[:, 1]) < 1e-9
    assert np.max(np.abs(np.diff(theta[:, 0]))) < np.radians(0.5)
    assert path.in_cone.any() and not path.pair_switch.any()
    fk = vp.forward_kinematics(machine, path.result.joints, tool_length=60.0)
    np.testing.assert_allclose(fk.tip, tip, atol=1e-9)
    error = 2 * np.arcsin(np.linalg.norm(fk.axis - axis, axis=1) / 2)
    assert error.max() <= np.radians(machine.pole.cone) + 1e-12
    assert np.all(error[~path.in_cone] < 1e-9)


def test_rapids_take_the_short_way_round(machine: vp.Machine) -> None:
    tip, axis = _cone_path(2, 30.0, 0.9)  # two poses 324 degrees apart in azimuth
    path = solve_path(machine, tip, axis, np.array([0, 1]), tool_length=60.0)
    assert abs(np.degrees(np.diff(path.result.joints[:, 4]))[0]) <= 180
