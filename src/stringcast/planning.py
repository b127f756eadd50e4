"""Motion planning (paper Section V): the search for a motion that hits the target.

Candidates are motions of :mod:`stringcast.motion` (eq. (1) Bezier velocity curves
from an initial posture q0):

* T is drawn in ``motion.T_range_s`` and snapped to the controller period.
* Curves breaking position, speed, acceleration or floor limits
  (:func:`stringcast.arm.check_limits`) are regenerated.
* First motion: random initial postures (:func:`stringcast.motion.sample_postures`).
  Our choice: a pool of ``motion.posture_pool`` postures is drawn once and each
  candidate takes a pool posture its curve fits, so that the hanging equilibrium
  (the model's initial state) is computed once per posture. All candidates of one
  batch share one T. The parameter set is :func:`first_parameters`.
* Later motions (Section V.B): the previous motion's q0 and T are kept and each
  control point V_1..V_{N-1} is moved by U(-perturb, +perturb) rad/s (V_N stays 0).
  The parameter set is the last estimate (:func:`planned_parameters`).
* Hit test: :func:`stringcast.model.closest_approach_batch` over [0, T + flight
  window] from the hanging equilibrium with the planned parameters; a hit is
  d_min <= target radius, min_y >= floor and a valid simulation. After the first
  hit the search goes on for ``motion.extra_after_hit`` candidates and returns the
  hit with the smallest d_min; without a hit it returns the closest candidate with
  ``hit=False`` and a message.

Stage entry points: :func:`run_first_plan` and :func:`run_plan` write ``motion.csv``
and its ``motion.json`` sidecar (:func:`write_motion`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np

from .arm import check_limits, hand_pose
from .config import PARAM_NAMES, Campaign, ConfigError, model_ranges
from .files import DataError, read_json, write_joint_table, write_json
from .motion import (Motion, joint_paths, read_motion_json, sample_control_points, sample_postures, start_box,
                     time_grid)


LIMIT_MARGIN = 1e-3
"""Planned motions use at most (1 - LIMIT_MARGIN) of the speed and acceleration limits."""


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


# ---------------------------------------------------------------------------
# Parameter sets the model is simulated with
# ---------------------------------------------------------------------------
def first_parameters(config: Mapping, string) -> tuple[np.ndarray, np.ndarray]:
    """The first plan's set: coeffs (10,) Table 2 minima, mu (n,) = ``model.first_mu``; k_s lifted (see below).

    At Table 2's minimum k_s = 1e3 N/m/kg the model's string cannot carry its own
    weight: the top segment of a hanging 10-point string (mu = 1) stretches by
    g n / k_s = 98 mm, 4.3 l0, beyond the 3 l0 blow-up limit. Our choice: k_s is
    raised to the least value keeping the top segment's static strain at
    ``motion.first_max_strain`` (default 0.05): k_s = g sum(mu) / (strain l0).
    """
    lo, _, _ = model_ranges(config)
    mu = np.full(string.n_points, float(config["model"].get("first_mu", 1.0)))
    strain = float(config.get("motion", {}).get("first_max_strain", 0.05))
    coeffs = lo.copy()
    coeffs[0] = max(lo[0], 9.81 * mu.sum() / (strain * string.l0))
    return coeffs, mu


def planned_parameters(config: Mapping, n_points: int, params: Mapping,
                       source: str = "params.json") -> tuple[np.ndarray, np.ndarray]:
    """coeffs (10,), mu (n,) from an estimate's params.json. Raises DataError naming ``source``."""
    try:
        coeffs = np.array([float(params["coefficients"][k]) for k in PARAM_NAMES])
        mu = np.asarray(params["mu"], float)
    except (KeyError, TypeError, ValueError) as exc:
        raise DataError(f"{source}: needs 'coefficients' ({', '.join(PARAM_NAMES)}) and 'mu' ({exc})") from exc
    if mu.shape != (n_points,) or not np.all(np.isfinite(coeffs)) or not np.all(mu > 0):
        raise DataError(f"{source}: mu must hold {n_points} positive values and coefficients be finite")
    return coeffs, mu


