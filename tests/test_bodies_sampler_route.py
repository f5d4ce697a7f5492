"""The bodies' sampler (verne_post.bodies.world.World.sampler) against the straightforward route
it was rewritten from, bit for bit.

The sampler computes the head's bodies a component at a time, all slots side by side, and turns
them into the cradle frame a body end at a time; the links too. Those are restructurings of the
same floating-point operations on the same numbers, so every body, radius and lever must come
out with the same bits (and the same memory layout, which numpy's einsum results depend on) as
the one-slot-at-a-time route below, over thousands of random joint sets (reachable or not),
tool stacks with and without a shank, every subset of bodies a caller may ask for, and a setup
(the table frame) or none.
"""

from __future__ import annotations

import numpy as np
import pytest

import verne_post as vp
from tests.conftest import random_usable_joints
from verne_post.bodies.clearance import K_J, Samples
from verne_post.bodies.config import BodiesConfig
from verne_post.bodies.layout import LINK_NAMES, link_radii, platform_speeds, table_origin, to_table
from verne_post.bodies.setup import Setup, SetupBody
from verne_post.bodies.world import ProgramBodies, ToolShape, World
from verne_post.kinematics import Geometry
from verne_post.kinematics.module import module_fk_working

# ---- the reference route: the bodies placed one vector at a time, one slot at a time ----


def _reference_links(bodies: BodiesConfig, g: Geometry, rho: np.ndarray, platform: np.ndarray,
                     alpha: np.ndarray) -> np.ndarray:
    p = bodies.platform
    ca, sa = np.cos(alpha), np.sin(alpha)
    ey = np.column_stack([np.zeros_like(ca), ca, sa])
    ex = np.array([1.0, 0.0, 0.0])

    def on_platform(x: float, y: float) -> np.ndarray:
        return platform + x * ex + y * ey

    d1, d2 = p.D1 - g.D1_minus_d1, p.D2 - g.D2_minus_d2
    one = np.ones(len(rho))

    def on_slider(x: float, y: float, k: int) -> np.ndarray:
        return np.column_stack([x * one, y * one, rho[:, k]])

    joints = np.stack([
        np.stack([on_slider(d1, g.r1, 0), on_platform(p.D1, g.R1)], 1),
        np.stack([on_slider(d1, -g.r1, 0), on_platform(p.D1, -g.R1)], 1),
        np.stack([on_slider(d2, -g.r4, 1), on_platform(p.D2, -g.R2)], 1),
        np.stack([on_slider(d2, g.r4, 2), on_platform(p.D2, g.R2)], 1),
    ], 1)
    span = joints[:, :, 1] - joints[:, :, 0]
    inset = (link_radii(bodies)[:4] / np.linalg.norm(span, axis=2))[..., None] * span
    rods = np.stack([joints[:, :, 0] + inset, joints[:, :, 1] - inset], 2)
    platform_link = np.stack([on_platform(0.5 * (p.D1 + p.D2), -max(g.R1, g.R2)),
                              on_platform(0.5 * (p.D1 + p.D2), max(g.R1, g.R2))], 1)
    return np.concatenate([rods, platform_link[:, None]], 1)


def _reference_rotation(theta1: np.ndarray, theta2: np.ndarray) -> np.ndarray:
    c1, s1, c2, s2 = np.cos(theta1), np.sin(theta1), np.cos(theta2), np.sin(theta2)
    zero = np.zeros_like(c1)
    ca, sa = -c1, -s1
    return np.stack([np.stack([c2, -s2, zero], -1),
                     np.stack([ca * s2, ca * c2, -sa], -1),
                     np.stack([sa * s2, sa * c2, ca], -1)], -2)


def _reference_to_cradle(points: np.ndarray, theta2: np.ndarray) -> np.ndarray:
    c, s = np.cos(theta2), np.sin(theta2)
    if points.ndim == 3:
        c, s = c[:, None], s[:, None]
    x, y = points[..., 0], points[..., 1]
    return np.stack([c * x - s * y, s * x + c * y, points[..., 2]], -1)


