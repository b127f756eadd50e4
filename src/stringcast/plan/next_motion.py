"""The next motion from an estimate (Section V.B): the played motion perturbed, or a new one when the
played motion missed far or the model does not follow it (:mod:`stringcast.plan.planning`'s module doc,
"Replan"); :func:`plan_next` in memory, :func:`run_plan` from and to the trial's files.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from stringcast.core import (TRACK_COLUMNS, Campaign, ConfigError, ModelSettings, MotionSettings, read_joint_table,
                             read_json, read_parquet_columns)
from stringcast.model import ensemble_parameters, planned_parameters
from .motion import Motion, read_motion_json
from .planning import PlanResult, _rng, search, write_motion
from .residual import observed_miss, observed_tip


def _replan(campaign: Campaign, model: ModelSettings, motion: MotionSettings, coeffs: np.ndarray, mu: np.ndarray,
            seed: int, previous: Motion,
            ensemble: tuple[np.ndarray, np.ndarray] | None, observed: tuple | None, why: str,
            wide: float = 0.0) -> PlanResult:
    """A new motion instead of the perturbation (module doc, "Replan"), after ``why``; first, when
    ``wide`` > 0, the played motion perturbed by up to ``wide`` rad/s, kept when its best candidate hits
    under at least ``motion.replan_min_share`` of the ensemble (the planning set alone without one) and
    the model's error on the played motion is within ``motion.replan_residual_mm``."""
    if wide > 0:
        result = search(campaign, model, replace(motion, perturb_rad_s=wide), coeffs, mu, _rng(motion, seed),
                        previous=previous, ensemble=ensemble, observed=observed)
        share = result.hit_share if ensemble is not None else float(result.hit)   # search sets it with an ensemble
        need = float(motion.replan_min_share)
        too_far = _residual_too_large(result, motion)
        if share >= need and not too_far:
            return _with_message(replace(result, origin="wide_perturbation"),
                                 f"{why}: the played motion perturbed by +-{wide:g} rad/s "
                                 f"(hits under {share:.0%} of the sets)")
        why += f"; its +-{wide:g} rad/s perturbation " + (too_far or f"hits under {share:.0%} of the sets "
                                                           f"(< {need:.0%})")
    result = replace(search(campaign, model, motion, coeffs, mu, _rng(motion, seed), ensemble=ensemble), origin="new")
    return _with_message(result, f"{why}: a new motion (random posture and T), not a perturbation of the played one")


def _with_message(result: PlanResult, text: str) -> PlanResult:
    """``result`` with ``text`` put before its own message."""
    return replace(result, message="; ".join([text] + [result.message] * bool(result.message)))


def _residual_too_large(result: PlanResult, motion: MotionSettings) -> str:
    """Why the residual correction is not to be trusted ("" when it is, or there is none): the model's
    tip error on the played motion (median over the motion) beyond ``motion.replan_residual_mm`` (> 0)."""
    limit = float(motion.replan_residual_mm)
    size = None if result.residual is None else result.residual["median_mm"]
    if limit > 0 and size is not None and size > limit:
        return f"relies on a model {size:.0f} mm off the played motion's tip (median; > replan_residual_mm {limit:.0f})"
    return ""


@dataclass(frozen=True)
class NextMotion:
    """The next motion planned in memory (:func:`plan_next`) and what it was planned on.

    Attributes
    ----------
    result : PlanResult
        The chosen motion and its predicted outcome (closest approach d_min m at t_min s, ...).
    coeffs : ndarray, (10,)
        The estimate's coefficients, ``PARAM_NAMES`` order (Table 2 units).
    mu : ndarray, (n,)
        Its relative masses.
    observed_miss_m : float
        The played motion's tracked tip's closest approach to the target, m (NaN: not read).
    failed_fit : dict or None
        The estimate's verdict where it is ``fail`` (the plan is then not to be trusted).
    """

    result: PlanResult
    coeffs: np.ndarray
    mu: np.ndarray
    observed_miss_m: float = float("nan")
    failed_fit: dict | None = None


