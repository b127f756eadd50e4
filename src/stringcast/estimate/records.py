"""The estimate stage's records: the search's :class:`Estimate`, one trial's :class:`Fit`, and their file
forms, ``params.json``'s document and ``fit.parquet``'s table (docs/data_contract.md).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from stringcast.core import (PARAM_NAMES, Campaign, EstimationSettings, ModelSettings, Verdict, model_ranges,
                             tracks_arrays)
from stringcast.model import decode
from .diagnostics import diagnostics
from .problem import EstimationProblem


@dataclass(frozen=True)
class Estimate:
    """The estimated parameter set and how the search went.

    Attributes:
        coeffs: (10,) in ``PARAM_NAMES`` order. mu: (n,) relative mass per point.
        chi: (10 + G + 1,) the exponents of eq. (2) (coefficients, mu_others, specials).
        E_m: evaluation value (m; inf if every candidate blew up). E_i: (n,) per point, m.
        history: {"evaluations": [...], "best_E_m": [...]} after each batch.
        top_chi: (<=K, D) best candidates, top_E: (<=K,) their E (m), K = ``estimation.top_k``.
        message: empty, or what went wrong (all candidates invalid, rest fallback).
        chi_evaluated: (N, D) every candidate in evaluation order; E_evaluated: (N,) its E (m).
        verdict: the fit's verdict (:mod:`stringcast.estimate.verdict`; ok until :func:`~stringcast.estimate.estimation.fit_tracks`
            judges it). likely_cause: geometry, clock, tracking, model, recording, or "" when ok.
    """

    coeffs: np.ndarray
    mu: np.ndarray
    chi: np.ndarray
    E_m: float
    E_i: np.ndarray
    history: dict
    optimizer: str
    seed: int
    n_evaluations: int
    n_blown_up: int
    seconds: float
    top_chi: np.ndarray
    top_E: np.ndarray
    message: str = ""
    chi_evaluated: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    E_evaluated: np.ndarray = field(default_factory=lambda: np.zeros(0))
    verdict: Verdict = field(default_factory=Verdict)
    likely_cause: str = ""

    def __post_init__(self):
        n = len(self.mu)
        if np.shape(self.coeffs) != (len(PARAM_NAMES),):
            raise ValueError(f"Estimate.coeffs: expected ({len(PARAM_NAMES)},), got {np.shape(self.coeffs)}")
        if np.shape(self.E_i) != (n,):
            raise ValueError(f"Estimate.E_i: expected ({n},), got {np.shape(self.E_i)}")
        if np.ndim(self.top_chi) != 2 or np.shape(self.top_chi)[:1] != np.shape(self.top_E):
            raise ValueError("Estimate.top_chi/top_E: shapes (k, D) and (k,) expected")
        if len(self.E_evaluated) and np.shape(self.chi_evaluated) != (len(self.E_evaluated), np.shape(self.top_chi)[1]):
            raise ValueError("Estimate.chi_evaluated/E_evaluated: shapes (N, D) and (N,) expected")


@dataclass(frozen=True)
class Fit:
    """One trial's fit, in memory (:func:`~stringcast.estimate.estimation.fit_tracks`).

    Attributes
    ----------
    estimate : Estimate
        The estimate, its ``verdict`` and ``likely_cause`` judged.
    problem : EstimationProblem
        The trial's problem (:mod:`stringcast.estimate.problem`: the frames compared, the rest state, the
        hand's path).
    simulation : tuple of (ndarray, (F, n, 2); bool)
        The model at the estimate over the compared frames, m, and whether it stayed valid.
    fit_check : dict
        The fit's figures (:func:`~stringcast.estimate.fitcheck.fit_figures`: ``skill``, the point error in
        mm, the best time shift, ...).
    chi_start : ndarray, (D,)
        chi_best of eq. (3), the search's start.
    executions : int
        M of eq. (3).
    """

    estimate: Estimate
    problem: EstimationProblem
    simulation: tuple
    fit_check: dict
    chi_start: np.ndarray
    executions: int


def params_document(fit: Fit, campaign: Campaign, model: ModelSettings, estimation: EstimationSettings) -> dict:
    """``params.json``'s document for ``fit`` (docs/data_contract.md): the coefficients and masses, E, the
    search's history, the best sets (``top``), the diagnostics, the fit check and the verdict."""
    est, problem, k = fit.estimate, fit.problem, fit.executions
    _, mu_groups_all = decode(est.top_chi, model, np.arange(problem.n_groups))
    top = [{"E_mm": e * 1000, "coefficients": dict(zip(PARAM_NAMES, c)), "mu_groups": m, "chi": x}
           for e, c, m, x in zip(est.top_E, decode(est.top_chi, model, problem.mass_groups)[0], mu_groups_all,
                                 est.top_chi)]
    names = list(PARAM_NAMES) + ["mu_others"] + [f"mu_{i}" for i in campaign.string.special_points()]
    lo, hi, (mlo, mhi) = model_ranges(model)
    log_lo = np.log10(np.concatenate([lo, np.full(problem.n_groups, mlo)]))
    log_hi = np.log10(np.concatenate([hi, np.full(problem.n_groups, mhi)]))
    diag = diagnostics(est.chi_evaluated, est.E_evaluated, log_lo, log_hi, names, estimation)
    return {
        "coefficients": dict(zip(PARAM_NAMES, est.coeffs)), "mu": est.mu, "mu_groups": mu_groups_all[0],
        "mass_groups": problem.mass_groups, "special_points": campaign.string.special_points(),
        "E_mm": est.E_m * 1000, "E_i_mm": est.E_i * 1000,
        "history": {"evaluations": est.history["evaluations"],
                    "best_E_mm": [e * 1000 for e in est.history["best_E_m"]]},
        "optimizer": est.optimizer, "seed": est.seed, "evaluations": est.n_evaluations,
        "blown_up": est.n_blown_up, "seconds": est.seconds, "M": k, "chi": est.chi,
        "chi_start": fit.chi_start, "chi_names": names, "top": top, "diagnostics": diag, "message": est.message,
        "verdict": {**est.verdict.as_dict(), "likely_cause": est.likely_cause}, "fit_check": fit.fit_check,
        "t_motion_start_s": problem.t_motion_start,
        "t_sim_start_s": problem.frame_t[0], "frames_compared": len(problem.frame_t),
        "rest_fallback_points": list(problem.fallback_points), "dt_s": problem.dt}