def _reference_sampler(world: World):
    start, end, radius, _ = world._spans()
    lengths = np.array([s.start[-1] for s in world.stacks])
    g, slots = world.geometry, world.slots
    radii = link_radii(world.bodies)
    rod_levers = (g.R1, g.R1, g.R2, g.R2)
    platform_half = max(g.R1, g.R2)
    table_side = frozenset(f"{name}@{frame}" for name in (*slots, "platform") for frame in ("table", "cradle"))

    def sample(joints: np.ndarray, stack: np.ndarray, guess: np.ndarray | None,
               names: frozenset[str] | None = None) -> Samples:
        def wanted(key: str) -> bool:
            return names is None or key in names

        true = g.true_joints(joints)
        module = module_fk_working(g, joints[:, :3], guess)
        speed_p, speed_alpha = platform_speeds(g, joints[:, :3], module.platform, module.alpha)
        speed_p, speed_alpha = K_J * speed_p, K_J * speed_alpha
        bodies, rad, levers = {}, {}, {}
        zero = np.zeros(len(true))
        links = _reference_links(world.bodies, g, true[:, :3], module.platform, module.alpha)
        for k, name in enumerate(LINK_NAMES[:4]):
            key = f"{name}@base"
            if not wanted(key):
                continue
            rod = links[:, k]
            platform_end = speed_p + speed_alpha * rod_levers[k]
            length = np.linalg.norm(rod[:, 1] - rod[:, 0], axis=1) + 2.0 * radii[k]
            bodies[key], rad[key] = rod, np.full(len(true), radii[k])
            levers[key] = np.column_stack([np.maximum(1.0, platform_end) + radii[k] * (1.0 + platform_end) / length,
                                           zero, zero])
        if names is not None and not names & table_side:
            return Samples(bodies, rad, module.alpha, levers)
        delta = g.spindle_nose + lengths[stack]
        alpha = module.alpha
        ez = np.column_stack([np.zeros_like(alpha), -np.sin(alpha), np.cos(alpha)])
        rotation = _reference_rotation(true[:, 3], true[:, 4])
        origin = table_origin(g.da, g.dt, true[:, 3])
        tip = to_table(module.platform + delta[:, None] * ez, rotation, origin)
        axis = -np.einsum("nji,nj->ni", rotation, ez)
        head = tip[:, None, None] + np.stack([start[stack], end[stack]], -1)[..., None] * axis[:, None, None]
        platform_table = to_table(links[:, 4], rotation, origin)
        theta2 = true[:, 4]
        for k, name in enumerate(slots):
            if not (wanted(f"{name}@table") or wanted(f"{name}@cradle")):
                continue
            r = radius[stack, k]
            spans = np.stack([delta - start[stack, k], delta - end[stack, k]], 1)
            head_base = module.platform[:, None] + spans[..., None] * ez[:, None]
            lever = np.column_stack([speed_p + speed_alpha * (np.abs(spans).max(axis=1) + r),
                                     np.hypot(head_base[..., 1], head_base[..., 2] - g.da).max(axis=1) + r,
                                     np.hypot(head[:, k, :, 0], head[:, k, :, 1]).max(axis=1) + r])
            if wanted(f"{name}@table"):
                bodies[f"{name}@table"], rad[f"{name}@table"], levers[f"{name}@table"] = head[:, k], r, lever
            if wanted(f"{name}@cradle"):
                bodies[f"{name}@cradle"] = _reference_to_cradle(head[:, k], theta2)
                rad[f"{name}@cradle"], levers[f"{name}@cradle"] = r, lever * [1.0, 1.0, 0.0]
        r = radii[4]
        lever = np.column_stack([speed_p + speed_alpha * (platform_half + r),
                                 np.hypot(links[:, 4, :, 1], links[:, 4, :, 2] - g.da).max(axis=1) + r,
                                 np.hypot(platform_table[..., 0], platform_table[..., 1]).max(axis=1) + r])
        bodies["platform@table"] = platform_table
        bodies["platform@cradle"] = _reference_to_cradle(platform_table, theta2)
        rad["platform@table"] = rad["platform@cradle"] = np.full(len(true), r)
        levers["platform@table"], levers["platform@cradle"] = lever, lever * [1.0, 1.0, 0.0]
        return Samples(bodies, rad, module.alpha, levers)

    return sample


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal bit for bit (signed zeros included), NaN where the other is NaN, in the same shape
    and layout (numpy's einsum results depend on it). A NaN's sign is not compared: where NaNs
    of both signs meet (a pose the module cannot reach: its platform NaN, and negated NaNs in
    its rotation) numpy's loops keep one or the other by their vector width and alignment, the
    old route too, and nothing reads it (NaN compares, prints and serialises alike)."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.dtype != b.dtype or a.strides != b.strides:
        return False
    nan = np.isnan(a)
    return bool(np.array_equal(nan, np.isnan(b))
                and np.array_equal(a[~nan].view(np.uint64), b[~nan].view(np.uint64)))


def _world(machine: vp.Machine, with_setup: bool) -> World:
    """Two tools (one with a shank, one whose holder reaches its flutes) and a clamp and a stock
    on the table, or no setup."""
    setup = Setup((SetupBody("clamp", "fixture", "box", (-80.0, -30.0, 0.0), (-40.0, 30.0, 50.0)),
                   SetupBody("stock", "stock", "box", (-30.0, -30.0, 0.0), (30.0, 30.0, 40.0)))) if with_setup \
        else Setup(())
    tools = {1: ToolShape(diameter=10.0), 2: ToolShape(diameter=6.0, flute_length=20.0, holder=((40.0, 30.0),))}
    world, _ = ProgramBodies(setup, tools).world(machine.bodies, machine.geom, np.array([1, 2]),
                                                 np.array([120.0, 45.0]), np.array([0.0, 0.0, 300.0]))
    return world


@pytest.mark.parametrize("with_setup", [True, False])
def test_the_sampler_places_every_body_as_the_one_slot_route(with_setup: bool) -> None:
    machine = vp.load_machine()
    world = _world(machine, with_setup)
    rng = np.random.default_rng(11 if with_setup else 12)
    usable = random_usable_joints(machine, 1500, seed=31)
    # near the usable ones, some far off (out of reach: NaN bodies), some unknown
    joints = np.concatenate([usable, usable[:500] + rng.normal(size=(500, 5)) * [200.0, 200.0, 200.0, 1.0, 3.0]])
    joints[rng.random(len(joints)) < 0.01, rng.integers(0, 5)] = np.nan
    # finite joints where the module has no working assembly: NaN bodies that clear_motion reads
    joints[rng.random(len(joints)) < 0.03, :3] += [900.0, -900.0, 0.0]
    stack = rng.integers(0, len(world.stacks), len(joints))
    guess = np.where(rng.random(len(joints)) < 0.5, rng.normal(size=len(joints)) * 0.1, np.nan)
    every = sorted({name for pair in world.pairs(stack, np.zeros(len(joints), bool))
                    for name in (pair.moving, pair.other) if "@" in name})
    subsets: list[frozenset[str] | None] = [None, frozenset(every)]
    subsets += [frozenset(rng.choice(every, size=rng.integers(1, 4), replace=False)) for _ in range(12)]
    subsets += [frozenset({name}) for name in every]
    new, old = world.sampler(), _reference_sampler(world)
    compared = 0
    for names in subsets:
        pick = rng.random(len(joints)) < 0.5
        args = (joints[pick], stack[pick], guess[pick], names)
        got, want = new(*args), old(*args)
        assert _same_bits(got.alpha, want.alpha)
        for field in ("bodies", "radius", "levers"):
            a, b = getattr(got, field), getattr(want, field)
            assert sorted(a) == sorted(b), (names, field)
            for key in b:
                assert _same_bits(a[key], b[key]), (names, field, key)
                compared += len(b[key])
    assert compared > 100_000
    unreachable = np.all(np.isfinite(joints), axis=1) & ~np.isfinite(old(joints, stack, guess).alpha)
    assert unreachable.sum() > 20


def test_the_head_is_the_stack_placed_whole() -> None:
    """Placed.head (built from the components on demand) is the layout the table frame uses."""
    machine = vp.load_machine()
    world = _world(machine, True)
    joints = random_usable_joints(machine, 300, seed=7)
    stack = np.arange(len(joints)) % 2
    got = world.sampler()(joints, stack, None, frozenset({"cutter@table"}))
    want = _reference_sampler(world)(joints, stack, None, frozenset({"cutter@table"}))
    assert _same_bits(got.bodies["cutter@table"], want.bodies["cutter@table"])


def test_each_block_gets_the_stack_of_its_tool_and_length() -> None:
    """ProgramBodies.world's stacks, one per (tool, gauge length) pair in the order numpy sorts the
    pairs as rows, and each block's index into them (unknown lengths taken as the first known)."""
    machine = vp.load_machine()
    rng = np.random.default_rng(11)
    bodies = ProgramBodies(Setup(()), {})
    for m in (1, 7, 5000):
        tool = rng.integers(0, 5, m)
        length = rng.choice([60.0, 80.0, 100.0, 100.5, np.nan], m)
        world, index = bodies.world(machine.bodies, machine.geom, tool, length, np.zeros(3))
        known = np.isfinite(length)
        filled = np.where(known, length, length[known][0] if known.any() else 0.0)
        rows, expected = np.unique(np.column_stack([tool.astype(float), filled]), axis=0, return_inverse=True)
        assert np.array_equal(index, expected.reshape(-1))
        assert [float(s.start[-1]) for s in world.stacks] == list(rows[:, 1])  # the spindle starts at the nose
