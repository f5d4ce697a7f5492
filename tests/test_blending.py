"""Guard blocks at rotary corners (verne_post.linuxcnc.blending) on seeded random tool paths: the
guards lie on the program's joint-space lines, their blocks' shares add up, the blend measure
agrees with a brute force here, and what cannot run is left alone. Through LinuxCNC itself:
tests/test_linuxcnc.py."""

from __future__ import annotations

import numpy as np
import pytest

import verne_post as vp
from tests.paths import TOOL, axis_from
from verne_post.linuxcnc import blending
from verne_post.linuxcnc.blend_bound import blend_estimate
from verne_post.linuxcnc.blending import (
    MARGIN,
    SAMPLES,
    Guarded,
    blend_deviation,
    corner_guards,
    guard_corners,
    split_durations,
)
from verne_post.motion.linearise import Blocks
from verne_post.planning.controller import rotary_block_floor
from verne_post.planning.timing import Limits


def _blocks(machine: vp.Machine, seed: int, n: int = 400, step: float = 0.4, turn: float = 0.6) -> Blocks:
    """A wandering 5-axis path (mm, table frame): tips in random steps of about ``step`` mm, the tool
    axis tilting back and forth (``turn``: the phase's largest step, rad), so that the table turns
    back at random points."""
    rng = np.random.default_rng(seed)
    tip = np.array([20.0, -10.0, 60.0]) + np.cumsum(rng.normal(0.0, step, (n, 3)), axis=0)
    tilt = np.radians(25.0 + 10.0 * np.sin(np.cumsum(rng.uniform(0.0, turn, n))))
    azimuth = np.radians(30.0) + np.cumsum(rng.normal(0.0, 0.02, n))
    axis = axis_from(tilt, azimuth)
    ik = vp.inverse_kinematics(machine, tip, axis, tool_length=TOOL, theta2_hint=0.5)
    assert np.all(ik.status == vp.Status.OK)
    ik = ik.with_joints(np.c_[ik.joints[:, :4], np.unwrap(ik.joints[:, 4])])
    return Blocks(tip, axis, np.arange(n), np.ones(n), ik, np.empty(0, int), np.zeros(n, bool))


@pytest.mark.parametrize("seed", range(4))
def test_guards_lie_on_the_joint_lines_and_share_their_blocks(machine: vp.Machine, seed: int) -> None:
    blocks = _blocks(machine, seed)
    n = len(blocks.joints)
    guarded = guard_corners(machine, blocks, np.zeros(n, bool), np.full(n, TOOL), tol=0.005, rapid_tol=0.5,
                            blend_tolerance=0.005)
    assert len(guarded.owner) > n  # random reversals of the table: some corners are guarded
    # every original block end is kept, in order
    np.testing.assert_array_equal(guarded.blocks.joints[_ends(guarded)], blocks.joints)
    # each row on the straight joint-space line of its block, the shares of a block adding to 1
    start = blocks.joints[np.maximum(guarded.owner - 1, 0)]
    end = blocks.joints[guarded.owner]
    u = np.einsum("ij,ij->i", guarded.blocks.joints - start, end - start) / np.maximum(
        np.einsum("ij,ij->i", end - start, end - start), 1e-300)
    np.testing.assert_allclose(start + u[:, None] * (end - start), guarded.blocks.joints, atol=1e-9)
    np.testing.assert_allclose(np.bincount(guarded.owner, guarded.piece), 1.0)
    assert np.all((guarded.piece > 0) & (guarded.piece <= 1.0)) and np.any(guarded.piece < 1.0)
    # durations: each row its share of its block, at least its own least time; never shorter in all
    duration = np.r_[0.0, np.full(n - 1, 0.02)]
    limits = Limits.from_machine(machine)
    split = split_durations(machine, guarded, duration, np.full(len(guarded.owner), TOOL), block_time=0.001)
    guards = guarded.piece < 1.0
    assert np.all(split[guards] >= rotary_block_floor(guarded.blocks.joints, limits)[guards] - 1e-15)
    assert np.all(split[guards] >= 0.001) and split.sum() >= duration.sum()
    np.testing.assert_array_equal(split[~guards], duration[guarded.owner[~guards]])


def _ends(guarded: Guarded) -> np.ndarray:
    """The rows that are the given blocks' own ends (the last row of each owner)."""
    return np.flatnonzero(np.r_[guarded.owner[1:] != guarded.owner[:-1], True])


def test_the_blend_measure_against_a_brute_force(machine: vp.Machine) -> None:
    """blend_deviation's largest distance equals one found here point by point: the tip by FK at
    dense points of the blend q(s), against the two CL segments around the corner."""
    blocks = _blocks(machine, 7, n=60)
    q, tips = blocks.joints, blocks.tip
    rng = np.random.default_rng(3)
    corner = np.arange(1, len(q) - 1)
    f1, f2 = rng.uniform(0.0, 0.5, len(corner)), rng.uniform(0.0, 0.5, len(corner))
    found = blend_deviation(machine, q[corner], q[corner] - q[corner - 1], q[corner + 1] - q[corner], f1, f2,
                            (tips[corner - 1], tips[corner], tips[corner + 1]), np.full(len(corner), TOOL))
    s = np.union1d(np.linspace(SAMPLES[0], SAMPLES[-1], 401), SAMPLES)  # the blend between the blocks
    for k, c in enumerate(corner):
        path = q[c] - np.outer(f1[k] * (1 - s) ** 2, q[c] - q[c - 1]) + np.outer(f2[k] * s**2, q[c + 1] - q[c])
        tip = vp.forward_kinematics(machine, path, tool_length=TOOL).tip
        distance = np.min([_to_segment(tip, tips[c - 1], tips[c]), _to_segment(tip, tips[c], tips[c + 1])], axis=0)
        # the measure samples the blend at 20 points: never above the dense maximum, and close to it
        assert found[k] <= distance.max() + 1e-9
        assert found[k] >= MARGIN * distance.max() - 1e-6  # understated by less than the guards keep in hand


