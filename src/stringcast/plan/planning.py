"""Motion planning (paper Section V): the search for a motion that hits the target.

Candidates are motions of :mod:`stringcast.plan.motion` (eq. (1) Bezier velocity curves
from an initial posture q0):

* T is drawn in ``motion.T_range_s`` and snapped to the controller period.
* Curves breaking position, speed, acceleration or floor limits
  (:func:`stringcast.core.arm.check_limits`) are regenerated.
* First motion: random initial postures (:func:`stringcast.plan.motion.sample_postures`).
  Our choice: a pool of ``motion.posture_pool`` postures is drawn once and each
  candidate takes a pool posture its curve fits, so that the hanging equilibrium
  (the model's initial state) is computed once per posture. All candidates of one
  batch share one T. The parameter set is :func:`first_parameters`.
* Later motions (Section V.B): the previous motion's q0 and T are kept and each
  control point V_1..V_{N-1} is moved by U(-perturb, +perturb) rad/s (V_N stays 0).
  The parameter set is the last estimate (:func:`planned_parameters`).
* Hit test: :func:`stringcast.model.string_model.closest_approach_batch` over [0, T + flight
  window] from the hanging equilibrium with the planned parameters; a hit is
  d_min <= target radius, min_y >= floor and a valid simulation. After the first
  hit the search goes on for ``motion.extra_after_hit`` candidates and returns the
  hit with the smallest d_min; without a hit it returns the closest candidate with
  ``hit=False`` and a message. An option (``motion.aim_radius_mm``, off in ours): the hit
  that starts that count must pass within the aim radius, not merely within the target's, so
  the search does not settle for a motion at the target's edge (measured, no gain:
  docs/method.md, "Aim at the centre").

* Planner (``motion.planner``): ``paper`` (default) is the above. ``robust`` (later
  motions) also scores candidates under an ensemble: the best K parameter sets of the
  last estimate (params.json ``top``, :mod:`stringcast.estimate.diagnostics`). Our choice, to keep
  the cost near the paper's: a candidate is scored under the ensemble, all members in one numba batch
  (:func:`stringcast.model.string_model.closest_approach_batch`, each member from its own hanging
  equilibrium), when under the best set it stays valid and above the floor and comes
  within ``motion.robust_screen_mm`` (default 20) of the target's edge. The chosen
  motion has the largest hit share (members for which it hits), then the largest
  margin (radius - median d_min over the members); the stopping rule is the paper's, or
  with ``motion.robust_min_share`` > 0 (tried, off in ours) the first hit that starts the
  count of ``extra_after_hit`` candidates must hit under at least that share of the members.
* A taut string at the hit (``motion.taut_chord_share`` > 0, off in ours; first and new plans): a
  hit whose model string's tip is at least that share of its length from the grasp at the closest
  approach ranks before one that is not (after the ensemble's hit share), and the count of
  ``extra_after_hit`` starts at the first such hit; perturbations are not judged (docs/method.md,
  "Where the executions go, and a taut string at the hit").
* A slack string at the hit (``motion.slack_warn_chord_share``, 0.9; first and new plans): when the
  chosen hit's model string has its tip nearer the grasp than that share of its length, the
  planner's note says so, and ``motion.json``'s ``slack_at_predicted_hit`` is true: such a hit rests
  on the bending, damping and drag the model guesses, and in the virtual labs such plans hit about
  one time in six, taut ones about one in two (docs/method.md, "A slack string at the predicted hit").
* Residual correction (``motion.residual_correction``, later motions, with either
  planner; ours): every set aims at the target minus the model's error on the played
  motion's tracked tip (:mod:`stringcast.plan.residual`), so d_min is the corrected one.
* Replan (``motion.replan_miss_mm`` > 0; ours 45): when the played motion's tracked tip missed
  the target by more than that, the next motion is searched afresh (random posture and T,
  as the first) with the estimate, not as a perturbation: a +-0.5 rad/s change cannot bridge a
  large miss, and the residual is a first-order correction. With
  ``motion.replan_perturb_rad_s`` > 0 (ours: 1.0) a *wider* perturbation of the played motion
  (residual-corrected) is searched first and kept when its best candidate hits under at least
  ``motion.replan_min_share`` (0.9) of the ensemble; not twice in a row: after a wide
  perturbation that missed by more than ``replan_miss_mm`` the next motion is the fresh one
  (docs/method.md: at d25a73b, type 5 seed 5, five in a row missed by 77-129 mm). With
  ``motion.replan_residual_mm`` > 0 (ours: 50) no perturbation, narrow or wide, is played when
  the model's tip error on the played motion (median over the motion) exceeds it. The offline
  and loop measurements behind the numbers are in docs/method.md ("Replan after a miss over 45 mm").

The model's predictions (equilibrium, closest approach, tip path) are
:class:`stringcast.plan.prediction.Predictor`'s. Stage entry points: :func:`run_first_plan` here
and :func:`~stringcast.plan.next_motion.run_plan` (the next motion, with the replan rules above; in memory
:func:`~stringcast.plan.next_motion.plan_next`) write ``motion.csv`` and its ``motion.json`` sidecar
(:func:`write_motion`).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from stringcast.core import (Campaign, ConfigError, ModelSettings, MotionSettings, PARAM_NAMES, write_joint_table,
                             write_json)
from stringcast.model import first_parameters
from .motion import Motion, time_grid
from .search import draw_candidates, keep_best, residual_correction, start_postures
from .prediction import Predictor
from .verdict import plan_verdict


@dataclass(frozen=True)
class PlanResult:
    """The chosen motion and its predicted outcome (d_min m at t_min s, lowest string point min_y m)."""

    motion: Motion
    hit: bool
    d_min: float
    t_min: float
    min_y: float
    candidates: int
    message: str = ""
    tip_path: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    planner: str = "paper"
    ensemble_d_min: np.ndarray | None = None
    """(K,) m, the chosen motion's closest approach under each ensemble member (robust planner only)."""
    hit_share: float | None = None
    """Share of the ensemble for which the chosen motion hits (robust planner only)."""
    margin: float | None = None
    """Target radius - median ensemble d_min, m (robust planner only; > 0: the median member hits)."""
    residual: dict | None = None
    """Residual correction (:meth:`stringcast.plan.residual.TipResidual.summary`); d_min is then corrected."""
    origin: str = ""
    """How the motion was made (motion.json ``origin``): first, perturbation, wide_perturbation, new."""
    chord_share: float | None = None
    """The model string's tip-to-grasp distance over its length at t_min (a first or new plan's hit; else None)."""
    slack: bool = False
    """A first or new plan's hit with chord_share under ``motion.slack_warn_chord_share`` (the note says so)."""


