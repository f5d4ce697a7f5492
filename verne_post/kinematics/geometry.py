"""The VERNE's kinematic parameters: the record every kinematics function takes.

The kinematics own their parameter record (as opw_kinematics does) so that they import nothing
else of verne_post: the machine file (:mod:`verne_post.machine`) builds a :class:`Geometry` and
asks the kinematics about it, never the other way round.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np


@dataclass(frozen=True)
class Geometry:
    """Identified dimensions of the VERNE (mm), paper notation; ``delta`` = P to tool tip.

    ``delta`` = ``spindle_nose`` + ``tool_length``. Only the differences D1-d1 and D2-d2 enter
    the closure equations (paper eq. 3-5).

    ``rho_offset`` (mm) and ``theta_offset`` (rad) are the joint zero offsets: the true joint
    position is the controller's reading plus the offset. Every public kinematics function
    takes and returns joint *readings*; the offsets are applied inside (all zero: the
    readings are the true positions, and no arithmetic is done on them at all).
    """

    D1_minus_d1: float
    D2_minus_d2: float
    R1: float
    r1: float
    L1: float
    R2: float
    r4: float
    L2: float
    L3: float
    spindle_nose: float
    da: float
    dt: float
    tool_length: float = 0.0
    rho_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    theta_offset: tuple[float, float] = (0.0, 0.0)

    @property
    def has_offsets(self) -> bool:
        """True where any joint zero offset is non-zero."""
        return any(self.rho_offset) or any(self.theta_offset)

    def _offsets(self, width: int) -> np.ndarray:
        return np.array((*self.rho_offset, *self.theta_offset)[:width], dtype=float)

    def true_joints(self, joints: np.ndarray) -> np.ndarray:
        """True joint positions from readings (N, 3) rho mm or (N, 5) rho mm, theta rad.

        Returns ``joints`` itself when every offset is zero (outputs stay bit-identical).
        """
        if not self.has_offsets:
            return joints
        joints = np.asarray(joints, dtype=float)
        return joints + self._offsets(joints.shape[-1])

    def readings(self, joints: np.ndarray) -> np.ndarray:
        """Controller readings from true joint positions, (N, 3) or (N, 5); inverse of :meth:`true_joints`."""
        if not self.has_offsets:
            return joints
        joints = np.asarray(joints, dtype=float)
        return joints - self._offsets(joints.shape[-1])

    @property
    def delta(self) -> float:
        """Distance from the platform centre P to the tool tip U (mm)."""
        return self.spindle_nose + self.tool_length

    @property
    def alpha_max(self) -> float:
        """Largest |alpha| (rad) without rod crossing in leg I: R1 cos(alpha) > r1."""
        return math.acos(self.r1 / self.R1)

    def with_tool_length(self, tool_length: float) -> Geometry:
        return replace(self, tool_length=float(tool_length))
