"""LinuxCNC: the machine's configuration for LinuxCNC 2.9 (``export``) and a program run through
LinuxCNC's own planner, headless (``simulate``). docs/linuxcnc.md."""

from .export import export_config
from .simulate import SimulationResult, simulate

__all__ = ["SimulationResult", "export_config", "simulate"]
