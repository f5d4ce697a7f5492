"""The bodies' distances against brute force, and the bodies' places against the kinematics.

Brute force: points sampled over the surface of body A (a coarse cloud, then a fine one about its
best point), each measured to body B by a point-to-body formula written here (not the code under
test). Their least distance is an upper bound of the true distance, within the fine cloud's
spacing of it; the certified distance must never exceed it, and must come within that spacing (and 0.02 mm: the
iterations stop within GAP of their upper bound, or after MAX_ITERATIONS).
"""

from __future__ import annotations

import zlib

import numpy as np
import pytest

import verne_post as vp
from tests.conftest import random_usable_joints
from tests.independent import table_transform
from verne_post.bodies.convex import Boxes, Capsules, Cylinders, distance
from verne_post.bodies.layout import link_radii, place, tool_stack
from verne_post.kinematics.module import module_fk_working

PAIRS = 200  # per combination of kinds


# --- independent point-to-body distances (0 inside) -------------------------------------------

def _to_segment(x: np.ndarray, p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
    d = p1 - p0
    t = np.clip(((x - p0) @ d) / (d @ d), 0.0, 1.0)
    return np.linalg.norm(x - (p0 + t[:, None] * d), axis=1)


def point_distance(kind: str, body: dict, x: np.ndarray) -> np.ndarray:
    if kind == "capsule":
        return np.maximum(_to_segment(x, body["p0"], body["p1"]) - body["r"], 0.0)
    if kind == "cylinder":
        span = body["p1"] - body["p0"]
        h = np.linalg.norm(span)
        a = span / h
        along = (x - body["p0"]) @ a
        radial = np.linalg.norm((x - body["p0"]) - along[:, None] * a, axis=1)
        return np.hypot(np.maximum(radial - body["r"], 0.0), np.maximum(np.abs(along - h / 2) - h / 2, 0.0))
    return np.linalg.norm(np.maximum(np.maximum(body["lo"] - x, x - body["hi"]), 0.0), axis=1)


# --- surfaces, parametrised over [0, 1]^2 (and a face for boxes) --------------------------------

def surface(kind: str, body: dict, u: np.ndarray, v: np.ndarray, w: np.ndarray, face: np.ndarray) -> np.ndarray:
    if kind == "capsule":  # the axis point at u, the sphere direction at (v, w)
        p0, p1, r = body["p0"], body["p1"], body["r"]
        z = 2.0 * v - 1.0
        phi = 2.0 * np.pi * w
        w = np.column_stack([np.sqrt(1 - z**2) * np.cos(phi), np.sqrt(1 - z**2) * np.sin(phi), z])
        t = np.clip(1.2 * u - 0.1, 0.0, 1.0)  # a share on each cap's pole
        return p0 + t[:, None] * (p1 - p0) + r * w
    if kind == "cylinder":
        p0, p1, r = body["p0"], body["p1"], body["r"]
        span = p1 - p0
        h = np.linalg.norm(span)
        a = span / h
        e1 = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(a, e1)
        s = u * (2 * r + h)  # bottom cap outward, side upward, top cap inward
        radius = np.where(s < r, s, np.where(s < r + h, r, 2 * r + h - s))
        height = np.clip(s - r, 0.0, h)
        phi = 2.0 * np.pi * v
        return p0 + height[:, None] * a + radius[:, None] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    lo, hi = body["lo"], body["hi"]
    axis, side = face % 3, face // 3
    point = lo + (hi - lo) * np.column_stack([u, v, u])
    point[:, 1] = np.where(axis == 0, lo[1] + (hi[1] - lo[1]) * u, point[:, 1])
    point[:, 2] = np.where(axis == 0, lo[2] + (hi[2] - lo[2]) * v, np.where(axis == 1, lo[2] + (hi[2] - lo[2]) * v,
                                                                              point[:, 2]))
    point[np.arange(len(u)), axis] = np.where(side == 1, hi[axis], lo[axis])
    return point


def brute_force(kind_a: str, a: dict, kind_b: str, b: dict, rng: np.random.Generator) -> tuple[float, float]:
    """The least sampled distance (an upper bound of the true one) and the fine cloud's spacing bound."""
    u, v, w, f = rng.random(60_000), rng.random(60_000), rng.random(60_000), rng.integers(0, 6, 60_000)
    d = point_distance(kind_b, b, surface(kind_a, a, u, v, w, f))
    k = int(np.argmin(d))
    best, at, face = float(d[k]), np.array([u[k], v[k], w[k]]), f[k]
    for spread in (0.05, 0.012, 0.003):  # a shrinking cloud about the best point so far
        near = np.clip(at + spread * (rng.random((20_000, 3)) - 0.5), 0.0, 1.0)
        cloud = surface(kind_a, a, *near.T, np.full(20_000, face))
        d_near = point_distance(kind_b, b, cloud)
        k = int(np.argmin(d_near))
        if d_near[k] < best:
            best, at = float(d_near[k]), near[k]
    size = max(np.ptp(cloud, axis=0).max(), 1e-9)
    return best, 3.0 * size / np.sqrt(20_000)


def random_body(kind: str, rng: np.random.Generator, centre: np.ndarray) -> dict:
    if kind == "box":
        half = rng.uniform(2.0, 60.0, 3)
        return {"lo": centre - half, "hi": centre + half}
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    half = rng.uniform(1.0, 80.0)
    return {"p0": centre - half * direction, "p1": centre + half * direction, "r": rng.uniform(1.0, 40.0)}


def as_batch(kind: str, bodies: list[dict]):
    if kind == "box":
        return Boxes(np.array([b["lo"] for b in bodies]), np.array([b["hi"] for b in bodies]))
    make = Capsules if kind == "capsule" else Cylinders
    return make(np.array([b["p0"] for b in bodies]), np.array([b["p1"] for b in bodies]),
                np.array([b["r"] for b in bodies]))


@pytest.mark.parametrize(("kind_a", "kind_b"), [("capsule", "capsule"), ("capsule", "box"), ("cylinder", "box"),
                                                ("cylinder", "cylinder"), ("cylinder", "capsule")])
def test_distance_is_a_lower_bound_within_the_sampling_of_brute_force(kind_a: str, kind_b: str) -> None:
    rng = np.random.default_rng(zlib.crc32(f"{kind_a} {kind_b}".encode()))
    a_list, b_list = [], []
    for _ in range(PAIRS):
        a_list.append(random_body(kind_a, rng, np.zeros(3)))
        b_list.append(random_body(kind_b, rng, rng.uniform(-110.0, 110.0, 3)))
    found = distance(as_batch(kind_a, a_list), as_batch(kind_b, b_list))
    apart = 0
    for k in range(PAIRS):
        truth_above, spacing = brute_force(kind_a, a_list[k], kind_b, b_list[k], rng)
        # never more than the truth (the truth is at most the sampled least distance)
        assert found[k] <= truth_above + 1e-6, (k, found[k], truth_above)
        if truth_above > 0:
            apart += 1
            assert found[k] >= truth_above - spacing - 0.02, (k, found[k], truth_above, spacing)
    assert 0.2 * PAIRS < apart < 0.95 * PAIRS  # both meeting and separated pairs were drawn


def test_bodies_that_overlap_have_distance_zero() -> None:
    rng = np.random.default_rng(5)
    for kind_a, kind_b in [("capsule", "box"), ("cylinder", "box"), ("cylinder", "cylinder")]:
        a = [random_body(kind_a, rng, np.zeros(3)) for _ in range(200)]
        # B's centre on A's axis: inside A, so they overlap
        b = [random_body(kind_b, rng, (x["p0"] + x["p1"]) / 2 + rng.uniform(-0.5, 0.5, 3)) for x in a]
        assert np.all(distance(as_batch(kind_a, a), as_batch(kind_b, b)) == 0.0)


def test_the_head_bodies_sit_on_the_tool_axis_from_the_tip(machine: vp.Machine) -> None:
    """Tip and axis of the placed head (table frame) against the independent FK route: the table
    transform of tests/independent.py and the platform pose."""
    joints = random_usable_joints(machine, 3000, seed=11, tool_length=80.0)
    g = machine.kinematic_geometry(80.0)
    module = module_fk_working(g, joints[:, :3])
    stack = tool_stack(machine.bodies, 80.0, 12.0)
    n = len(joints)
    placed = place(machine.bodies, g, joints, module.platform, module.alpha, np.full(n, g.delta),
                   np.tile(stack.start, (n, 1)), np.tile(stack.end, (n, 1)))
    fk = vp.forward_kinematics(machine, joints, tool_length=80.0)
    assert np.allclose(placed.head[:, 0, 0], fk.tip, atol=1e-9)
    span = placed.head[:, -1, 1] - placed.head[:, 0, 0]
    assert np.allclose(span / np.linalg.norm(span, axis=1, keepdims=True), fk.axis, atol=1e-9)
    # the platform's link (base frame) back into the table frame by the independent transform
    transform = table_transform(g, joints[:, 3], joints[:, 4])  # table -> base, (N, 4, 4)
    centre = 0.5 * (placed.links[:, 4, 0] + placed.links[:, 4, 1])
    back = np.einsum("nji,nj->ni", transform[:, :3, :3], centre - transform[:, :3, 3])
    assert np.allclose(back, 0.5 * (placed.platform_table[:, 0] + placed.platform_table[:, 1]), atol=1e-9)
    # the rods end at their joint centres: each as long as its leg's rods (the paper's L1, L2, L3)
    # with its round ends, its axis its diameter shorter
    lengths = np.linalg.norm(placed.links[:, :4, 1] - placed.links[:, :4, 0], axis=2)
    radii = link_radii(machine.bodies)[:4]
    assert np.allclose(lengths + 2.0 * radii, [g.L1, g.L1, g.L2, g.L3], atol=1e-6)


def test_capsules_shrunk_to_points_and_parallel_ones_against_brute_force() -> None:
    """The closed-form capsule distance where its formula divides by little: a capsule that is a
    sphere (a zero-length axis) on either side, and parallel axes."""
    rng = np.random.default_rng(17)
    n = 300
    p0, q0 = rng.uniform(-50, 50, (n, 3)), rng.uniform(-50, 50, (n, 3))
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    length = rng.uniform(0.0, 60.0, (n, 1))
    cases = [(p0, p0, q0, q0 + direction * length), (p0, p0 + direction * length, q0, q0),
             (p0, p0 + direction * length, q0, q0 + direction * rng.uniform(1.0, 60.0, (n, 1)))]
    s = np.linspace(0.0, 1.0, 2001)
    for a0, a1, b0, b1 in cases:
        ra, rb = rng.uniform(0.5, 10.0, n), rng.uniform(0.5, 10.0, n)
        found = distance(Capsules(a0, a1, ra), Capsules(b0, b1, rb))
        for k in range(0, n, 10):
            pts = a0[k] + s[:, None] * (a1[k] - a0[k])
            axis = (np.linalg.norm(pts - b0[k], axis=1) if np.array_equal(b0[k], b1[k])
                    else _to_segment(pts, b0[k], b1[k]))
            truth = max(float(axis.min()) - ra[k] - rb[k], 0.0)
            spacing = float(np.linalg.norm(a1[k] - a0[k])) / 2000
            assert truth - spacing - 1e-9 <= found[k] <= truth + 1e-9, (k, found[k], truth)
