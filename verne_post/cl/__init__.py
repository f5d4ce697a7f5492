"""CL readers: APT/CLSF cutter-location files and CSV pose lists into a :class:`~verne_post.cl.toolpath.Toolpath`."""

from .reader import read_cl, read_pose_csv, read_toolpath

__all__ = ["read_cl", "read_pose_csv", "read_toolpath"]