# ---------------------------------------------------------------------------
# Candidate search
# ---------------------------------------------------------------------------
def search(campaign: Campaign, model: ModelSettings, motion: MotionSettings, coeffs: np.ndarray, mu: np.ndarray,
           rng: np.random.Generator,
           previous: Motion | None = None, ensemble: tuple[np.ndarray, np.ndarray] | None = None,
           observed: tuple | None = None) -> PlanResult:
    """Search random motions (first plan) or perturbations of ``previous`` (later plans) for a hit.

    Args:
        model, motion: the model's and the planner's settings.
        coeffs (10,), mu (n,): the parameter set the model is simulated with.
        previous: the motion just played (its q0, T and control points are kept / perturbed).
        ensemble: robust planner (module doc): coeffs (K, 10), mu (K, n), the sets that
            screened candidates are scored under; None for the paper's planner.
        observed: residual correction (with ``previous``): the played motion's tracked tip
            (:func:`stringcast.plan.residual.observed_tip`); every set then aims at its own
            corrected target (:mod:`stringcast.plan.residual`).

    Returns:
        :class:`PlanResult` (hit=False with a message when no candidate hits; with an
        ensemble, its hit share and margin, and a message when no member is hit).

    Raises:
        ConfigError: when no motion within the arm's limits can be generated at all.
    """
    from tqdm.auto import tqdm

    arm = campaign.arm
    pl = Predictor(campaign, model, motion, coeffs, mu)
    batch, max_cand = int(motion.batch), int(motion.max_candidates)
    extra = int(motion.extra_after_hit)
    min_share = float(motion.robust_min_share) if ensemble is not None else 0.0
    t_lo, t_hi = (float(x) for x in motion.T_range_s)
    n_cp, alpha = int(motion.n_control_points), float(motion.alpha_max_rad_s2)
    perturb = float(motion.perturb_rad_s)
    postures = start_postures(campaign, motion, rng, previous)
    equilibria: dict[int, np.ndarray] = {}
    member_eq: dict[int, np.ndarray] = {}    # posture -> (K, n, 2), robust planner
    screen = float(motion.robust_screen_mm) / 1000
    radius = campaign.target.radius
    aim = radius if motion.aim_radius_mm is None else min(radius, float(motion.aim_radius_mm) / 1000)
    why_not = residual_correction(pl, previous, observed, coeffs, mu, ensemble, equilibria, member_eq)
    taut_min = float(motion.taut_chord_share) if previous is None else 0.0   # first and new plans only
    best, best_key, tried, first_hit, fails = None, None, 0, None, 0
    bar = tqdm(total=max_cand, desc="plan", unit="cand", disable=None)
    while tried < max_cand and (first_hit is None or tried < first_hit + extra):
        if previous is not None:
            T = previous.T
        else:
            T = time_grid(rng.uniform(t_lo, t_hi), pl.rate)[1]
        want = min(batch, max_cand - tried)
        cands = draw_candidates(arm, pl.rate, rng, T, want, postures, previous, perturb, n_cp, alpha)
        if not cands:
            fails += 1
            if fails >= 20 or previous is not None:
                raise ConfigError(f"arm {arm.name}: no motion within the joint limits could be generated "
                                  f"({'perturbing the played motion' if previous is not None else 'random curves'}); "
                                  "check motion.alpha_max_rad_s2, T_range_s and the arm limits")
            continue
        fails = 0
        d, tm, my, ok, hit, scores = _score_batch(pl, cands, T, postures, equilibria, member_eq, ensemble, radius,
                                                  arm.floor_y, screen)
        taut = _taut_hits(pl, cands, equilibria, tm, hit, taut_min) if taut_min > 0 else None
        best, best_key = keep_best(cands, T, d, tm, my, ok, hit, scores, arm.floor_y, best, best_key, taut)
        tried += len(cands)
        bar.update(len(cands))
        if first_hit is None and any(hit[b] and d[b] <= aim and scores.get(b, (0.0,))[0] >= min_share
                                     and (taut is None or taut[b][0]) for b in range(len(cands))):
            first_hit = tried
    bar.close()
    if previous is None:
        best = _with_chord(pl, best, equilibria)
    slack_below = float(motion.slack_warn_chord_share) if previous is None else 0.0
    return _plan_result(pl, best, tried, radius, ensemble, why_not, equilibria, slack_below)


