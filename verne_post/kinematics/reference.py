"""The reference pose check of a geometry: do these numbers describe a working VERNE?"""

from __future__ import annotations

import numpy as np

from .full import machine_ik_all, machine_ik_working
from .geometry import Geometry


def reference_pose_problem(geom: Geometry) -> str | None:
    """Why the reference pose (tool tip at the table origin, axis along the table normal, no tool:
    the spindle nose at the origin) is not reachable in the working mode, or None where it is.
    Otherwise the numbers describe no working VERNE, whatever the joint limits; the machine
    file's validation refuses them with this reason."""
    tip, axis = np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]])
    if machine_ik_working(geom, tip, axis).reachable[0]:
        return None
    if len(machine_ik_all(geom, tip, axis).alpha) == 0:
        why = "no assembly of the legs reaches it (rod lengths L1, L2, L3 against da, dt and spindle_nose)"
    else:
        why = "it is reached only outside the working mode (a slider below its platform point, or leg I rods " \
              "crossed)"
    return (f"the reference pose (spindle nose at the table origin, axis along the table normal) is not "
            f"reachable in the working mode: {why}")