def fit_table(tracks: pd.DataFrame, problem: EstimationProblem, sim: tuple[np.ndarray, bool],
              n: int) -> pd.DataFrame:
    """``fit.parquet``: ``frame, t_s, point, x_tracked_m, y_tracked_m, valid, x_sim_m, y_sim_m``.

    ``sim``: :func:`simulate_fit`'s (positions (F, n, 2) m at the compared frames, stayed valid).
    Every tracked frame and point 1..n; simulated values NaN outside the compared frames
    (or everywhere if the simulation blew up).
    """
    frames, t, xy, valid = tracks_arrays(tracks, n)
    sim_xy = np.full_like(xy[:, 1:], np.nan)
    pos, ok = sim
    idx = np.searchsorted(frames, problem.frames)
    sim_xy[idx] = pos if ok else np.nan
    f, nn = len(frames), n
    return pd.DataFrame({
        "frame": np.repeat(frames, nn), "t_s": np.repeat(t, nn), "point": np.tile(np.arange(1, n + 1), f),
        "x_tracked_m": xy[:, 1:, 0].ravel(), "y_tracked_m": xy[:, 1:, 1].ravel(),
        "valid": valid[:, 1:].ravel(), "x_sim_m": sim_xy[..., 0].ravel(), "y_sim_m": sim_xy[..., 1].ravel()})