def _to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    t = np.clip((p - a) @ (b - a) / max(float((b - a) @ (b - a)), 1e-300), 0.0, 1.0)
    return np.linalg.norm(p - a - t[:, None] * (b - a), axis=1)


def test_what_cannot_run_is_left_alone(machine: vp.Machine) -> None:
    blocks = _blocks(machine, 1, n=50)
    n = len(blocks.joints)
    unreachable = blocks.result.with_joints(np.full((n, 5), np.nan))
    nan_blocks = Blocks(blocks.tip, blocks.axis, blocks.pose, blocks.fraction, unreachable, blocks.unresolved,
                        blocks.between)
    for given in (nan_blocks, blocks.rows(slice(0, 2))):
        m = len(given.joints)
        out = guard_corners(machine, given, np.zeros(m, bool), np.full(m, TOOL), tol=0.005, rapid_tol=0.5,
                            blend_tolerance=0.005)
        assert out.blocks is given and np.array_equal(out.owner, np.arange(m))


@pytest.mark.parametrize(("step", "turn", "share", "tight", "offsets"), [
    (0.05, 0.05, 1.0, 1e-6, False), (0.4, 0.6, 1.0, 1e-6, False), (1.0, 0.2, 1.0, 1e-6, False),
    (2.0, 1.5, 0.5, 1e-4, False), (0.4, 0.6, 1.0, 1e-6, True)])
def test_the_blend_estimate_is_within_its_bound_of_the_full_kinematics(machine: vp.Machine, step: float, turn: float,
                                                                       share: float, tight: float,
                                                                       offsets: bool) -> None:
    """blend_bound's estimate against blend_deviation (the full FK at each of the 20 samples) at
    1,200 corners of a wandering path, at random shares of the blocks: they differ by no more than
    the bound, and the bound is finite (the estimate decides) at all corners of blocks of a few mm
    and at most of blocks of 8 to 40 mm (``share``; beyond its contraction the full FK decides), and
    mostly far below the 0.004 mm budget of --tol 0.005 (``tight``). Also with joint zero offsets
    (joints read by the controller, not the true ones)."""
    if offsets:
        zeros = {name: getattr(machine.joints, name).model_copy(update={"offset": offset}) for name, offset in
                 (("rho1", 0.7), ("rho2", -1.3), ("rho3", 0.4), ("theta1", 0.3), ("theta2", -2.0))}
        machine = machine.model_copy(update={"joints": machine.joints.model_copy(update=zeros)})
    rng = np.random.default_rng(int(100 * step) + offsets)
    blocks = _blocks(machine, int(10 * step) + offsets, n=1200, step=step, turn=turn)
    q, tips = blocks.joints, blocks.tip
    corner = np.arange(1, len(q) - 1)
    f1, f2 = rng.uniform(0.0, 0.5, len(corner)), rng.uniform(0.0, 0.5, len(corner))
    tool = np.full(len(corner), TOOL)
    estimate, bound = blend_estimate(machine, blocks, corner, f1, f2, tool, SAMPLES)
    exact = blend_deviation(machine, q[corner], q[corner] - q[corner - 1], q[corner + 1] - q[corner], f1, f2,
                            (tips[corner - 1], tips[corner], tips[corner + 1]), tool)
    used = np.isfinite(bound)
    assert used.mean() >= share
    assert np.all(np.abs(estimate - exact)[used] <= bound[used])
    assert np.median(bound[used]) < tight


@pytest.mark.parametrize("tol", [0.001, 0.005, 0.02])
def test_the_guards_are_the_full_kinematics_guards(machine: vp.Machine, tol: float,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """corner_guards decides with the estimate where its bound tells: the same guards, to the bit,
    as deciding every corner by the full kinematics (an estimate whose bound tells nothing)."""
    blocks = _blocks(machine, 5, n=600)
    n = len(blocks.joints)
    rapid = np.zeros(n, bool)
    rapid[200:220] = True
    args = (machine, blocks, rapid, np.full(n, TOOL))
    options = {"tol": tol, "rapid_tol": 0.5, "blend_tolerance": 0.005}
    fast = corner_guards(*args, **options)
    monkeypatch.setattr(blending, "blend_estimate",
                        lambda machine, blocks, corner, *rest: (np.zeros(len(corner)), np.full(len(corner), np.inf)))
    full = corner_guards(*args, **options)
    assert np.any(full[0] > 0)
    np.testing.assert_array_equal(fast[0], full[0])
    np.testing.assert_array_equal(fast[1], full[1])
