"""Parameter estimation (paper Section VI, eqs. 2-3).

The string model (:mod:`stringcast.model.string_model`) is driven by the *measured* joint log
(forward kinematics -> grasp point and hand angle) from the tracked rest state,
and its 10 coefficients plus relative masses are searched so that the simulated
mass points match the tracked ones (evaluation value E, eqs. 4-6,
:func:`stringcast.estimate.evaluation.evaluation_value`).

Search space (eq. 2): x = chi in [0, 1]^(10 + 1 + G): the ten coefficients in
``PARAM_NAMES`` order, then mu_others (shared by the plain points), then
one mu per special point (``StringSpec.mass_groups``); P = P_min (P_max/P_min)^chi.

Optimizers (``estimation.optimizer``; :mod:`stringcast.estimate.optimizers`: the
paper's eq. 3 ``random_search``, ``cmaes``, ``de``), all evaluating candidates in
numba batches of ``estimation.batch``, start from chi_best = the previous
trial's estimate. With no previous estimate (trial 1) chi_best is the set the
first motion was planned with (:func:`stringcast.model.parameters.first_parameters`):
chi = 0 for the coefficients (Table 2 minima) except k_s (lifted so the model
carries its own weight, or Table 2's maximum: ``motion.first_k_s``), and chi of
``model.first_mu`` for the masses.

params.json also holds ``top`` (the best ``estimation.top_k`` sets, best first, with
chi: the robust planner's ensemble), ``diagnostics`` (which parameters this
trial's motion pins down, :mod:`stringcast.estimate.diagnostics`), ``fit_check`` (how the
fitted points follow the tracked ones, :mod:`stringcast.estimate.fitcheck`) and ``verdict``
(ok / warn / fail, its reasons and ``likely_cause``, :mod:`stringcast.estimate.verdict`), which
also carries the warnings and failures of the trial's calibration.json, sync.json and
tracking.json.

The settings (``estimation.*``, ``model.*``, ...) are the stage's settings objects
(:class:`~stringcast.core.EstimationSettings`, :class:`~stringcast.core.ModelSettings`, ...).

The trial's problem and E as a function of chi (the rest state, the frames compared) are
:mod:`stringcast.estimate.problem`'s.
"""
from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from collections.abc import Callable, Mapping

import numpy as np
import pandas as pd

from stringcast.core import (PARAM_NAMES, TRACK_COLUMNS, Campaign, ConfigError, DataError, EstimationSettings,
                             EvaluationSettings, ModelSettings, MotionSettings, TrackingSettings, Verdict,
                             motion_window, read_joint_table, read_json, read_parquet, trial_result, write_json,
                             write_parquet)
from stringcast.model import decode, start_chi
from .diagnostics import best_k, best_k_two_basins, checked
from .fitcheck import fit_figures
from .optimizers import K_PH, OPTIMIZERS, Recorder
from .records import Estimate, Fit, fit_table, params_document
from .problem import (EstimationProblem, build_problem, make_objective, point_errors, simulate_fit,
                      upstream_causes)
from .verdict import fit_verdict, sweep_bounds

UPSTREAM = ("geometry", "clock", "tracking")
"""The earlier stages whose ``<stage>.json`` verdicts the fit's verdict carries (beside tracks.parquet):
the sweep's ``geometry.json`` and ``clock.json``, which judge the calibration and the sync with the
trial's own evidence (results made before the sweep existed: ``calibration.json``, ``sync.json``;
:func:`stringcast.core.trial_result`)."""


