"""Identification model: the tool tip predicted by the forward kinematics as a function of the
machine's parameters, and its analytic Jacobian over all poses at once.

Parameters (:data:`PARAMETERS`): the 12 geometry values of the machine file (mm), the three
slider zero offsets (mm) and the two table-angle zero offsets (carried in rad inside, degrees in
the machine file). Joints are the controller's readings (rho mm, theta rad); tips in mm and
axes as unit vectors, both in the table frame. Pure: no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..kinematics import module_fk_working, tool_pose
from ..machine import Geometry, Machine

GEOMETRY_NAMES = ("D1_minus_d1", "D2_minus_d2", "R1", "r1", "L1", "R2", "r4", "L2", "L3", "spindle_nose", "da", "dt")
OFFSET_NAMES = ("rho1_offset", "rho2_offset", "rho3_offset", "theta1_offset", "theta2_offset")
#: Every parameter the calibration knows, in the order of the parameter vector.
PARAMETERS = GEOMETRY_NAMES + OFFSET_NAMES
ANGLE_PARAMETERS = ("theta1_offset", "theta2_offset")

#: Typical size of each parameter's error, in its internal unit (mm, rad): 1 mm for the lengths
#: and the slider zeros, 1 mrad (0.057 deg) for the table-angle zeros. The fit's variables are
#: the parameters divided by these, and its prior toward the machine file has this standard
#: deviation: it decides only what the measurements leave open.
SCALE = np.array([1.0] * 15 + [1e-3] * 2)

#: Each parameter in the shop's words (reports and messages).
WORDS = {"D1_minus_d1": "leg I's x offset D1-d1", "D2_minus_d2": "legs II-III's x offset D2-d2",
         "R1": "leg I's platform joint spacing R1", "r1": "leg I's slider joint spacing r1",
         "L1": "leg I's rod length L1", "R2": "legs II-III's platform joint spacing R2",
         "r4": "legs II-III's slider joint spacing r4", "L2": "leg II's rod length L2", "L3": "leg III's rod length L3",
         "spindle_nose": "the spindle nose distance", "da": "the table height da",
         "dt": "the table's distance dt from the tilt axis", "rho1_offset": "slider 1's zero",
         "rho2_offset": "slider 2's zero", "rho3_offset": "slider 3's zero", "theta1_offset": "the tilt (A) zero",
         "theta2_offset": "the rotary table's (C) zero"}

#: Weight of a measured tool axis against a tip coordinate: an axis error of 1 rad counts as
#: this many mm (10 um per 0.1 mrad, about what a tracker's 6-DOF probe resolves).
AXIS_LENGTH = 100.0

#: Residual (mm) given to a pose that has no working assembly at a trial geometry: large, so
#: the trust region steps back, and finite, so the solver can go on.
UNREACHABLE_RESIDUAL = 1e3


def unit(name: str) -> str:
    """Unit of a parameter at the interface (machine file, report)."""
    return "deg" if name in ANGLE_PARAMETERS else "mm"


def to_interface(name: str, value: float) -> float:
    """Internal value (mm, rad) in the interface unit (mm, degrees)."""
    return math.degrees(value) if name in ANGLE_PARAMETERS else value


def parameters_of(machine: Machine) -> np.ndarray:
    """The parameter vector (17,) of a machine: mm, and rad for the angle offsets."""
    g, j = machine.geometry, machine.joints
    return np.array([*(getattr(g, n) for n in GEOMETRY_NAMES), j.rho1.offset, j.rho2.offset, j.rho3.offset,
                     math.radians(j.theta1.offset), math.radians(j.theta2.offset)], dtype=float)


def geometry_of(p: np.ndarray) -> Geometry:
    """:class:`Geometry` (tool length 0) of a parameter vector (mm, rad)."""
    values = [float(v) for v in p]
    return Geometry(*values[:12], rho_offset=tuple(values[12:15]), theta_offset=tuple(values[15:17]))


@dataclass(frozen=True)
class Poses:
    """Measured poses: joint readings (N, 5) rho mm / theta rad, tool lengths (N,) mm, measured
    tips (N, 3) mm and axes (N, 3) (NaN rows where not measured) in the table frame, weights (N,)."""

    joints: np.ndarray
    tool_length: np.ndarray
    tip: np.ndarray
    axis: np.ndarray
    weight: np.ndarray

    def __len__(self) -> int:
        return len(self.tool_length)

    def take(self, rows: np.ndarray) -> Poses:
        return Poses(self.joints[rows], self.tool_length[rows], self.tip[rows], self.axis[rows], self.weight[rows])

    @property
    def has_axis(self) -> np.ndarray:
        return np.all(np.isfinite(self.axis), axis=1)


@dataclass(frozen=True)
class Prediction:
    """Forward kinematics of the poses at one parameter vector (table frame, mm)."""

    tip: np.ndarray  # (N, 3)
    axis: np.ndarray  # (N, 3)
    platform: np.ndarray  # (N, 3) base frame
    alpha: np.ndarray  # (N,) rad
    reachable: np.ndarray  # (N,) bool


def predict(p: np.ndarray, joints: np.ndarray, tool_length: np.ndarray, alpha_guess: np.ndarray | None = None
            ) -> Prediction:
    """Tool tips (N, 3) mm and axes in the table frame at parameters ``p`` for readings (N, 5);
    ``alpha_guess`` (N,) rad, the platform's tilt at nearby parameters, makes it faster."""
    geom = geometry_of(p)
    module = module_fk_working(geom, joints[:, :3], alpha_guess)
    true = joints + np.r_[0.0, 0.0, 0.0, p[15:17]]
    tip, axis = tool_pose(geom, module.platform, module.alpha, true[:, 3], true[:, 4],
                          delta=geom.spindle_nose + tool_length)
    return Prediction(tip, axis, module.platform, module.alpha, module.reachable)