def plan_next(params: dict, played: Motion, campaign: Campaign, seed: int = 0, tracks=None,
              t_j: np.ndarray | None = None, q_j: np.ndarray | None = None, *, model: ModelSettings,
              motion: MotionSettings, played_origin: str = "", source: str = "params.json",
              tracks_name: str = "tracks.parquet") -> NextMotion:
    """The next motion (Section V.B) from an estimate, in memory (:func:`run_plan`'s rules; no file read or written).

    Parameters
    ----------
    params : dict
        The estimate, as ``params.json`` holds it (coefficients, mu, ``top`` for the robust planner,
        ``verdict``).
    played : Motion
        The motion just played (:func:`~stringcast.plan.motion.read_motion_json`): its posture and T.
    campaign : Campaign
        The resolved campaign (arm, string, target).
    seed : int
        The planner's seed, beside ``motion.seed``.
    tracks : DataFrame or mapping of columns, optional
        The played trial's tracked points (``tracks.parquet``), for the residual correction and the
        replan rules.
    t_j, q_j : ndarray, (K,) and (K, J), optional
        The played trial's joint log, s and rad (with ``tracks``).
    model, motion : settings
        :class:`~stringcast.core.ModelSettings`, :class:`~stringcast.core.MotionSettings`.
    played_origin : str
        The played motion's ``origin`` (a played wide perturbation that missed is not widened again).
    source, tracks_name : str
        How messages name the estimate and the tracks.

    Returns
    -------
    NextMotion

    Raises
    ------
    DataError
        Malformed parameters (or, robust, none in ``top``), or tracks that are not the played motion.
    ConfigError
        Residual correction or replanning without the played trial's tracks and joint log.
    """
    failed_fit = params.get("verdict") if (params.get("verdict") or {}).get("status") == "fail" else None
    coeffs, mu = planned_parameters(n_points=campaign.string.n_points, params=params, source=source)
    ensemble = ensemble_parameters(n_points=campaign.string.n_points, params=params, source=source) \
        if motion.planner == "robust" else None
    residual, replan_mm = bool(motion.residual_correction), float(motion.replan_miss_mm)
    observed, miss = None, float("nan")
    if residual or replan_mm > 0:
        if tracks is None or t_j is None or q_j is None:
            raise ConfigError("motion.residual_correction and motion.replan_miss_mm need the played trial's "
                              "tracks.parquet and joints.csv")
        observed = observed_tip(tracks, t_j, q_j, played.q, campaign.string.n_points, campaign.arm.controller_rate,
                                tracks_name)
        miss = observed_miss(*observed[:3], campaign.target.xy, played.T + float(motion.flight_window_s))
    observed = observed if residual else None
    if replan_mm > 0 and miss * 1000 > replan_mm:
        why = f"the tracked tip missed by {miss * 1000:.0f} mm (> replan_miss_mm {replan_mm:.0f})"
        wide = float(motion.replan_perturb_rad_s)
        if wide > 0 and played_origin == "wide_perturbation":
            wide, why = 0.0, why + " after a wide perturbation"
        result = _replan(campaign, model, motion, coeffs, mu, seed, played, ensemble, observed, why, wide)
    else:
        result = replace(search(campaign, model, motion, coeffs, mu, _rng(motion, seed), previous=played,
                                ensemble=ensemble, observed=observed), origin="perturbation")
        too_far = _residual_too_large(result, motion)
        if too_far:
            result = _replan(campaign, model, motion, coeffs, mu, seed, played, ensemble, observed,
                             "the perturbation " + too_far)
    if failed_fit is not None:
        cause = failed_fit.get("likely_cause") or "not named"
        result = _with_message(result, f"planned on a failed fit (likely cause: {cause}): the estimate is not "
                                       "usable, so neither is this motion's predicted outcome")
    return NextMotion(result, coeffs, mu, miss, failed_fit)


