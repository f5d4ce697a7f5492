"""The 3D view's scene (:mod:`verne_post.report.scene3d`) of a posted program: the table, the
cradle, the setup, the head's bodies and the platform at up to MAX_FRAMES block ends (the
contacts' blocks always among them), the tool path with each block's certified clearance, and
the collisions and near misses the check found. Everything in the table frame, mm; the cradle
turns in it by -theta2, the head and the platform move.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..bodies.world import cutting, plain
from ..checks.collision import tool_use_of_poses, world_of
from ..machine import Machine

#: Frames and path points of a posted program's scene: the page of a 36,000-block job stays
#: under a megabyte (tests/test_report_html.py).
FRAMES = 600
PATH_POINTS = 6000

if TYPE_CHECKING:
    from ..pipeline import PostResult

_GROUPS = {"cutter": "tool", "shank": "tool", "spindle": "head", "platform": "head"}


def _frames(count: int, keep: np.ndarray, limit: int) -> np.ndarray:
    """Up to ``limit`` block indices evenly over ``count``, with ``keep`` among them."""
    even = np.linspace(0, count - 1, min(count, max(limit - len(keep), 2))).astype(int)
    return np.unique(np.concatenate([even, keep]))[: max(limit, len(keep))]


def post_scene(machine: Machine, result: PostResult) -> dict | None:
    """The scene of ``result``'s blocks; None where the machine file turns the bodies' check off
    or there are no blocks."""
    blocks, poses = result.blocks, result.poses
    if not machine.bodies.check or not len(blocks.pose):
        return None
    world = world_of(machine, poses)
    stack = tool_use_of_poses(poses)[blocks.pose]
    radius = max(float(s.radius[0]) for s in world.stacks)
    clearance = world.clearance(blocks.joints, stack, cutting(poses.setup, blocks.tip, result.rapid, radius))
    contacts = sorted(clearance.contacts, key=lambda c: c.clearance)[:500]
    keep = np.unique(np.array([c.block for c in contacts], dtype=int))
    chosen = _frames(len(blocks.pose), keep, FRAMES)
    placed = world.sampler()(blocks.joints[chosen], stack[chosen], None)
    # a block end out of reach (a program with violations) has no bodies to draw
    drawn = np.all([np.isfinite(v).all(axis=(1, 2)) for v in placed.bodies.values()], axis=0)
    if not drawn.any():
        return None
    if not drawn.all():
        chosen = chosen[drawn]
        placed = world.sampler()(blocks.joints[chosen], stack[chosen], None)
        contacts = [c for c in contacts if c.block in set(chosen.tolist())]
    ends = np.cumsum(np.nan_to_num(result.duration))  # s: when each block ends
    slots = world.slots
    moving = [{"name": name, "group": _GROUPS.get(name, "holder"), "kind": "cylinder",
               "radius": float(np.nanmax(placed.radius[f"{name}@table"]))} for name in slots]
    moving.append({"name": "platform", "group": "head", "kind": "capsule",
                   "radius": float(placed.radius["platform@table"][0])})
    pose_parts = [placed.bodies[f"{name}@table"].reshape(len(chosen), 6) for name in [*slots, "platform"]]
    theta2 = machine.geom.true_joints(blocks.joints[chosen])[:, 4]
    c, s = np.cos(theta2), np.sin(theta2)
    turn = np.stack([np.stack([c, s, 0 * c], -1), np.stack([-s, c, 0 * c], -1),
                     np.stack([0 * c, 0 * c, 1 + 0 * c], -1)], -2)  # cradle -> table: Rz(theta2)^T
    for box in machine.bodies.cradle:
        lo, hi = np.asarray(box.lo), np.asarray(box.hi)
        centre = np.einsum("nij,j->ni", turn, 0.5 * (lo + hi))
        moving.append({"name": box.name, "group": "machine", "kind": "box", "half": (0.5 * (hi - lo)).tolist()})
        pose_parts.append(np.hstack([centre, turn.reshape(len(chosen), 9)]))
    table = machine.bodies.table
    fixed = [{"name": "table", "group": "machine", "kind": "cylinder", "center": [0.0, 0.0],
              "z0": table.top - table.thickness, "z1": table.top, "radius": 0.5 * table.diameter}]
    for body in poses.setup.bodies:
        group = "stock" if body.role == "stock" else "fixture"
        if body.kind == "box":
            fixed.append({"name": body.name, "group": group, "kind": "box", "lo": list(body.lo), "hi": list(body.hi)})
        else:
            fixed.append({"name": body.name, "group": group, "kind": "cylinder",
                          "center": [0.5 * (body.lo[0] + body.hi[0]), 0.5 * (body.lo[1] + body.hi[1])],
                          "z0": body.lo[2], "z1": body.hi[2], "radius": body.radius})
    frame_of_block = np.clip(np.searchsorted(chosen, np.arange(len(blocks.pose))), 0, len(chosen) - 1)
    points = np.unique(np.concatenate([np.linspace(0, len(blocks.pose) - 1,
                                                   min(len(blocks.pose), PATH_POINTS)).astype(int), keep]))
    points = points[np.isfinite(blocks.tip[points]).all(axis=1)]
    smallest = clearance.smallest
    findings = [{"severity": "collision" if c.clearance <= 0 else "near miss",
                 "bodies": [plain(c.moving), plain(c.other)], "clearance": float(c.clearance),
                 "line": int(poses.line[blocks.pose[c.block]]), "xyz": blocks.tip[c.block].tolist(),
                 "frame": int(frame_of_block[c.block])} for c in contacts]
    return {"units": "mm", "frame": "table", "margin": machine.bodies.margin, "fixed": fixed, "moving": moving,
            "frames": {"t": ends[chosen].tolist(), "line": poses.line[blocks.pose[chosen]].tolist(),
                       "poses": np.hstack(pose_parts).tolist()},
            "path": {"xyz": blocks.tip[points].ravel().tolist(),
                     "clearance": [None if not v < clearance.cap else float(v) for v in smallest[points]],
                     "rapid": result.rapid[points].tolist(), "frame": frame_of_block[points].tolist()},
            "clearance": {"t": ends.tolist(), "mm": [None if not v < clearance.cap else float(v) for v in smallest]},
            "findings": findings}