# ---------------------------------------------------------------------------
# Search
# ---------------------------------------------------------------------------
def estimate(problem: EstimationProblem, model: ModelSettings, estimation: EstimationSettings,
             chi_start: np.ndarray, M: int, seed: int, objective: Callable | None = None) -> Estimate:
    """Run the configured optimizer on ``problem``.

    Args:
        model: the model settings (:class:`~stringcast.core.ModelSettings`: eq. 2's ranges).
        estimation: the estimation settings (:class:`~stringcast.core.EstimationSettings`).
        chi_start: (10 + G,) chi_best at m = 0. M: executions so far (>= 1, eq. 3).
        objective: batch objective chi (B, D) -> E (B,); default :func:`make_objective`
            (with a custom objective ``E_i`` is NaN).

    Returns:
        The :class:`Estimate` (never raises on blown-up candidates: E = inf and a message).

    Raises:
        ConfigError: unknown optimizer name or a bad budget.
    """
    name = str(estimation.optimizer)
    if name not in OPTIMIZERS:
        raise ConfigError(f"estimation.optimizer: unknown {name!r} (known: {', '.join(OPTIMIZERS)})")
    budget, batch = int(estimation.iterations), int(estimation.batch)
    if budget < 1 or batch < 1:
        raise ConfigError("estimation.iterations and estimation.batch must be >= 1")
    d = len(PARAM_NAMES) + problem.n_groups
    chi_start = np.asarray(chi_start, float)
    if chi_start.shape != (d,):
        raise ValueError(f"chi_start: expected ({d},), got {chi_start.shape}")
    custom = objective is not None
    if not custom:
        objective = make_objective(problem, model)
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    rec = Recorder(objective, budget, f"estimate ({name})")
    try:
        OPTIMIZERS[name](rec, chi_start, batch, max(1, int(M)), rng, estimation)
    finally:
        rec.bar.close()
    all_chi, all_E = np.concatenate(rec.chi), np.concatenate(rec.E)
    k, tol, _ = checked(estimation)
    top_chi, top_E = (best_k_two_basins(all_chi, all_E, k, K_PH, tol) if estimation.top_grasp_basins
                      else best_k(all_chi, all_E, k))
    best_chi = top_chi[0]
    coeffs, mu = decode(best_chi, model, problem.mass_groups)
    if custom:  # E_i needs the model; a custom objective defines no points
        E_i = np.full(problem.n_points, np.nan)
    elif np.isfinite(top_E[0]):
        E_i = point_errors(problem, model, best_chi)
    else:
        E_i = np.full(problem.n_points, np.inf)
    msgs = []
    blown = int(np.sum(~np.isfinite(all_E)))
    if not np.isfinite(top_E[0]):
        msgs.append(f"every one of {len(all_E)} candidates blew up or was invalid; the parameters are the best "
                    "it had (E = inf)")
    elif blown > len(all_E) // 2:
        msgs.append(f"{blown} of {len(all_E)} candidates blew up (E = inf); the estimate is the best finite one")
    if problem.fallback_points:
        msgs.append(f"points {list(problem.fallback_points)} were never tracked at rest: their initial state "
                    "is filled with rest-length segments between the tracked points around them")
    return Estimate(coeffs=coeffs, mu=mu, chi=best_chi, E_m=float(top_E[0]), E_i=E_i,
                    history=rec.history, optimizer=name, seed=int(seed), n_evaluations=len(all_E),
                    n_blown_up=blown, seconds=time.perf_counter() - t0,
                    top_chi=top_chi, top_E=top_E, message="; ".join(msgs),
                    chi_evaluated=all_chi, E_evaluated=all_E)