def run_plan(params_json: Path, played_motion_json: Path, campaign: Campaign, out_csv: Path, out_json: Path,
             seed: int = 0, tracks_parquet: Path | None = None, joints_csv: Path | None = None, *,
             model: ModelSettings, motion: MotionSettings) -> PlanResult:
    """Next motion (Section V.B, :func:`plan_next`): the played motion's posture and T, perturbed control
    points, estimated parameters; writes ``motion.csv`` and ``motion.json``.

    With ``motion.planner: robust`` the candidates are also scored under params.json's
    ``top`` ensemble (module doc); motion.json then carries ``ensemble_hit_share``,
    ``ensemble_margin_mm`` and ``ensemble_d_min_mm``. With ``motion.residual_correction``
    the played trial's ``tracks_parquet`` and ``joints_csv`` correct every prediction
    (:mod:`stringcast.plan.residual`); motion.json's ``residual_correction`` says how. With
    ``motion.replan_miss_mm`` > 0 and a tracked miss beyond it, the next motion is a wider
    perturbation (``motion.replan_perturb_rad_s``) if the ensemble agrees on it, else a new
    search (:func:`search` without ``previous``); motion.json's ``played_observed_miss_mm``
    is that miss; a played wide perturbation (motion.json ``origin``) that missed so is not
    perturbed again. With ``motion.replan_residual_mm`` > 0 no perturbation is played on a model
    further than that off the played motion's tracked tip (the new search instead). On a fit
    whose params.json verdict is ``fail`` it still plans (the person decides) and says so:
    motion.json's ``planned_on_failed_fit`` is true, ``failed_fit`` that verdict, and the
    message begins "planned on a failed fit".

    Parameters
    ----------
    params_json : Path
        The trial's ``params.json`` (the estimate).
    played_motion_json : Path
        ``motion.json`` of the motion just played (its posture q0_rad, T_s, control points, origin).
    campaign : Campaign
        The resolved campaign (arm, string, target).
    out_csv, out_json : Path
        The next ``motion.csv`` (t_s, q1_rad ..) and its ``motion.json`` to write.
    seed : int
        The planner's seed, beside ``motion.seed``.
    tracks_parquet, joints_csv : Path, optional
        The played trial's tracked points and joint log (residual correction, replan rules).
    model, motion : settings
        :class:`~stringcast.core.ModelSettings`, :class:`~stringcast.core.MotionSettings`.

    Returns
    -------
    PlanResult
        The chosen motion and its predicted outcome.

    Raises
    ------
    DataError
        Unreadable params.json (or, robust, one without ``top``), a played motion.json without q0_rad,
        T_s, control_points_rad_s, or (residual correction) unreadable tracks or a joint log that is not
        the played motion.
    ConfigError
        Residual correction without the trial's files.
    """
    params = read_json(params_json, mapping=True)
    planned_parameters(n_points=campaign.string.n_points, params=params, source=str(params_json))  # named first
    played = read_motion_json(played_motion_json, campaign.arm.n_joints, campaign.arm.controller_rate)
    tracks = t_j = q_j = None   # without them, plan_next refuses the rules that need them (ConfigError)
    if (motion.residual_correction or float(motion.replan_miss_mm) > 0) and None not in (tracks_parquet, joints_csv):
        t_j, q_j = read_joint_table(joints_csv, n_joints=campaign.arm.n_joints, arm_name=campaign.arm.name)
        tracks = read_parquet_columns(tracks_parquet, TRACK_COLUMNS)
    origin = read_json(played_motion_json, mapping=True).get("origin") or ""
    plan = plan_next(params, played, campaign, seed, tracks, t_j, q_j, model=model, motion=motion,
                     played_origin=str(origin), source=str(params_json), tracks_name=str(tracks_parquet))
    miss = plan.observed_miss_m
    write_motion(plan.result, campaign, motion, plan.coeffs, plan.mu, seed, out_csv, out_json, "next",
                 observed_miss_mm=miss * 1000 if np.isfinite(miss) else None, failed_fit=plan.failed_fit)
    return plan.result
