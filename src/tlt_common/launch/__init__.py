"""The launcher: start any set of processes from a YAML launch set (``tlt launch``)."""

from tlt_common.launch.launch_set import LaunchSet, ProcessSpec, load_launch_set
from tlt_common.launch.supervisor import Supervisor

__all__ = ["LaunchSet", "ProcessSpec", "Supervisor", "load_launch_set"]
