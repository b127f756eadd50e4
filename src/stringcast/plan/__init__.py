"""Motion generation (Section V): eq. (1) joint curves, the model's prediction of a
candidate, the planners (the paper's and the robust one) and the residual correction.
"""
from .next_motion import NextMotion, plan_next, run_plan
from .planning import run_first_plan

__all__ = ["NextMotion", "plan_next", "run_first_plan", "run_plan"]