def _score_batch(pl: Predictor, cands: list, T: float, postures: np.ndarray, equilibria: dict, member_eq: dict,
                 ensemble: tuple[np.ndarray, np.ndarray] | None, radius: float, floor_y: float,
                 screen: float) -> tuple:
    """One batch's candidates cands (B,) of T s under the planning set, each from its posture's hanging
    equilibrium (added to ``equilibria`` when new): closest approach d (B,) m at tm (B,) s, lowest point
    my (B,) m, valid ok (B,), hit (B,), and with an ``ensemble`` the scores of those valid, above the
    floor and within ``screen`` m of the target's edge (:func:`_ensemble_scores`; else {})."""
    for _, _, _, i in cands:
        if i not in equilibria:
            equilibria[i] = pl.equilibrium(postures[i])
    q = np.stack([c[2] for c in cands])
    p_init = np.stack([equilibria[c[3]] for c in cands])
    d, tm, my, ok = pl.evaluate(q, T, p_init)
    hit = ok & (d <= radius) & (my >= floor_y)
    scores = _ensemble_scores(pl, cands, q, T, ok & (my >= floor_y) & (d <= radius + screen), ensemble,
                              postures, member_eq) if ensemble is not None else {}
    return d, tm, my, ok, hit, scores


def _taut_hits(pl: Predictor, cands: list, equilibria: dict, tm: np.ndarray, hit: np.ndarray,
               taut_min: float) -> dict[int, tuple[bool, float]]:
    """{index of a hit: (its model string's chord share at its closest approach >= ``taut_min``, that
    share)} (:meth:`Predictor.chord_share`): a hit on a taut string rests on the string's length and the
    hand's motion, one on a slack string on the bending, damping and drag the model guesses
    (docs/method.md, "Where the executions go, and a taut string at the hit")."""
    idx = np.flatnonzero(hit)
    if not len(idx):
        return {}
    q = np.stack([cands[b][2] for b in idx])
    share = pl.chord_share(q, np.stack([equilibria[cands[b][3]] for b in idx]), tm[idx])
    return {int(b): (bool(c >= taut_min), float(c)) for b, c in zip(idx, share)}