# ---------------------------------------------------------------------------
# Stage entry point
# ---------------------------------------------------------------------------
def fit_tracks(tracks: pd.DataFrame, t_j: np.ndarray, q_j: np.ndarray, campaign: Campaign,
               previous: Mapping | None = None, executions: int = 1, *, model: ModelSettings,
               evaluation: EvaluationSettings, estimation: EstimationSettings, motion: MotionSettings,
               tracking: TrackingSettings, verdicts: Mapping[str, Verdict] | None = None,
               bounds: Mapping | None = None, source: str = "tracks", previous_name: str = "previous") -> Fit:
    """Fit the model to one trial's tracked points, in memory (paper Section VI, eqs. 2-6; no file read or written).

    Parameters
    ----------
    tracks : DataFrame
        ``frame, t_s, point, x_m, y_m, valid`` ((n + 1) rows per frame, m in the robot frame).
    t_j, q_j : ndarray, (K,) and (K, J)
        The measured joint log, s and rad (it drives the model's hand).
    campaign : Campaign
        The resolved campaign (string, arm).
    previous : mapping, optional
        The previous trial's ``params.json`` document: chi_best of eq. (3); None for trial 1 (the first
        plan's set).
    executions : int
        M of eq. (3), the executions so far (>= 1); the search's seed is ``estimation.seed + M``.
    model, evaluation, estimation, motion, tracking : settings
        The stage's settings objects (:class:`~stringcast.core.ModelSettings`, ...).
    verdicts : mapping of str to Verdict, optional
        The earlier stages' verdicts (geometry, clock, tracking), carried by the fit's.
    bounds : mapping, optional
        The sweep's stated bounds (:func:`~stringcast.estimate.verdict.sweep_bounds`).
    source, previous_name : str
        How messages name the tracks and the previous estimate.

    Returns
    -------
    Fit
        The estimate with its verdict, the problem, the simulation at the estimate and the fit check.

    Raises
    ------
    DataError
        No problem can be built from the tracks (too few valid points, no rest frames, ...), or a
        malformed previous estimate.
    ConfigError
        Bad optimizer settings.
    """
    problem = build_problem(tracks, t_j, q_j, campaign, model=model, evaluation=evaluation, estimation=estimation,
                            tracking=tracking, source=str(source))
    chi0 = start_chi(previous, campaign.string, model, motion, previous_name)
    k = max(1, int(executions))
    est = estimate(problem, model, estimation, chi0, k, int(estimation.seed) + k)
    sim = simulate_fit(problem, model, est.chi)
    figures, verdict, cause = judge_fit(problem, sim, campaign.string.length, motion_window(t_j, q_j)[1],
                                        est.E_m * 1000, estimation, dict(verdicts or {}), bounds)
    return Fit(replace(est, verdict=verdict, likely_cause=cause), problem, sim, figures, np.asarray(chi0), k)


def run_estimation(tracks_parquet: Path, joints_csv: Path, campaign: Campaign,
                   prev_params_json: Path | None, trial_index: int, out_params_json: Path,
                   out_fit_parquet: Path, *, model: ModelSettings,
                   evaluation: EvaluationSettings, estimation: EstimationSettings, motion: MotionSettings,
                   tracking: TrackingSettings, upstream: Mapping[str, Path] | None = None) -> Estimate:
    """Estimate the parameters of one trial (:func:`fit_tracks`) and write ``params.json`` and ``fit.parquet``.

    Parameters
    ----------
    tracks_parquet, joints_csv : Path
        The trial's tracked points and measured joint log.
    campaign : Campaign
        The resolved campaign (string, arm).
    prev_params_json : Path or None
        The previous trial's ``params.json`` (chi_best of eq. 3); None for trial 1.
    trial_index : int
        k >= 1, the number of executions so far (M of eq. 3); seed = ``estimation.seed`` + k.
    out_params_json, out_fit_parquet : Path
        ``params.json`` and ``fit.parquet`` to write (docs/data_contract.md).
    model, evaluation, estimation, tracking : settings
        The settings of the search and its problem (:class:`~stringcast.core.ModelSettings`,
        :class:`~stringcast.core.EvaluationSettings`, :class:`~stringcast.core.EstimationSettings`,
        :class:`~stringcast.core.TrackingSettings`).
    motion : MotionSettings
        Without ``prev_params_json`` the search starts at the first plan's set (``first_k_s``,
        ``first_max_strain``).
    upstream : mapping of str to Path, optional
        The earlier stages' JSON files by stage (:data:`UPSTREAM`) whose ``"verdict"`` the fit's verdict
        carries; default: ``<stage>.json`` beside ``tracks_parquet`` (a missing file or key is ok).

    Returns
    -------
    Estimate
        With the fit's ``verdict`` and ``likely_cause``.

    Raises
    ------
    DataError
        Unreadable or inconsistent inputs (named; where no problem can be built, with the earlier stages'
        reasons), or an earlier stage's malformed verdict.
    ConfigError
        Bad optimizer settings.
    """
    tracks = read_parquet(tracks_parquet, TRACK_COLUMNS)
    t_j, q_j = read_joint_table(joints_csv, n_joints=campaign.arm.n_joints, arm_name=campaign.arm.name)
    if upstream is None:
        upstream = dict(trial_result(Path(tracks_parquet).parent, stage) for stage in UPSTREAM)
    prev = read_json(prev_params_json, mapping=True) if prev_params_json else None
    settings = dict(model=model, evaluation=evaluation, estimation=estimation, motion=motion, tracking=tracking)
    try:
        fit = fit_tracks(tracks, t_j, q_j, campaign, prev, trial_index, **settings, verdicts=read_verdicts(upstream),
                         bounds=read_sweep_bounds(upstream), source=str(tracks_parquet),
                         previous_name=str(prev_params_json))
    except DataError as exc:
        raise DataError(f"{exc}{upstream_causes(upstream)}") from exc
    write_json(out_params_json, params_document(fit, campaign, model, estimation))
    write_parquet(out_fit_parquet, fit_table(tracks, fit.problem, fit.simulation, campaign.string.n_points))
    return fit.estimate


