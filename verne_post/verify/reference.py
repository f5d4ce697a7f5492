"""What a program is verified against and what the verification finds: the CL path's poses
(:class:`Reference`), one finding (:class:`Finding`), and the tolerances and slacks of the checks."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, replace

import numpy as np

from ..cl.toolpath import Toolpath
from ..motion.poses import MachinePoses

DEFAULT_TOL = 0.005  # mm, when neither the caller nor the program header gives one
DEFAULT_AXIS_TOL = 0.05  # deg
FIRST_INTERVALS = 3
MAX_INTERVALS = 256
SAMPLING_SHARE = 0.1
RAPID_INTERVALS = 32
DEFAULT_RAPID_TOL = 0.5  # mm: a rapid's tip from its CL line, when neither caller nor header gives one
#: mm: how far below its CL line a rapid may pass: the rounding of the written joints and the
#: forward kinematics' convergence, no more (a rapid never approaches the part on the way).
RAPID_DIP_TOL = 1e-3
#: mm: a DELTA comment further than this from spindle nose + LENGTH is a finding (the joints
#: were computed for another tool length, which moves the tip by that much along the axis).
DELTA_TOL = 1e-3
#: Relative slack on the programmed feed and the joint velocity limits for the rounding of the
#: written numbers (block ends to 1e-4 mm, F to its decimals).
FEED_SLACK = 0.01
JOINT_SPEED_SLACK = 0.01
#: mm: what the rounding of a block's two ends can add to its tip path. Sliders are written to
#: 1e-4 mm and angles to 1e-5 deg (about 1e-4 mm at the table's reach): each end may sit up to
#: ~2e-4 mm from the planned pose, so a block of a few micrometres can look several per cent
#: faster than planned without being so. Absolute, so it matters only for tiny blocks.
FEED_LENGTH_SLACK = 5e-4
#: mm: a CL move whose tip travels less than this turns on the spot (as the planner's TIP_EPS).
STILL_TIP = 1e-4
#: Point-segment pairs and poses evaluated at once (bound the memory of a long program).
PAIR_CHUNK = 1 << 17
POSE_CHUNK = 1 << 15

JOINT_WORDS = ("slider rho1", "slider rho2", "slider rho3", "tilt theta1", "rotary theta2")


@dataclass(frozen=True)
class Reference:
    """The CL path a program must follow, in the table frame: as :class:`.toolpath.Toolpath`
    (``tip`` (N, 3) mm, unit ``axis``, ``line``, ``rapid``, ``feed`` mm/min or 1/min where
    ``inverse_time``)."""

    source: str
    tip: np.ndarray
    axis: np.ndarray
    line: np.ndarray
    rapid: np.ndarray
    feed: np.ndarray
    inverse_time: np.ndarray

    @classmethod
    def of(cls, path: Toolpath | MachinePoses, work_offset: Iterable[float] = (0.0, 0.0, 0.0)) -> Reference:
        """From a CL toolpath (part frame) and the work offset (mm), or from machine poses
        (already in the table frame: offset 0)."""
        return cls(path.source, np.asarray(path.tip, float) + np.asarray(tuple(work_offset), float), path.axis,
                   path.line, path.rapid, path.feed, path.inverse_time)

    def rows(self, index: slice | np.ndarray) -> Reference:
        return replace(self, **{name: getattr(self, name)[index] for name in _POSE_FIELDS})

    def then(self, other: Reference) -> Reference:
        """These poses, then those of ``other``."""
        return replace(self, **{name: np.concatenate([getattr(self, name), getattr(other, name)])
                                for name in _POSE_FIELDS})


_POSE_FIELDS = ("tip", "axis", "line", "rapid", "feed", "inverse_time")


@dataclass(frozen=True)
class Finding:
    """Something the program does wrong, at a G-code line (and the CL line it concerns)."""

    line: int
    kind: str  # program, tool, limit, unreachable, rod_clearance, singular, joint_speed, reach, order, motion,
    #            collision, tip, axis, feed
    message: str
    cl_line: int | None = None
    value: float | None = None  # the figure found (mm, deg, ratio or margin, as the message says)
    limit: float | None = None
