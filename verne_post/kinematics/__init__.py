"""Pure kinematics of the VERNE: closed-form IK/FK of the parallel module and the whole machine.

No I/O here: functions over numpy arrays of a :class:`~verne_post.kinematics.geometry.Geometry`,
the one record of verne_post they import (they import nothing else of it).
"""

from .full import (
    MachineFK,
    MachineFKSolutions,
    MachineIK,
    MachineIKSolutions,
    axis_angles,
    axis_from_angles,
    machine_fk_all,
    machine_fk_working,
    machine_ik_all,
    machine_ik_working,
    tool_pose,
    unwrap_near,
    wrap_angle,
)
from .geometry import Geometry
from .jacobian import Margins, joint_rates, machine_jacobian, margins, module_jacobian, singularity_measures
from .module import (
    ModuleFK,
    ModuleFKSolutions,
    ModuleIK,
    ModuleIKSolutions,
    closure_residuals,
    coupling_cubic,
    coupling_ellipse,
    is_working_mode,
    module_fk_all,
    module_fk_working,
    module_ik_all,
    module_ik_working,
)
from .reference import reference_pose_problem

__all__ = [
    "Geometry",
    "MachineFK",
    "MachineFKSolutions",
    "MachineIK",
    "MachineIKSolutions",
    "Margins",
    "ModuleFK",
    "ModuleFKSolutions",
    "ModuleIK",
    "ModuleIKSolutions",
    "axis_angles",
    "axis_from_angles",
    "closure_residuals",
    "coupling_cubic",
    "coupling_ellipse",
    "is_working_mode",
    "joint_rates",
    "machine_fk_all",
    "machine_fk_working",
    "machine_ik_all",
    "machine_ik_working",
    "machine_jacobian",
    "margins",
    "module_fk_all",
    "module_fk_working",
    "module_ik_all",
    "module_ik_working",
    "module_jacobian",
    "reference_pose_problem",
    "singularity_measures",
    "tool_pose",
    "unwrap_near",
    "wrap_angle",
]
