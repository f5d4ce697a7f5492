"""What the controller adds to the plan: the block durations a controller's own planner cannot
beat, so that the header's cycle time is the controller's.

LinuxCNC 2.9 (read in its source, branch 2.9; docs/linuxcnc.md): a line that moves A or C gets no
tangent or arc blend and no lookahead (src/emc/tp/tp.c ``tcRotaryMotionCheck``,
``tpSetupTangent``, ``tpRunOptimization``): it is planned to end at rest, overlapped with the next
by a parabolic blend at half the acceleration (tc.c ``tcGetOverallMaxAccel``), the acceleration of
its slowest axis over its travel (src/emc/task/emccanon.cc ``getStraightAcceleration``). Such a
block takes at least

    T_min = sqrt(2 max_i |dq_i| / AMAX_i)

whatever its F (joints in mm and rad, AMAX the axes' accelerations as the exported configuration
gives them: the machine's joint limits). Measured on the impeller as posted: the durations
max(planned, T_min) add to 1644.9 s; LinuxCNC ran it in 1651-1660 s (planned 1192.5 s).
"""

from __future__ import annotations

import numpy as np

from .timing import Limits

#: Controllers whose planner is modelled here.
MODELLED = ("linuxcnc",)


def rotary_block_floor(joints: np.ndarray, limits: Limits) -> np.ndarray:
    """(M,) s: LinuxCNC's least duration of each block ending at ``joints`` (M, 5) mm and rad (the
    first block, whose start is not here, and blocks that move no rotary: 0)."""
    floor = np.zeros(len(joints))
    if len(joints) < 2:
        return floor
    step = np.abs(np.diff(joints, axis=0))
    rotary = np.any(step[:, 3:] > 0, axis=1)
    floor[1:] = np.where(rotary, np.sqrt(2.0 * np.max(step / np.asarray(limits.acceleration), axis=1)), 0.0)
    return floor
