"""Parameter estimation (eqs. 2-6): the evaluation value E, the trial's problem, the
search (the paper's random search, CMA-ES, differential evolution) and its diagnostics.
"""
from .estimation import run_estimation

__all__ = ["run_estimation"]
