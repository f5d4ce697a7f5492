"""verne-post: postprocessor for the VERNE hybrid parallel/serial 5-axis machine tool.

Library entry points (mm, radians inside arrays; table frame for tool poses)::

    machine = verne_post.load_machine()            # the shipped VERNE, or a YAML path
    ik = verne_post.inverse_kinematics(machine, tip, axis)
    fk = verne_post.forward_kinematics(machine, ik.joints)
    results = verne_post.batch(["parts/"], None, verne_post.BatchOptions(), output_dir="posted")
"""

from .api import (
    FKResult,
    IKResult,
    Status,
    forward_kinematics,
    forward_kinematics_all,
    inverse_kinematics,
    inverse_kinematics_all,
    inverse_kinematics_pairs,
    within_limits,
)
from .batch import BatchOptions, BatchResult, batch
from .kinematics import module_fk_all, module_fk_working, module_ik_all, module_ik_working
from .machine import Geometry, Machine, load_machine
from .placement.workspace import workspace
from .version import __version__ as __version__  # re-exported: verne_post.__version__

__all__ = [
    "BatchOptions", "BatchResult", "FKResult", "Geometry", "IKResult", "Machine", "Status", "batch",
    "forward_kinematics", "forward_kinematics_all", "inverse_kinematics", "inverse_kinematics_all",
    "inverse_kinematics_pairs", "load_machine", "module_fk_all", "module_fk_working", "module_ik_all",
    "module_ik_working", "within_limits", "workspace",
]