def judge_fit(problem: EstimationProblem, sim: tuple[np.ndarray, bool], length_m: float, t_stop: float, E_mm: float,
              estimation: EstimationSettings, upstream: Mapping[str, Verdict],
              sweep: Mapping | None = None) -> tuple[dict, Verdict, str]:
    """The fit's figures (:func:`~stringcast.estimate.fitcheck.fit_figures`), verdict and likely cause
    (:func:`~stringcast.estimate.verdict.fit_verdict`, with the sweep's bounds ``sweep``) for
    :func:`simulate_fit`'s ``sim`` (NaN if it blew up)."""
    pos = sim[0] if sim[1] else np.full_like(sim[0], np.nan)
    figures = fit_figures(problem, pos, length_m, t_stop)
    return (figures, *fit_verdict(figures, E_mm, estimation, upstream, sweep))


def read_sweep_bounds(paths: Mapping[str, Path]) -> dict:
    """The stated bounds on the geometry, the clock and tracking (:func:`~stringcast.estimate.verdict.sweep_bounds`)
    from the ``"geometry"``, ``"clock"`` and ``"tracking"`` files of ``paths`` (a missing file: None); malformed JSON is
    :func:`read_verdicts`' error."""
    docs = {}
    for stage in ("geometry", "clock", "tracking"):
        path = paths.get(stage)
        doc = read_json(Path(path)) if path is not None and Path(path).exists() else None
        docs[stage] = doc if isinstance(doc, dict) else None
    return sweep_bounds(docs["geometry"], docs["clock"], docs["tracking"])


def read_verdicts(paths: Mapping[str, Path]) -> dict[str, Verdict]:
    """The ``"verdict"`` of each stage's JSON file, by stage; a missing file or key is ok.

    Raises:
        DataError: a file that is not JSON, or a verdict with an unknown status (named).
    """
    out = {}
    for stage, path in paths.items():
        path = Path(path)
        if not path.exists():
            continue
        doc = read_json(path)
        try:
            out[stage] = Verdict.from_dict(doc.get("verdict") if isinstance(doc, dict) else None)
        except (ValueError, TypeError, AttributeError) as exc:
            raise DataError(f"{path}: malformed \"verdict\": {exc}") from exc
    return out
