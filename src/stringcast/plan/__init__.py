"""Motion generation (Section V): eq. (1) joint curves, the model's prediction of a
candidate, the planners (the paper's and the robust one) and the residual correction.
"""
from .planning import run_first_plan, run_plan

__all__ = ["run_first_plan", "run_plan"]
