"""The report's figures of a program, gathered a part at a time, and the JSON report
(``--report PART.json``) made of them."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..api import JOINT_NAMES
from ..checks.limits import Violation
from ..cl.toolpath import Dwell
from ..machine import Machine
from ..motion.branch import PathIK
from ..motion.linearise import Blocks
from ..motion.poses import MachinePoses
from ..options import PostOptions, work_offset_in_force
from ..placement.search import Placement
from ..planning.stage import Timing
from ..version import __version__

_MARGINS = ("serial", "parallel", "machine", "rod_clearance")


@dataclass
class Figures:
    """The report's figures of a program's blocks, gathered a part at a time (:meth:`add`): mm,
    rad inside, seconds. The timing figures only where every part was planned."""

    blocks: int = 0
    inserted: int = 0
    in_pole_cone: int = 0
    cone_deviation: float = 0.0  # rad: largest axis deviation in the pole cone
    low: np.ndarray = field(default_factory=lambda: np.full(5, np.inf))  # joint ranges (finite blocks)
    high: np.ndarray = field(default_factory=lambda: np.full(5, -np.inf))
    margins: dict[str, float] = field(default_factory=lambda: dict.fromkeys(_MARGINS, np.inf))
    feed_length: float = 0.0
    rapid_length: float = 0.0
    time: float = 0.0  # s: sum of the block durations
    rapid_time: float = 0.0
    time_per_tool: dict[int, float] = field(default_factory=dict)
    planned: bool = True  # every part has a schedule
    budget: dict[str, float] = field(default_factory=dict)
    ratios: np.ndarray = field(default_factory=lambda: np.zeros((3, 5)))  # velocity, acceleration, jerk / limit

    def add(self, poses: MachinePoses, path: PathIK, first: int, blocks: Blocks, rapid: np.ndarray, timed: Timing,
            context: int = 0) -> None:
        """Add the figures of a part: the path of poses ``first``... and its blocks, their timing
        (with the planner's figures, if gathered); the first ``context`` blocks belong to the part
        before (the motion from there counts)."""
        own = slice(context, None)
        joints = blocks.joints[own]
        finite = joints[np.all(np.isfinite(joints), axis=1)]
        if len(finite):
            self.low, self.high = np.fmin(self.low, finite.min(axis=0)), np.fmax(self.high, finite.max(axis=0))
        self.blocks += len(joints)
        self.inserted += int(np.sum(blocks.fraction[own] != 1))
        self.in_pole_cone += int(path.in_cone.sum())
        axis = poses.axis[first:first + len(path.axis)]
        self.cone_deviation = max(self.cone_deviation, float(np.max(
            2 * np.arcsin(np.linalg.norm(path.axis - axis, axis=1) / 2), initial=0.0)))
        for name in _MARGINS:
            self.margins[name] = float(np.fmin(self.margins[name], np.nanmin(
                getattr(blocks.result.margins, name)[own], initial=np.inf)))
        step = np.linalg.norm(np.diff(blocks.tip, axis=0), axis=1)
        self.feed_length += float(np.sum(step[~rapid[1:]]))
        self.rapid_length += float(np.sum(step[rapid[1:]]))
        own_duration, own_rapid = timed.duration[own], rapid[own]
        self.time += float(np.sum(own_duration))
        self.rapid_time += float(np.sum(own_duration[own_rapid]))
        tools = poses.tool[blocks.pose[own]]
        for tool in np.unique(tools):
            self.time_per_tool[int(tool)] = self.time_per_tool.get(int(tool), 0.0) + float(
                np.sum(own_duration[tools == tool]))
        self.planned &= timed.planned
        if timed.ratios is not None and timed.budget is not None:
            self.ratios = np.maximum(self.ratios, timed.ratios)
            for name, value in timed.budget.items():
                self.budget[name] = self.budget.get(name, 0.0) + value


def _finite(value: float) -> float | None:
    return value if np.isfinite(value) else None


def report(machine: Machine, options: PostOptions, poses: MachinePoses, violations: list[Violation],
            warnings: list[str], figures: Figures, placement: Placement | None, seconds: dict[str, float]
            ) -> dict[str, Any]:
    """Summary statistics and every violation, JSON-ready (mm, degrees, seconds)."""
    scale = np.array([1.0, 1.0, 1.0, 180 / np.pi, 180 / np.pi])
    ranges = {name: [float(figures.low[j] * scale[j]), float(figures.high[j] * scale[j])]
              if figures.low[j] <= figures.high[j] else None for j, name in enumerate(JOINT_NAMES)}
    timing = None
    if figures.planned and figures.blocks:
        dwell = sum(e.seconds for e in poses.events if isinstance(e, Dwell))
        timing = {
            "cycle_time_s": figures.time + dwell,
            "dwell_time_s": dwell,
            "rapid_time_s": figures.rapid_time,
            **figures.budget,
            "time_per_tool_s": {str(t): figures.time_per_tool[t] for t in sorted(figures.time_per_tool)},
            "largest_ratio_to_limit": {name: dict(zip(("velocity", "acceleration", "jerk"),
                                                      map(float, figures.ratios[:, j]), strict=True))
                                       for j, name in enumerate(JOINT_NAMES)},
        }
    return {
        "source": poses.source,
        "dialect": poses.dialect,
        "machine": machine.source,
        "verne_post": __version__,
        "ok": not violations,
        "violations": [{"line": v.line, "kind": v.kind, "message": v.message} for v in violations],
        "warnings": warnings,
        "points": {"cl": len(poses), "inserted": figures.inserted, "blocks": figures.blocks,
                   "in_pole_cone": figures.in_pole_cone},
        "largest_axis_deviation_in_pole_cone_deg": float(np.degrees(figures.cone_deviation)),
        "joint_ranges": ranges,
        "joint_units": {"rho1": "mm", "rho2": "mm", "rho3": "mm", "theta1": "deg", "theta2": "deg"},
        "smallest_margins": {name: _finite(figures.margins[name]) for name in _MARGINS},
        "path_length_mm": {"feed": figures.feed_length, "rapid": figures.rapid_length},
        "estimated_time_s": figures.time,
        "tolerances": {"tip_mm": options.tol, "axis_deg": options.axis_tol, "arc_mm": options.arc_tol},
        "tools": [{"tool": t.number, "length_mm": t.length, "delta_mm": t.delta, "line": t.line,
                   "length_from": t.source} for t in poses.tools],
        "timing": timing,
        "work_offset_mm": list(placement.offset if placement else work_offset_in_force(machine, options)),
        "placement": None if placement is None else placement.to_dict(),
        "seconds": seconds,
    }