def jacobian(p: np.ndarray, joints: np.ndarray, tool_length: np.ndarray, fk: Prediction
             ) -> tuple[np.ndarray, np.ndarray]:
    """d(tip)/dp (N, 3, 17) mm per unit parameter and d(axis)/dp (N, 3, 17), table frame.

    The module's pose (xP, yP, zP, alpha) depends on the parameters through the four closure
    equations f = |rod|^2 - L^2 = 0: by the implicit function theorem d(pose)/dp =
    -(df/dpose)^-1 df/dp, with df/dpose the matrix A of the module Jacobian (rods and their
    alpha derivative). The tip then follows eq. 32-33 explicitly. Rows of unreachable poses are 0.
    """
    g = geometry_of(p)
    n = len(tool_length)
    ok = fk.reachable
    platform = np.where(ok[:, None], fk.platform, 0.0)
    alpha = np.where(ok, fk.alpha, 0.0)
    c, s = np.cos(alpha), np.sin(alpha)
    true = joints + np.r_[p[12:17]]
    rho = true[:, :3]
    # Rods 1a, 1b, II, III: B - A with B the platform point, A the slider point (true heights).
    big_y = np.array([g.R1, -g.R1, -g.R2, g.R2])
    small_y = np.array([g.r1, -g.r1, -g.r4, g.r4])
    dx = np.array([g.D1_minus_d1, g.D1_minus_d1, g.D2_minus_d2, g.D2_minus_d2])
    rod_x = platform[:, :1] + dx
    rod_y = platform[:, 1:2] + big_y * c[:, None] - small_y
    rod_z = platform[:, 2:3] + big_y * s[:, None] - rho[:, [0, 0, 1, 2]]
    d_alpha = rod_y * (-big_y * s[:, None]) + rod_z * (big_y * c[:, None])
    a = np.stack([rod_x, rod_y, rod_z, d_alpha], axis=-1)  # (N, 4, 4): half of df/d(x, y, z, alpha)
    # Half of df/dp (N, 4, 17), column by column.
    f = np.zeros((n, 4, len(PARAMETERS)))
    turn = rod_y * c[:, None] + rod_z * s[:, None]  # d(rod)/dY . rod per unit platform-point offset
    f[:, 0:2, 0] = rod_x[:, 0:2]
    f[:, 2:4, 1] = rod_x[:, 2:4]
    f[:, 0, 2], f[:, 1, 2] = turn[:, 0], -turn[:, 1]  # R1: Y = +R1, -R1
    f[:, 0, 3], f[:, 1, 3] = -rod_y[:, 0], rod_y[:, 1]  # r1: slider y = +r1, -r1
    f[:, 0:2, 4] = -g.L1
    f[:, 2, 5], f[:, 3, 5] = -turn[:, 2], turn[:, 3]  # R2: Y = -R2, +R2
    f[:, 2, 6], f[:, 3, 6] = rod_y[:, 2], -rod_y[:, 3]  # r4: slider y = -r4, +r4
    f[:, 2, 7] = -g.L2
    f[:, 3, 8] = -g.L3
    f[:, 0:2, 12] = -rod_z[:, 0:2]  # slider offsets move the slider points
    f[:, 2, 13] = -rod_z[:, 2]
    f[:, 3, 14] = -rod_z[:, 3]
    a[~ok] = np.eye(4)  # keeps the solve regular; those rows are zeroed below
    d_pose = -np.linalg.solve(a, f)  # (N, 4, 17): d(xP, yP, zP, alpha)/dp

    # Explicit dependence of (xP, lateral, tip z) on v = (xP, yP, zP, alpha, theta1, Delta, da, dt).
    y, z = platform[:, 1], platform[:, 2]
    t1, t2 = true[:, 3], true[:, 4]
    c1, s1, c2, s2 = np.cos(t1), np.sin(t1), np.cos(t2), np.sin(t2)
    delta = g.spindle_nose + tool_length
    phi1 = alpha - t1
    cp, sp = np.cos(phi1), np.sin(phi1)
    zero, one = np.zeros(n), np.ones(n)
    d_x = np.stack([one, zero, zero, zero, zero, zero, zero, zero], -1)
    d_lat = np.stack([zero, -c1, -s1, delta * cp, -delta * cp + s1 * y - c1 * (z - g.da), sp, s1, zero], -1)
    d_tz = np.stack([zero, s1, -c1, delta * sp, c1 * y + s1 * z - g.da * s1 - delta * sp, -cp, c1, one], -1)
    # dv/dp (N, 8, 17)
    dv = np.zeros((n, 8, len(PARAMETERS)))
    dv[:, :4] = d_pose
    dv[:, 4, 15] = 1.0  # theta1 offset
    dv[:, 5, 9] = 1.0  # spindle nose
    dv[:, 6, 10] = 1.0  # da
    dv[:, 7, 11] = 1.0  # dt
    dx_p = np.einsum("nv,nvp->np", d_x, dv)
    dlat_p = np.einsum("nv,nvp->np", d_lat, dv)
    dtz_p = np.einsum("nv,nvp->np", d_tz, dv)
    d_tip = np.stack([c2[:, None] * dx_p + s2[:, None] * dlat_p, -s2[:, None] * dx_p + c2[:, None] * dlat_p, dtz_p],
                     axis=1)
    d_tip[:, 0, 16], d_tip[:, 1, 16] = fk.tip[:, 1], -fk.tip[:, 0]  # theta2 offset turns the table
    # Axis (-sin phi1 sin t2, -sin phi1 cos t2, cos phi1), phi1 = alpha - theta1.
    d_axis_phi1 = np.stack([-cp * s2, -cp * c2, -sp], -1)
    dphi1 = d_pose[:, 3] - dv[:, 4]
    d_axis = d_axis_phi1[:, :, None] * dphi1[:, None, :]
    d_axis[:, 0, 16], d_axis[:, 1, 16] = -sp * c2, sp * s2
    d_tip[~ok] = 0.0
    d_axis[~ok] = 0.0
    return d_tip, d_axis


__all__ = [
    "ANGLE_PARAMETERS",
    "AXIS_LENGTH",
    "GEOMETRY_NAMES",
    "OFFSET_NAMES",
    "PARAMETERS",
    "SCALE",
    "WORDS",
    "Poses",
    "Prediction",
    "geometry_of",
    "jacobian",
    "parameters_of",
    "predict",
    "to_interface",
    "unit",
]
