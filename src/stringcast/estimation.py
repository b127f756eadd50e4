"""Parameter estimation (paper Section VI, eqs. 2-3).

The string model (:mod:`stringcast.model`) is driven by the *measured* joint log
(forward kinematics -> grasp point and hand angle) from the tracked rest state,
and its 10 coefficients plus relative masses are searched so that the simulated
mass points match the tracked ones (evaluation value E, eqs. 4-6,
:func:`stringcast.evaluation.evaluation_value`).

Search space (eq. 2): x = chi in [0, 1]^(10 + 1 + G): the ten coefficients in
``config.PARAM_NAMES`` order, then mu_others (shared by the plain points), then
one mu per special point (``StringSpec.mass_groups``); P = P_min (P_max/P_min)^chi.

Optimizers (``config.estimation.optimizer``; :mod:`stringcast.optimizers`: the
paper's eq. 3 ``random_search``, ``cmaes``, ``de``), all evaluating candidates in
numba batches of ``config.estimation.batch``, start from chi_best = the previous
trial's estimate. With no previous estimate (trial 1) chi_best is the set the
first motion was planned with (:func:`stringcast.parameters.first_parameters`):
chi = 0 for the coefficients (Table 2 minima) except k_s (lifted so the model
carries its own weight, or Table 2's maximum: ``motion.first_k_s``), and chi of
``model.first_mu`` for the masses.

params.json also holds ``top`` (the best ``estimation.top_k`` sets, best first, with
chi: the robust planner's ensemble) and ``diagnostics`` (which parameters this
trial's motion pins down, :mod:`stringcast.diagnostics`).

Choices where the paper is silent: the rest state p_init is the median of the
valid tracked positions over the last ``tracking.rest_frames`` frames before the
motion starts (:func:`stringcast.arm.motion_start`); points never valid there are
filled with l0 segments between the known points around them
(:func:`stringcast.rest_state.fill_rest_pose`, reported in ``Estimate.message``).
The simulation starts at the first of those frames and is compared at every later
frame up to the end of the joint log, or (``estimation.compare_after_motion_s``, our
option) up to that long after the arm stops (:func:`stringcast.arm.motion_window`).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping

import numpy as np
import pandas as pd

from .arm import hand_pose, motion_start, motion_window
from .config import PARAM_NAMES, Campaign, ConfigError, model_ranges
from .diagnostics import best_k, diagnostics
from .diagnostics import settings as diagnostics_settings
from .files import (TRACK_COLUMNS, DataError, read_joint_table, read_json, read_parquet, tracks_arrays, write_json,
                    write_parquet)
from .optimizers import OPTIMIZERS, Recorder
from .parameters import decode, start_chi
from .rest_state import fill_rest_pose

MIN_REST_FRAMES = 3


@dataclass(frozen=True)
class EstimationProblem:
    """Everything the search needs, from the pipeline's files (never ground truth).

    Attributes:
        hand_t: (K,) s, controller clock; hand_t[0] == frame_t[0].
        hand: (K, 3) grasp point x, y (m) and hand angle phi_h (rad) from FK.
        p_init: (n, 2) m, the rest state at frame_t[0].
        frame_t: (F,) s, frame times compared (frame_t[0] = simulation start).
        frames: (F,) int, the frame numbers of ``frame_t``.
        tracked: (F, n, 2) m, tracked points 1..n (0 where not valid).
        valid: (F, n) bool.
        l0: rest segment length, m. psi0: rest direction in the hand frame, rad.
        dt: integration step, s. mass_groups: (n,) int (0 = mu_others).
        w: tip weighting of eq. (6).
        fallback_points: points (1..n) never valid at rest (p_init filled by ``fill_rest_pose``).
        t_motion_start: s, when the joint log starts to move.
    """

    hand_t: np.ndarray
    hand: np.ndarray
    p_init: np.ndarray
    frame_t: np.ndarray
    frames: np.ndarray
    tracked: np.ndarray
    valid: np.ndarray
    l0: float
    psi0: float
    dt: float
    mass_groups: np.ndarray
    w: float
    fallback_points: tuple = ()
    t_motion_start: float = 0.0

    def __post_init__(self):
        k, f, n = len(self.hand_t), len(self.frame_t), len(self.p_init)
        shapes = {"hand_t": (k,), "hand": (k, 3), "p_init": (n, 2), "frame_t": (f,), "frames": (f,),
                  "tracked": (f, n, 2), "valid": (f, n), "mass_groups": (n,)}
        for name, shape in shapes.items():
            if np.shape(getattr(self, name)) != shape:
                raise ValueError(f"EstimationProblem.{name}: expected shape {shape}, got {np.shape(getattr(self, name))}")
        if k < 2 or f < 2:
            raise ValueError("EstimationProblem: needs at least two joint samples and two frames")
        if not np.all(np.isfinite(self.p_init)) or not np.all(np.isfinite(self.hand)):
            raise ValueError("EstimationProblem: p_init and hand must be finite")

    @property
    def n_points(self) -> int:
        return len(self.p_init)

    @property
    def n_groups(self) -> int:
        return int(self.mass_groups.max()) + 1


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


# ---------------------------------------------------------------------------
# Problem from the pipeline's files
# ---------------------------------------------------------------------------
def build_problem(tracks_df: pd.DataFrame, t_joints: np.ndarray, q_joints: np.ndarray,
                  campaign: Campaign, config: Mapping, source: str = "tracks.parquet") -> EstimationProblem:
    """Assemble the estimation problem from tracked points and the measured joint log.

    Args:
        tracks_df: long table ``frame, t_s, point, x_m, y_m, valid`` (t_s on the controller clock).
        t_joints: (K,) s; q_joints: (K, J) rad, the measured joint log.

    Raises:
        DataError: missing columns, a log that never moves, fewer than 3 frames at
            rest before the motion, fewer than 2 frames overlapping the joint log, or
            no valid tracked point to compare.
    """
    s, arm = campaign.string, campaign.arm
    n = s.n_points
    frames, t, xy, valid = tracks_arrays(tracks_df, n, source)
    t_joints = np.asarray(t_joints, float)
    q_joints = np.asarray(q_joints, float)
    try:
        t_move = motion_start(t_joints, q_joints)
    except ValueError as exc:
        raise DataError(f"joints.csv: {exc}") from exc
    rest = np.nonzero((t >= t_joints[0]) & (t < t_move))[0]
    n_rest = int(config.get("tracking", {}).get("rest_frames", 40))
    rest = rest[-max(n_rest, MIN_REST_FRAMES):]
    if len(rest) < MIN_REST_FRAMES:
        raise DataError(f"{source}: only {len(rest)} frames before the motion starts at t = {t_move:.3f} s "
                        f"(need {MIN_REST_FRAMES}) within the joint log")
    use = np.arange(rest[0], len(t))
    use = use[t[use] <= t_joints[-1]]
    window_s = config.get("estimation", {}).get("compare_after_motion_s")
    if window_s is not None:
        use = use[t[use] <= motion_window(t_joints, q_joints)[1] + float(window_s)]
    if len(use) < 2:
        raise DataError(f"{source}: fewer than two frames overlap the joint log")
    t0 = t[use[0]]
    q0 = np.array([np.interp(t0, t_joints, q_joints[:, j]) for j in range(q_joints.shape[1])])
    after = t_joints > t0
    hand_t = np.concatenate([[t0], t_joints[after]])
    hand = hand_pose(arm, np.vstack([q0, q_joints[after]]))

    known = np.full((n, 2), np.nan)
    for i in range(1, n + 1):
        ok = valid[rest, i]
        if ok.any():
            known[i - 1] = np.median(xy[rest[ok], i], axis=0)
    psi0 = np.radians(float(config["model"].get("psi0_deg", 0.0)))
    p_init, fallback = fill_rest_pose(hand[0, :2], hand[0, 2] + psi0, known, s.l0)
    if not valid[use, 1:].any():
        raise DataError(f"{source}: no valid tracked point 1..{n} in the frames to compare")
    tracked = np.where(valid[use, 1:, None], xy[use, 1:], 0.0)
    return EstimationProblem(
        hand_t=hand_t, hand=hand, p_init=p_init, frame_t=t[use], frames=frames[use], tracked=tracked,
        valid=valid[use, 1:], l0=s.l0, psi0=psi0,
        dt=float(config["model"]["dt_s"]), mass_groups=s.mass_groups(),
        w=float(config.get("evaluation", {}).get("w", 0.1)), fallback_points=tuple(fallback),
        t_motion_start=t_move)


# ---------------------------------------------------------------------------
# Objective and search
# ---------------------------------------------------------------------------
def make_objective(problem: EstimationProblem, config: Mapping) -> Callable[[np.ndarray], np.ndarray]:
    """E (eqs. 4-6) of a batch: chi (B, D) -> E (B,) in m, +inf where the simulation blew up."""
    from .evaluation import evaluation_value
    from .model import simulate_batch

    hand = problem.hand[None]
    p_init = problem.p_init[None]

    def objective(chi: np.ndarray) -> np.ndarray:
        coeffs, mu = decode(chi, config, problem.mass_groups)
        b = len(chi)
        pos, ok = simulate_batch(np.ascontiguousarray(coeffs), np.ascontiguousarray(mu), problem.hand_t, hand,
                                 np.zeros(b, np.int64), p_init, problem.l0, problem.psi0, problem.dt,
                                 problem.frame_t)
        E = np.asarray(evaluation_value(problem.tracked, problem.valid, pos, problem.w), float).reshape(b)
        return np.where(np.asarray(ok, bool) & np.isfinite(E), E, np.inf)

    return objective


def make_joint_objective(problems, config: Mapping) -> Callable[[np.ndarray], np.ndarray]:
    """E over several trials of one string: chi (B, D) -> mean over ``problems`` of E (B,), m.

    The issue's "fit all of a campaign's trials at once": a set must reproduce every
    motion played so far, not only the last (our choice: each trial weighs the same,
    whatever its number of frames). +inf where any trial's simulation blew up.

    Raises:
        ValueError: no problems, or problems of different strings (points, mass groups).
    """
    problems = list(problems)
    if not problems:
        raise ValueError("make_joint_objective: no problems")
    if len({(p.n_points, p.n_groups) for p in problems}) != 1:
        raise ValueError("make_joint_objective: the trials disagree on the string's points or mass groups")
    objectives = [make_objective(p, config) for p in problems]

    def objective(chi: np.ndarray) -> np.ndarray:
        return np.mean([f(chi) for f in objectives], axis=0)

    return objective


def estimate(problem: EstimationProblem, config: Mapping, chi_start: np.ndarray, M: int, seed: int,
             objective: Callable | None = None, earlier: tuple = ()) -> Estimate:
    """Run the configured optimizer on ``problem``.

    Args:
        chi_start: (10 + G,) chi_best at m = 0. M: executions so far (>= 1, eq. 3).
        objective: batch objective chi (B, D) -> E (B,); default :func:`make_objective`
            (with a custom objective ``E_i`` is NaN).
        earlier: problems of earlier trials of the same string, fitted together with
            ``problem`` (:func:`make_joint_objective`; E_m is then the mean over the
            trials, E_i stays ``problem``'s).

    Returns:
        The :class:`Estimate` (never raises on blown-up candidates: E = inf and a message).

    Raises:
        ConfigError: unknown optimizer name or a bad budget.
    """
    est_cfg = config.get("estimation", {})
    name = str(est_cfg.get("optimizer", "random_search"))
    if name not in OPTIMIZERS:
        raise ConfigError(f"estimation.optimizer: unknown {name!r} (known: {', '.join(OPTIMIZERS)})")
    budget, batch = int(est_cfg.get("iterations", 3000)), int(est_cfg.get("batch", 64))
    if budget < 1 or batch < 1:
        raise ConfigError("estimation.iterations and estimation.batch must be >= 1")
    d = len(PARAM_NAMES) + problem.n_groups
    chi_start = np.asarray(chi_start, float)
    if chi_start.shape != (d,):
        raise ValueError(f"chi_start: expected ({d},), got {chi_start.shape}")
    custom = objective is not None
    if not custom:
        objective = make_joint_objective((*earlier, problem), config)   # E itself for one trial
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    rec = Recorder(objective, budget, f"estimate ({name})")
    try:
        OPTIMIZERS[name](rec, chi_start, batch, max(1, int(M)), rng, est_cfg)
    finally:
        rec.bar.close()
    all_chi, all_E = np.concatenate(rec.chi), np.concatenate(rec.E)
    top_chi, top_E = best_k(all_chi, all_E, diagnostics_settings(config)[0])
    best_chi = top_chi[0]
    coeffs, mu = decode(best_chi, config, problem.mass_groups)
    if custom:  # E_i needs the model; a custom objective defines no points
        E_i = np.full(problem.n_points, np.nan)
    elif np.isfinite(top_E[0]):
        E_i = point_errors(problem, config, best_chi)
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


def simulate_fit(problem: EstimationProblem, config: Mapping, chi: np.ndarray) -> tuple[np.ndarray, bool]:
    """Simulated points (F, n, 2) at ``problem.frame_t`` for one chi, and whether the run stayed valid."""
    from .model import simulate_batch

    coeffs, mu = decode(np.atleast_2d(chi), config, problem.mass_groups)
    pos, ok = simulate_batch(coeffs, mu, problem.hand_t, problem.hand[None], np.zeros(1, np.int64),
                             problem.p_init[None], problem.l0, problem.psi0, problem.dt, problem.frame_t)
    return np.asarray(pos)[0], bool(np.asarray(ok)[0])


def point_errors(problem: EstimationProblem, config: Mapping, chi: np.ndarray) -> np.ndarray:
    """E_i of eq. (5) for one chi: (n,) m (:func:`stringcast.evaluation.per_point_errors`)."""
    from .evaluation import per_point_errors

    pos, _ = simulate_fit(problem, config, chi)
    return np.asarray(per_point_errors(problem.tracked, problem.valid, pos), float)


# ---------------------------------------------------------------------------
# Stage entry point
# ---------------------------------------------------------------------------
def run_estimation(tracks_parquet: Path, joints_csv: Path, campaign: Campaign, config: Mapping,
                   prev_params_json: Path | None, trial_index: int, out_params_json: Path,
                   out_fit_parquet: Path, earlier: tuple = ()) -> Estimate:
    """Estimate the parameters of one trial and write ``params.json`` and ``fit.parquet``.

    Args:
        tracks_parquet, joints_csv: the trial's tracked points and measured joint log.
        prev_params_json: the previous trial's ``params.json`` (chi_best of eq. 3) or None.
        trial_index: k >= 1, the number of executions so far (M of eq. 3); seed = estimation.seed + k.
        earlier: (tracks_parquet, joints_csv) pairs of earlier trials of the campaign, fitted
            together with this one (``estimation.joint_trials``; :func:`make_joint_objective`).
            params.json's ``E_mm`` is then the mean over the trials, ``E_trials_mm`` each one's.

    Raises:
        DataError: unreadable or inconsistent inputs (named). ConfigError: bad optimizer settings.
    """
    tracks = read_parquet(tracks_parquet, TRACK_COLUMNS)
    t_j, q_j, _ = read_joint_table(joints_csv)
    problem = build_problem(tracks, t_j, q_j, campaign, config, source=str(tracks_parquet))
    prev = read_json(prev_params_json) if prev_params_json else None
    chi0 = start_chi(prev, campaign.string, config, str(prev_params_json))
    k = max(1, int(trial_index))
    seed = int(config.get("estimation", {}).get("seed", 0)) + k
    earlier_problems = []
    for tr, jo in earlier:
        t_e, q_e, _ = read_joint_table(jo)
        earlier_problems.append(build_problem(read_parquet(tr, TRACK_COLUMNS), t_e, q_e, campaign, config,
                                              source=str(tr)))
    est = estimate(problem, config, chi0, k, seed, earlier=tuple(earlier_problems))
    E_trials = [float(make_objective(p, config)(est.chi[None])[0]) * 1000 for p in (*earlier_problems, problem)]

    _, mu_groups_all = decode(est.top_chi, config, np.arange(problem.n_groups))
    top = [{"E_mm": e * 1000, "coefficients": dict(zip(PARAM_NAMES, c)), "mu_groups": m, "chi": x}
           for e, c, m, x in zip(est.top_E, decode(est.top_chi, config, problem.mass_groups)[0], mu_groups_all,
                                 est.top_chi)]
    names = list(PARAM_NAMES) + ["mu_others"] + [f"mu_{i}" for i in campaign.string.special_points()]
    lo, hi, (mlo, mhi) = model_ranges(config)
    log_lo = np.log10(np.concatenate([lo, np.full(problem.n_groups, mlo)]))
    log_hi = np.log10(np.concatenate([hi, np.full(problem.n_groups, mhi)]))
    diag = diagnostics(est.chi_evaluated, est.E_evaluated, log_lo, log_hi, names, config)
    write_json(out_params_json, {
        "coefficients": dict(zip(PARAM_NAMES, est.coeffs)), "mu": est.mu, "mu_groups": mu_groups_all[0],
        "mass_groups": problem.mass_groups, "special_points": campaign.string.special_points(),
        "E_mm": est.E_m * 1000, "E_i_mm": est.E_i * 1000, "E_trials_mm": E_trials,
        "trials_fitted": [str(tr) for tr, _ in earlier] + [str(tracks_parquet)],
        "history": {"evaluations": est.history["evaluations"],
                    "best_E_mm": [e * 1000 for e in est.history["best_E_m"]]},
        "optimizer": est.optimizer, "seed": est.seed, "evaluations": est.n_evaluations,
        "blown_up": est.n_blown_up, "seconds": est.seconds, "M": k, "chi": est.chi,
        "chi_start": chi0, "chi_names": names, "top": top, "diagnostics": diag, "message": est.message,
        "t_motion_start_s": problem.t_motion_start,
        "t_sim_start_s": problem.frame_t[0], "frames_compared": len(problem.frame_t),
        "rest_fallback_points": list(problem.fallback_points), "dt_s": problem.dt})
    write_parquet(out_fit_parquet, fit_table(tracks, problem, config, est.chi, campaign.string.n_points))
    return est


def fit_table(tracks: pd.DataFrame, problem: EstimationProblem, config: Mapping, chi: np.ndarray,
              n: int) -> pd.DataFrame:
    """``fit.parquet``: ``frame, t_s, point, x_tracked_m, y_tracked_m, valid, x_sim_m, y_sim_m``.

    Every tracked frame and point 1..n; simulated values NaN outside the compared frames
    (or everywhere if the simulation blew up).
    """
    frames, t, xy, valid = tracks_arrays(tracks, n)
    sim = np.full_like(xy[:, 1:], np.nan)
    pos, ok = simulate_fit(problem, config, chi)
    idx = np.searchsorted(frames, problem.frames)
    sim[idx] = pos if ok else np.nan
    f, nn = len(frames), n
    return pd.DataFrame({
        "frame": np.repeat(frames, nn), "t_s": np.repeat(t, nn), "point": np.tile(np.arange(1, n + 1), f),
        "x_tracked_m": xy[:, 1:, 0].ravel(), "y_tracked_m": xy[:, 1:, 1].ravel(),
        "valid": valid[:, 1:].ravel(), "x_sim_m": sim[..., 0].ravel(), "y_sim_m": sim[..., 1].ravel()})
