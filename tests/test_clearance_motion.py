"""The clearance along a motion (verne_post.bodies.clearance) against brute force.

Random walks of the joints, many windows of blocks long, with short steps and long jumps, pass a
fixture set beside the tool and the table. Each block's joint-space line is sampled densely and
every checked pair measured at every sample: the least of those is within the distance
function's settling (0.02 mm) of an upper bound of the block's true least clearance. The
clearance the check reports for the block must never exceed it, whether it came from a window's
capsule, the sampling bound between block ends or the bisection.
"""

from __future__ import annotations

import numpy as np

import verne_post as vp
from tests.conftest import random_usable_joints
from verne_post.bodies.clearance import MAX_SLIDER_STEP, MAX_TURN, WINDOW, _motion, clear_motion
from verne_post.bodies.convex import Capsules, distance, rows
from verne_post.bodies.setup import Setup, SetupBody
from verne_post.bodies.world import ProgramBodies, ToolShape, World

TOOL_LENGTH = 100.0
DENSE = 48  # samples per block
SETTLED = 0.02  # mm: verne_post.bodies.convex.SETTLED


def _walk(start: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` block ends from ``start`` (mm, rad): short steps, and a long jump now and then."""
    step = rng.normal(size=(count, 5)) * np.array([1.5, 1.5, 1.5, 0.004, 0.01])
    jump = rng.random(count) < 0.05
    step[jump] *= 20.0
    return start + np.cumsum(np.r_[np.zeros((1, 5)), step[1:]], axis=0)


def _brute(sample, pair, joints: np.ndarray, stack: np.ndarray) -> np.ndarray:
    """(M - 1,) per block: the pair's least distance at DENSE samples of its line."""
    f = np.linspace(0.0, 1.0, DENSE + 1)
    q = (joints[:-1, None] + f[None, :, None] * (joints[1:, None] - joints[:-1, None])).reshape(-1, 5)
    placed = sample(q, np.repeat(stack[1:], DENSE + 1), None)
    known = np.flatnonzero(np.isfinite(placed.alpha))
    least = np.full(len(q), np.inf)
    least[known] = _pair_distance(placed, pair, known)
    return least.reshape(len(joints) - 1, DENSE + 1).min(axis=1)


def _pair_distance(placed, pair, index: np.ndarray) -> np.ndarray:
    """(len(index),) mm: the pair's distance at the placed samples ``index``, the bodies built here."""
    a = placed.bodies[pair.moving][index]
    body_a = pair.kind(a[:, 0], a[:, 1], placed.radius[pair.moving][index])
    if pair.fixed is None:
        b = placed.bodies[pair.other][index]
        body_b = Capsules(b[:, 0], b[:, 1], placed.radius[pair.other][index])
    else:
        body_b = rows(pair.fixed, np.zeros(len(index), int))
    return distance(body_a, body_b)


def _beside_a_clamp(machine: vp.Machine, start: np.ndarray, gap: float, m: int) -> tuple[World, np.ndarray]:
    """The bodies of a 100 mm tool (10 mm cutter) and a clamp ``gap`` mm beside the tip at joints
    ``start`` (mm, rad), reaching above it; the world and the tool stacks of ``m`` block ends."""
    tip = vp.forward_kinematics(machine, start[None], tool_length=TOOL_LENGTH).tip[0]
    lo, hi = tip + np.array([gap, -15.0, -10.0]), tip + np.array([40.0, 15.0, 60.0])
    clamp = SetupBody("clamp", "fixture", "box", tuple(lo), tuple(hi))
    bodies = ProgramBodies(Setup((clamp,)), {1: ToolShape(diameter=10.0)})
    return bodies.world(machine.bodies, machine.geom, np.ones(m), np.full(m, TOOL_LENGTH), np.zeros(3))


def test_the_clearance_along_a_motion_never_exceeds_dense_sampling() -> None:
    machine = vp.load_machine()
    margin = machine.bodies.margin
    rng = np.random.default_rng(5)
    starts = random_usable_joints(machine, 4, seed=21, tool_length=TOOL_LENGTH)
    compared = near = 0
    for start in starts:
        joints = _walk(start, 4 * WINDOW + 7, rng)
        # a clamp 12 mm beside the tip at the start, reaching above it: the cutter, the shank and
        # the holder pass it at a few mm to tens of mm as the walk goes on
        world, stack = _beside_a_clamp(machine, start, 12.0, len(joints))
        m = len(joints)
        sample = world.sampler()
        for pair in world.pairs(stack, np.zeros(m, bool)):
            # one pair at a time: the least over the pairs would hide a pair's overstated bound
            reported = clear_motion(joints, sample, stack, [pair], margin).smallest[1:]
            brute = _brute(sample, pair, joints, stack)
            valid = np.isfinite(brute)
            assert np.all(reported[valid] <= brute[valid] + SETTLED + 1e-9), (
                pair.moving, pair.other, np.max(reported[valid] - brute[valid]))
            compared += int(np.count_nonzero(valid & (brute < 100.0)))
            near += int(np.count_nonzero(valid & (brute < 3.0 * margin)))
    # the comparison means something: many blocks within the cap, and some near the margin
    assert compared > 1000 and near > 10, (compared, near)


def _rim(ends: np.ndarray, radius: np.ndarray) -> list[np.ndarray]:
    """Points of a body of revolution (T, K, 2, 3) axis ends, (T, K) radius, without spin about its
    axis: its axis ends, and four points on each end's rim carried by a direction kept normal to
    the axis (the projection of one fixed direction)."""
    axis = ends[..., 1, :] - ends[..., 0, :]
    unit = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    fixed = np.cross(unit[:, :1], [0.577, 0.577, 0.577]) + 0.3 * np.cross(unit[:, :1], [1.0, 0.0, 0.0])
    normal = fixed - np.sum(fixed * unit, axis=-1, keepdims=True) * unit
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    other = np.cross(unit, normal)
    points = []
    for end in (0, 1):
        points.append(ends[..., end, :])
        for angle in np.arange(4) * np.pi / 2:
            points.append(ends[..., end, :] + radius[..., None] * (np.cos(angle) * normal + np.sin(angle) * other))
    return points


def test_no_body_point_moves_faster_than_the_bound() -> None:
    """Along random stretches of every size the bound allows (sliders up to 100 mm, turns up to
    0.5 rad, alone and together, and sliders moving against each other), every point's speed,
    measured by dense forward kinematics, stays under the bound m of the stretch."""
    machine = vp.load_machine()
    count, dense = 1500, 48
    starts = random_usable_joints(machine, count, seed=8, tool_length=TOOL_LENGTH)
    rng = np.random.default_rng(9)
    bodies = ProgramBodies(Setup(()), {1: ToolShape(diameter=10.0)})
    world, _ = bodies.world(machine.bodies, machine.geom, np.ones(2), np.full(2, TOOL_LENGTH), np.zeros(3))
    sample = world.sampler()
    f = np.linspace(0.0, 1.0, dense + 1)
    checked = 0
    for kind in ("all", "sparse", "turns", "against"):
        step = rng.uniform(-1.0, 1.0, (count, 5))
        if kind == "sparse":
            step *= rng.random((count, 5)) < 0.4
            step[~step.any(axis=1), 0] = 1.0
        elif kind == "turns":
            step[:, :3] *= 0.02
        elif kind == "against":
            step[:, 2] = -step[:, 0]
            step[:, 1] *= 0.05
        size = rng.uniform(0.02, 1.0, count) ** 2
        step *= (size / np.maximum(np.linalg.norm(step[:, :3], axis=1) / MAX_SLIDER_STEP,
                                   np.abs(step[:, 3:]).sum(axis=1) / MAX_TURN))[:, None]
        q = (starts[:, None] + f[None, :, None] * step[:, None]).reshape(-1, 5)
        placed = sample(q, np.zeros(len(q), int), None)
        for name, ends in placed.bodies.items():
            ends = ends.reshape(count, dense + 1, 2, 3)
            levers = placed.levers[name].reshape(count, dense + 1, 3)
            bound = _motion(starts, starts + step, levers[:, 0], levers[:, -1])
            speed = np.zeros(count)
            for points in _rim(ends, placed.radius[name].reshape(count, dense + 1)):
                speed = np.maximum(speed, np.linalg.norm(np.diff(points, axis=1), axis=-1).max(axis=1) * dense)
            known = np.isfinite(levers).all(axis=(1, 2)) & np.isfinite(speed)
            excess = speed[known] - bound[known]
            assert np.all(excess <= 1e-9), (kind, name, np.max(excess))
            checked += int(known.sum())
    assert checked > 0.9 * 4 * count * len(placed.bodies)


def test_the_clearance_of_bodies_standing_still_is_every_pairs_least_distance() -> None:
    """clear_at (placement's bodies screen) against each pair's distance at each joint set, measured
    one pair at a time: the same under the margin (within the settling), at least the margin above."""
    machine = vp.load_machine()
    margin = machine.bodies.margin
    rng = np.random.default_rng(8)
    seen = meeting = 0
    for start in random_usable_joints(machine, 3, seed=34, tool_length=TOOL_LENGTH):
        joints = _walk(start, 200, rng)
        world, stack = _beside_a_clamp(machine, start, 4.0, len(joints))
        m = len(joints)
        cut = rng.random(m) < 0.5  # the cutter against the stock is left out where it cuts
        screened = world.clearance_at(joints, stack, cut)
        placed = world.sampler()(joints, stack, None)
        known = np.isfinite(placed.alpha)
        least = np.full(m, np.inf)
        for pair in world.pairs(stack, cut):
            rows_ = np.flatnonzero(known & (True if pair.active is None else pair.active))
            np.minimum.at(least, rows_, _pair_distance(placed, pair, rows_))
        valid = known & np.isfinite(least)
        assert np.allclose(np.minimum(screened[valid], margin), np.minimum(least[valid], margin), atol=SETTLED)
        assert np.array_equal(screened[valid] <= 0.0, least[valid] <= 0.0)
        seen += int(np.count_nonzero(valid & (least < margin)))
        meeting += int(np.count_nonzero(valid & (least <= 0.0)))
    assert seen > 20 and meeting > 5, (seen, meeting)
