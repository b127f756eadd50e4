"""Parameter estimation (eqs. 2-6): the evaluation value E, the trial's problem, the
search (the paper's random search, CMA-ES, differential evolution) and its diagnostics; and
the next-motion prediction error (an estimate predicting the next trial, :mod:`.prediction`).
"""
from .estimation import Fit, fit_tracks, run_estimation
from .inertia import string_response
from .prediction import run_prediction
from .problem import build_problem, make_objective, simulate_fit

__all__ = ["Fit", "build_problem", "fit_tracks", "make_objective", "run_estimation", "run_prediction", "simulate_fit",
           "string_response"]
