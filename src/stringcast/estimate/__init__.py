"""Parameter estimation (eqs. 2-6): the evaluation value E, the trial's problem, the
search (the paper's random search, CMA-ES, differential evolution) and its diagnostics; and
the next-motion prediction error (an estimate predicting the next trial, :mod:`.prediction`).
"""
from .estimation import run_estimation
from .prediction import run_prediction

__all__ = ["run_estimation", "run_prediction"]