def _with_chord(pl: Predictor, best: tuple, equilibria: dict) -> tuple:
    """:func:`keep_best`'s tuple with the chord share of its hit filled in where the search did not
    compute it (``motion.taut_chord_share`` off): one run of the chosen candidate to its t_min."""
    (cp, q0, q, i), T, hit, d, tm, my, share, margin, d_k, chord = best
    if hit and chord is None:
        chord = float(pl.chord_share(q[None], equilibria[i][None], np.array([tm]))[0])
    return (cp, q0, q, i), T, hit, d, tm, my, share, margin, d_k, chord


def _slack_note(chord: float, below: float) -> str:
    """The planner's note on a hit whose model string is slack (chord share under ``below``)."""
    return (f"the model string is slack at the predicted hit (its tip {chord:.2f} of the string's length from the "
            f"grasp, under motion.slack_warn_chord_share {below:g}): the hit rests on the bending, damping and "
            "drag the model guesses, not on the string's length and the hand's motion; in the virtual labs such "
            "first and new plans hit about one time in six, taut ones about one in two (docs/method.md, "
            "\"A slack string at the predicted hit\")")


def _plan_result(pl: Predictor, best: tuple, tried: int, radius: float, ensemble: tuple[np.ndarray, np.ndarray] | None,
                 why_not: str, equilibria: dict, slack_below: float = 0.0) -> PlanResult:
    """The :class:`PlanResult` of the search's best candidate (:func:`keep_best`'s tuple) after ``tried``
    candidates: its motion, predicted tip path and messages (no hit, chosen for the ensemble, a hit on a
    string slacker than ``slack_below``, the model's first warning, why there is no residual correction)."""
    (cp, q0, q, i), T, hit, d, tm, my, share, margin, d_k, chord = best
    t, _ = time_grid(T, pl.rate)
    motion = Motion(t=t, q=q, T=T, control_points=cp, q0=q0)
    msgs = [] if hit else [f"no candidate hit in {tried} tried; returning the closest "
                           f"({d * 1000:.1f} mm from the target, radius {radius * 1000:.0f} mm)"]
    if not hit and ensemble is not None and share > 0:  # chosen for the ensemble, not for the planning set
        msgs = [f"chosen for the ensemble (hits under {share:.0%} of its {len(ensemble[0])} sets); under the "
                f"planning set it passes {d * 1000:.1f} mm from the target (radius {radius * 1000:.0f} mm)"]
    robust = {}
    if ensemble is not None:
        robust = {"planner": "robust", "ensemble_d_min": d_k, "hit_share": share if d_k is not None else 0.0,
                  "margin": margin if d_k is not None else None}
        if d_k is None or share == 0:
            msgs.append(f"no candidate hit under any of the {len(ensemble[0])} ensemble sets; returning the "
                        "best under the estimate")
    slack = bool(hit and chord is not None and chord < slack_below)
    msgs += [_slack_note(chord, slack_below)] if slack else []
    msgs += sorted(set(pl.warnings))[:1] + [why_not] * bool(why_not)
    residual = None if pl.residual is None else pl.residual.summary()
    return PlanResult(motion, hit, d, tm, my, tried, "; ".join(msgs), pl.tip_path(motion, equilibria[i]),
                      residual=residual, chord_share=chord, slack=slack, **robust)


def _ensemble_scores(pl: Predictor, cands: list, q: np.ndarray, T: float, screened: np.ndarray,
                     ensemble: tuple[np.ndarray, np.ndarray], postures: np.ndarray,
                     member_eq: dict) -> dict[int, tuple[float, float, np.ndarray]]:
    """Robust planner: {candidate index: (hit share, margin m, d_min (K,) m)} for the screened candidates."""
    idx = np.nonzero(screened)[0]
    if len(idx) == 0:
        return {}
    coeffs, mu = ensemble
    for b in idx:
        i = cands[b][3]
        if i not in member_eq:
            member_eq[i] = np.stack([pl.equilibrium(postures[i], c, m) for c, m in zip(coeffs, mu)])
    p_init = np.stack([member_eq[cands[b][3]] for b in idx])              # (S, K, n, 2)
    d, my, ok = pl.evaluate_ensemble(q[idx], T, p_init, coeffs, mu)
    radius = pl.campaign.target.radius
    hits = ok & (d <= radius) & (my >= pl.arm.floor_y)
    d = np.where(ok, d, np.inf)
    return {int(b): (float(hits[s].mean()), radius - float(np.median(d[s])), d[s]) for s, b in enumerate(idx)}


