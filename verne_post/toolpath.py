"""Plain data passed between the pipeline stages (parse -> IK -> checks -> linearise -> timing -> write).

Every array is indexed by pose (or by output block) and carries the CL source line of that pose,
so any stage can name the line at fault. Positions are in mm, angles inside arrays in radians.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

MIN_FEED = 1e-6  # mm/min (or 1/min inverse time): slower is a mistake, and rounds to 0 in the planner's mm/s
MOTION_KINDS = ("feed", "rapid", "arc", "spline", "cycle")  # what a pose's motion came from in the CL file


@dataclass(frozen=True)
class ToolChange:
    """Load tool ``tool`` before pose ``index``; ``length`` (mm) is the gauge length if the CL file gives it."""

    index: int
    line: int
    tool: int
    length: float | None = None
    diameter: float | None = None
    adjust: int | None = None


@dataclass(frozen=True)
class Spindle:
    """Spindle command before pose ``index``; ``rpm`` in rev/min."""

    index: int
    line: int
    rpm: float
    direction: Literal["CW", "CCW", "OFF"]


@dataclass(frozen=True)
class Coolant:
    """Coolant command before pose ``index``."""

    index: int
    line: int
    mode: Literal["ON", "FLOOD", "MIST", "THRU", "OFF"]


@dataclass(frozen=True)
class Comment:
    """Operator comment (PPRINT, TOOL PATH name, ...) before pose ``index``."""

    index: int
    line: int
    text: str


@dataclass(frozen=True)
class Stop:
    """Program stop before pose ``index``: ``optional`` is OPSTOP (M1), otherwise STOP (M0)."""

    index: int
    line: int
    optional: bool = False


@dataclass(frozen=True)
class Dwell:
    """Dwell of ``seconds`` (s) before pose ``index``, the tool standing still (a drilling cycle's pause)."""

    index: int
    line: int
    seconds: float


Event = ToolChange | Spindle | Coolant | Comment | Stop | Dwell


@dataclass(frozen=True)
class Toolpath:
    """Poses read from a CL or CSV file, in the part frame (MSYS/CSYS applied), mm.

    - ``tip`` (N, 3) mm: tool tip; ``axis`` (N, 3): unit tool axis, tip towards spindle.
    - ``line`` (N,): source line of each pose (1-based).
    - ``rapid`` (N,): the motion *into* pose k is a rapid (G0).
    - ``feed`` (N,): programmed feed of the motion into pose k in mm/min (NaN on rapids, or
      when ``inverse_time[k]``: then ``feed`` is the inverse-time value in 1/min).
    - ``tool`` (N,): tool number active at pose k (0 if none loaded yet).
    - ``events``: non-motion records in source order; ``event.index`` is the pose they precede
      (``N`` for records after the last motion).
    """

    source: str
    tip: np.ndarray
    axis: np.ndarray
    line: np.ndarray
    rapid: np.ndarray
    feed: np.ndarray
    tool: np.ndarray
    inverse_time: np.ndarray
    events: tuple[Event, ...] = ()
    part_name: str | None = None
    units: Literal["mm", "inch"] = "mm"
    warnings: tuple[str, ...] = field(default=())
    dialect: str = "CSV poses"  # the CAM dialect and conventions the reader applied
    motion: np.ndarray | None = None  # (N,) int8: how pose k is reached, an index into MOTION_KINDS
    notes: tuple[str, ...] = ()  # choices the reader made from options or by rule, for the program header
    frame_hint: str | None = None  # the --frame under which the tool would point away from the table, if not this

    def __len__(self) -> int:
        return int(self.tip.shape[0])
