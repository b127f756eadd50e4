"""The executor: plays a motion file on an arm (the virtual lab, or a UR arm over
ur_rtde), after checking it against the joint limits.
"""
from .executor import execute, lab_module

__all__ = ["execute", "lab_module"]