# ---------------------------------------------------------------------------
# Files and stage entry points
# ---------------------------------------------------------------------------
def write_motion(result: PlanResult, campaign: Campaign, motion: MotionSettings, coeffs: np.ndarray, mu: np.ndarray,
                 seed: int, out_csv: Path, out_json: Path, kind: str, observed_miss_mm: float | None = None,
                 failed_fit: dict | None = None) -> None:
    """Write ``motion.csv`` (t_s, q1_rad..) and its ``motion.json`` sidecar (``observed_miss_mm``: the
    played motion's tracked tip's closest approach, when the plan read it; ``failed_fit``: the
    verdict of a failed fit the plan was made on: ``planned_on_failed_fit`` and its reasons), with the plan
    stage's ``verdict`` (:func:`stringcast.plan.verdict.plan_verdict`: how sure the predicted hit is)."""
    m = result.motion
    miss_m = float("nan") if observed_miss_mm is None else observed_miss_mm / 1000
    verdict = plan_verdict(result.origin, result.hit, result.d_min, campaign.target.radius, result.residual,
                           result.slack, failed_fit, miss_m)
    write_joint_table(out_csv, m.t, m.q)
    step = max(1, len(result.tip_path) // 400)
    write_json(out_json, {
        "kind": kind, "T_s": m.T, "control_points_rad_s": m.control_points, "q0_rad": m.q0,
        "controller_rate_hz": campaign.arm.controller_rate, "arm": campaign.arm.name,
        "params": dict(zip(PARAM_NAMES, coeffs)), "mu": mu,
        "predicted_tip_path": result.tip_path[::step], "closest_approach_mm": result.d_min * 1000,
        "closest_approach_t_s": result.t_min, "min_y_mm": result.min_y * 1000,
        "hit_predicted": result.hit, "candidates": result.candidates, "seed": seed,
        "flight_window_s": float(motion.flight_window_s),
        "target": {"x_mm": campaign.target.x * 1000, "y_mm": campaign.target.y * 1000,
                   "radius_mm": campaign.target.radius * 1000},
        "planner": result.planner, "ensemble_size": None if result.ensemble_d_min is None else len(result.ensemble_d_min),
        "ensemble_hit_share": result.hit_share,
        "ensemble_margin_mm": None if result.margin is None else result.margin * 1000,
        "ensemble_d_min_mm": None if result.ensemble_d_min is None else np.asarray(result.ensemble_d_min) * 1000,
        "residual_correction": result.residual, "played_observed_miss_mm": observed_miss_mm,
        "origin": result.origin, "chord_share_at_closest_approach": result.chord_share,
        "slack_at_predicted_hit": result.slack,
        "message": result.message, "planned_on_failed_fit": failed_fit is not None,
        "failed_fit": failed_fit, "verdict": verdict.as_dict()})


def _rng(motion: MotionSettings, seed: int) -> np.random.Generator:
    return np.random.default_rng([int(motion.seed), int(seed)])


def run_first_plan(campaign: Campaign, out_csv: Path, out_json: Path, seed: int = 0, *, model: ModelSettings,
                   motion: MotionSettings) -> PlanResult:
    """First motion of a campaign (Section V.A), planned with :func:`first_parameters` (Table 2 minima, k_s
    per ``motion.first_k_s``); writes ``motion.csv`` and ``motion.json``.

    Parameters
    ----------
    campaign : Campaign
        The resolved campaign (arm, string, target).
    out_csv, out_json : Path
        ``motion.csv`` (t_s, q1_rad ..) and its ``motion.json`` to write.
    seed : int
        The planner's seed, beside ``motion.seed``.
    model, motion : settings
        :class:`~stringcast.core.ModelSettings`, :class:`~stringcast.core.MotionSettings`.

    Returns
    -------
    PlanResult
        The chosen motion and its predicted outcome (closest approach d_min m at t_min s, ...).

    Raises
    ------
    ConfigError
        No motion within the arm's limits can be generated at all.
    """
    coeffs, mu = first_parameters(model=model, motion=motion, string=campaign.string)
    result = replace(search(campaign, model, motion, coeffs, mu, _rng(motion, seed)), origin="first")
    write_motion(result, campaign, motion, coeffs, mu, seed, out_csv, out_json, "first")
    return result