# ---------------------------------------------------------------------------
# Candidate search
# ---------------------------------------------------------------------------
def _fast_limits(arm, dq: np.ndarray, qd: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Speed/acceleration test and the feasible q0 box per candidate: ok (B,), lo (B, J), hi (B, J)."""
    qdd = np.gradient(qd, 1.0 / rate, axis=-2)
    ok = np.all(np.max(np.abs(qd), axis=-2) <= arm.qd_max, axis=-1)
    ok &= np.all(np.max(np.abs(qdd), axis=-2) <= arm.qdd_max, axis=-1)
    lo = arm.q_min - dq.min(axis=-2)
    hi = arm.q_max - dq.max(axis=-2)
    return ok & np.all(lo <= hi, axis=-1), lo, hi


class _Planner:
    """Holds the planned parameter set, the target and the model settings for one plan."""

    def __init__(self, campaign: Campaign, config: Mapping, coeffs: np.ndarray, mu: np.ndarray):
        self.campaign, self.arm, self.config = campaign, campaign.arm, config
        self.mcfg = config.get("motion", {})
        self.coeffs, self.mu = np.asarray(coeffs, float), np.asarray(mu, float)
        self.rate = float(self.arm.controller_rate)
        self.flight = float(self.mcfg.get("flight_window_s", 0.5))
        self.dt = float(config["model"]["dt_s"])
        self.psi0 = np.radians(float(config["model"].get("psi0_deg", 0.0)))
        self.n, self.l0 = campaign.string.n_points, campaign.string.l0
        self.warnings: list[str] = []

    def equilibrium(self, q0: np.ndarray) -> np.ndarray:
        """Hanging equilibrium (n, 2) m at posture q0 with the planned parameters.

        If the model cannot settle (RuntimeError), the string hangs straight down
        instead and a warning is kept for the plan's message.
        """
        from .model import hanging_equilibrium, straight_hanging

        hp = hand_pose(self.arm, q0)
        try:
            return np.asarray(hanging_equilibrium(self.coeffs, self.mu, hp, self.l0, self.psi0, self.n, self.dt), float)
        except RuntimeError as exc:
            self.warnings.append(f"initial state straight down: {exc}")
            return np.asarray(straight_hanging(self.coeffs, self.mu, hp, self.l0, self.n), float)

    def hand_trajectory(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """q (..., K, J) over [0, T] -> hand_t (K + hold,) and hand (..., K + hold, 3), end held for the flight window."""
        hold = int(round(self.flight * self.rate))
        q_ext = np.concatenate([q, np.repeat(q[..., -1:, :], hold, axis=-2)], axis=-2)
        return np.arange(q_ext.shape[-2]) / self.rate, hand_pose(self.arm, q_ext)

    def evaluate(self, q: np.ndarray, T: float, p_init: np.ndarray):
        """Closest approach of B candidates q (B, K, J) from p_init (B, n, 2): d_min, t_min, min_y, ok (B,)."""
        from .model import closest_approach_batch

        hand_t, hand = self.hand_trajectory(q)
        b = len(q)
        d, tm, my, ok = closest_approach_batch(self.coeffs, self.mu, hand_t, np.ascontiguousarray(hand),
                                               np.arange(b, dtype=np.int64), np.ascontiguousarray(p_init),
                                               self.l0, self.psi0, self.dt, 0.0, T + self.flight,
                                               self.campaign.target.xy, self.arm.floor_y)
        return (np.asarray(d, float), np.asarray(tm, float), np.asarray(my, float), np.asarray(ok, bool))

    def tip_path(self, motion: Motion, p_init: np.ndarray, rate_hz: float = 200.0) -> np.ndarray:
        """Predicted tip path (S, 3) = (t, x, y) over [0, T + flight window]."""
        from .model import simulate

        hand_t, hand = self.hand_trajectory(motion.q)
        sample_t = np.arange(0.0, hand_t[-1] + 1e-12, 1.0 / rate_hz)
        pos, _ = simulate(self.coeffs, self.mu, hand_t, hand, p_init, self.l0, self.psi0, self.dt, sample_t)
        return np.column_stack([sample_t, np.asarray(pos)[:, -1, :]])


def _valid_curves(arm, cps: np.ndarray, T: float, rate: float, postures: np.ndarray, rng: np.random.Generator):
    """Keep the control-point sets (B, J, N) whose curve fits a posture: list of (cp, q0, q, posture index)."""
    dq, qd = joint_paths(cps, T, rate)
    ok, lo, hi = _fast_limits(arm, dq, qd, rate)
    out = []
    for b in np.nonzero(ok)[0]:
        fits = np.nonzero(np.all((postures >= lo[b] - 1e-12) & (postures <= hi[b] + 1e-12), axis=1))[0]
        if len(fits) == 0:
            continue
        i = int(rng.choice(fits))
        q = postures[i] + dq[b]
        rep = check_limits(arm, q, 1.0 / rate)
        # keep LIMIT_MARGIN below the speed/acceleration limits: the executor re-checks the
        # file after its 9-digit CSV rounding, which moves finite-difference accelerations
        if rep.ok and max(rep.velocity.max(), rep.acceleration.max()) <= 1.0 - LIMIT_MARGIN:
            out.append((cps[b], postures[i], q, i))
    return out


def search(campaign: Campaign, config: Mapping, coeffs: np.ndarray, mu: np.ndarray, rng: np.random.Generator,
           previous: Motion | None = None) -> PlanResult:
    """Search random motions (first plan) or perturbations of ``previous`` (later plans) for a hit.

    Args:
        coeffs (10,), mu (n,): the parameter set the model is simulated with.
        previous: the motion just played (its q0, T and control points are kept / perturbed).

    Returns:
        :class:`PlanResult` (hit=False with a message when no candidate hits).

    Raises:
        ConfigError: when no motion within the arm's limits can be generated at all.
    """
    from tqdm.auto import tqdm

    arm, mcfg = campaign.arm, config.get("motion", {})
    pl = _Planner(campaign, config, coeffs, mu)
    batch, max_cand = int(mcfg.get("batch", 64)), int(mcfg.get("max_candidates", 20000))
    extra = int(mcfg.get("extra_after_hit", 200))
    t_lo, t_hi = (float(x) for x in mcfg.get("T_range_s", [0.2, 1.2]))
    n_cp, alpha = int(mcfg.get("n_control_points", 6)), float(mcfg.get("alpha_max_rad_s2", 40.0))
    perturb = float(mcfg.get("perturb_rad_s", 0.5))
    if previous is not None:
        if previous.control_points.shape[1] < 1:
            raise ValueError("search: the previous motion has no control points to perturb")
        postures = previous.q0[None]
        fixed_T = previous.T
    else:
        margin = float(mcfg.get("floor_margin_m", 0.05))
        postures = sample_postures(campaign, rng, int(mcfg.get("posture_pool", 32)), margin, box=start_box(config))
    equilibria: dict[int, np.ndarray] = {}
    best, best_key, tried, first_hit, fails = None, None, 0, None, 0
    bar = tqdm(total=max_cand, desc="plan", unit="cand", disable=None)
    while tried < max_cand and (first_hit is None or tried < first_hit + extra):
        if previous is not None:
            T = fixed_T
        else:
            T = time_grid(rng.uniform(t_lo, t_hi), pl.rate)[1]
        want = min(batch, max_cand - tried)
        cands = []
        for _ in range(50):
            if previous is not None:
                cps = previous.control_points[None] + rng.uniform(-perturb, perturb, (4 * want,) + previous.control_points.shape)
                cps[..., -1] = previous.control_points[:, -1]
            else:
                cps = sample_control_points(rng, T, arm.n_joints, n_cp, alpha, 4 * want)
            cands += _valid_curves(arm, cps, T, pl.rate, postures, rng)
            if len(cands) >= want:
                break
        cands = cands[:want]
        if not cands:
            fails += 1
            if fails >= 20 or previous is not None:
                raise ConfigError(f"arm {arm.name}: no motion within the joint limits could be generated "
                                  f"({'perturbing the played motion' if previous is not None else 'random curves'}); "
                                  "check motion.alpha_max_rad_s2, T_range_s and the arm limits")
            continue
        fails = 0
        for _, _, _, i in cands:
            if i not in equilibria:
                equilibria[i] = pl.equilibrium(postures[i])
        q = np.stack([c[2] for c in cands])
        p_init = np.stack([equilibria[c[3]] for c in cands])
        d, tm, my, ok = pl.evaluate(q, T, p_init)
        hit = ok & (d <= campaign.target.radius) & (my >= arm.floor_y)
        for b, c in enumerate(cands):
            key = (not hit[b], not (ok[b] and my[b] >= arm.floor_y), not ok[b],
                   d[b] if np.isfinite(d[b]) else np.inf)
            if best_key is None or key < best_key:
                best_key = key
                best = (c, T, bool(hit[b]), float(d[b]), float(tm[b]), float(my[b]))
        tried += len(cands)
        bar.update(len(cands))
        if first_hit is None and hit.any():
            first_hit = tried
    bar.close()
    (cp, q0, q, i), T, hit, d, tm, my = best
    t, _ = time_grid(T, pl.rate)
    motion = Motion(t=t, q=q, T=T, control_points=cp, q0=q0)
    msgs = [] if hit else [f"no candidate hit in {tried} tried; returning the closest "
                           f"({d * 1000:.1f} mm from the target, radius {campaign.target.radius * 1000:.0f} mm)"]
    msgs += sorted(set(pl.warnings))[:1]
    return PlanResult(motion, hit, d, tm, my, tried, "; ".join(msgs), pl.tip_path(motion, equilibria[i]))


# ---------------------------------------------------------------------------
# Files and stage entry points
# ---------------------------------------------------------------------------
def write_motion(result: PlanResult, campaign: Campaign, config: Mapping, coeffs: np.ndarray, mu: np.ndarray,
                 seed: int, out_csv: Path, out_json: Path, kind: str) -> None:
    """Write ``motion.csv`` (t_s, q1_rad..) and its ``motion.json`` sidecar."""
    m = result.motion
    write_joint_table(out_csv, m.t, m.q)
    step = max(1, len(result.tip_path) // 400)
    write_json(out_json, {
        "kind": kind, "T_s": m.T, "control_points_rad_s": m.control_points, "q0_rad": m.q0,
        "controller_rate_hz": campaign.arm.controller_rate, "arm": campaign.arm.name,
        "params": dict(zip(PARAM_NAMES, coeffs)), "mu": mu,
        "predicted_tip_path": result.tip_path[::step], "closest_approach_mm": result.d_min * 1000,
        "closest_approach_t_s": result.t_min, "min_y_mm": result.min_y * 1000,
        "hit_predicted": result.hit, "candidates": result.candidates, "seed": seed,
        "flight_window_s": float(config.get("motion", {}).get("flight_window_s", 0.5)),
        "target": {"x_mm": campaign.target.x * 1000, "y_mm": campaign.target.y * 1000,
                   "radius_mm": campaign.target.radius * 1000},
        "message": result.message})


def _rng(config: Mapping, seed: int) -> np.random.Generator:
    return np.random.default_rng([int(config.get("motion", {}).get("seed", 0)), int(seed)])


def run_first_plan(campaign: Campaign, config: Mapping, out_csv: Path, out_json: Path, seed: int = 0) -> PlanResult:
    """First motion of a campaign, planned with :func:`first_parameters` (Table 2 minima, lifted k_s)."""
    coeffs, mu = first_parameters(config, campaign.string)
    result = search(campaign, config, coeffs, mu, _rng(config, seed))
    write_motion(result, campaign, config, coeffs, mu, seed, out_csv, out_json, "first")
    return result


def run_plan(params_json: Path, played_motion_json: Path, campaign: Campaign, config: Mapping, out_csv: Path,
             out_json: Path, seed: int = 0) -> PlanResult:
    """Next motion (Section V.B): the played motion's posture and T, perturbed control points, estimated parameters.

    Raises:
        DataError: unreadable params.json or a played motion.json without q0_rad, T_s, control_points_rad_s.
    """
    coeffs, mu = planned_parameters(config, campaign.string.n_points, read_json(params_json), str(params_json))
    previous = read_motion_json(played_motion_json, campaign.arm.n_joints, campaign.arm.controller_rate)
    result = search(campaign, config, coeffs, mu, _rng(config, seed), previous=previous)
    write_motion(result, campaign, config, coeffs, mu, seed, out_csv, out_json, "next")
    return result
