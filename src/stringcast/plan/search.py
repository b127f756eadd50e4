"""Steps of :func:`stringcast.plan.planning.search` (the candidate search; its module doc says how):
the postures candidates start from, the candidate curves of one batch, the residual
correction's sets, and the ranking that keeps the best candidate so far."""
from __future__ import annotations


import numpy as np

from stringcast.core import Campaign, MotionSettings
from .motion import Motion, sample_control_points, sample_postures, start_box, valid_curves
from .prediction import Predictor


def start_postures(campaign: Campaign, motion: MotionSettings, rng: np.random.Generator,
                   previous: Motion | None) -> np.ndarray:
    """The initial postures (P, J) rad candidates start from: ``previous``'s q0 (P = 1) for a
    perturbation, else a pool of ``motion.posture_pool`` random postures drawn with ``rng``
    (:func:`stringcast.plan.motion.sample_postures`).

    Raises:
        ValueError: ``previous`` has no control points to perturb.
    """
    if previous is not None:
        if previous.control_points.shape[1] < 1:
            raise ValueError("search: the previous motion has no control points to perturb")
        return previous.q0[None]
    return sample_postures(campaign, rng, int(motion.posture_pool), float(motion.floor_margin_m),
                           box=start_box(motion), clearance=float(motion.hang_clearance_mm) / 1000)


def draw_candidates(arm, rate: float, rng: np.random.Generator, T: float, want: int, postures: np.ndarray,
                    previous: Motion | None, perturb: float, n_cp: int, alpha: float) -> list:
    """Up to ``want`` candidate motions of T s within the arm's limits, from rounds (at most 50) of
    4 * want curves: ``previous``'s control points moved by U(-perturb, +perturb) rad/s (V_N kept),
    else random curves (:func:`stringcast.plan.motion.sample_control_points`: n_cp points, alpha rad/s^2).
    Each is :func:`stringcast.plan.motion.valid_curves`' (control points (J, N), q0 (J,), q (M, J),
    posture index); [] when none fits."""
    cands = []
    for _ in range(50):
        if previous is not None:
            cps = previous.control_points[None] + rng.uniform(-perturb, perturb, (4 * want,) + previous.control_points.shape)
            cps[..., -1] = previous.control_points[:, -1]
        else:
            cps = sample_control_points(rng, T, arm.n_joints, n_cp, alpha, 4 * want)
        cands += valid_curves(arm, cps, T, rate, postures, rng)
        if len(cands) >= want:
            break
    return cands[:want]


def residual_correction(pl: Predictor, previous: Motion | None, observed: tuple | None, coeffs: np.ndarray,
                        mu: np.ndarray, ensemble: tuple[np.ndarray, np.ndarray] | None, equilibria: dict,
                        member_eq: dict) -> str:
    """Set ``pl``'s residual correction (:meth:`Predictor.set_residual`) from the played motion's tracked
    tip ``observed`` for the planning set coeffs (10,), mu (n,) and the ``ensemble``'s sets (K, 10),
    (K, n), each from its hanging equilibrium at ``previous``'s q0 (stored as posture 0 in
    ``equilibria`` (n, 2) and ``member_eq`` (K, n, 2)). Returns "" or why there is no correction;
    nothing is done without ``observed`` or ``previous``."""
    if observed is None or previous is None:
        return ""
    equilibria[0] = pl.equilibrium(previous.q0)
    sets_c, sets_mu, eq = coeffs[None], mu[None], equilibria[0][None]
    if ensemble is not None:
        member_eq[0] = np.stack([pl.equilibrium(previous.q0, c, m) for c, m in zip(*ensemble)])
        sets_c, sets_mu, eq = (np.concatenate(a) for a in ((sets_c, ensemble[0]), (sets_mu, ensemble[1]),
                                                           (eq, member_eq[0])))
    return pl.set_residual(previous, observed, eq, sets_c, sets_mu)


def keep_best(cands: list, T: float, d: np.ndarray, tm: np.ndarray, my: np.ndarray, ok: np.ndarray,
              hit: np.ndarray, scores: dict, floor_y: float, best: tuple | None,
              best_key: tuple | None, taut: dict | None = None) -> tuple[tuple | None, tuple | None]:
    """The best candidate so far and its ranking key, after one batch: cands (B,) of T s with closest
    approach d (B,) m at tm (B,) s, lowest point my (B,) m, valid ok (B,), hit (B,), (robust
    planner) scores {index: (hit share, margin m, d_min (K,) m)} and (``motion.taut_chord_share``)
    taut {index of a hit: (taut enough, chord share)}. The key ranks by the larger hit share, then a
    taut hit, then the larger margin, a hit, valid and above the floor, valid, the smaller d."""
    taut = taut or {}
    for b, c in enumerate(cands):
        share, margin, d_k = scores.get(b, (0.0, -np.inf, None))
        is_taut, chord = taut.get(b, (False, None))
        key = (-share, not is_taut, -margin if share > 0 else np.inf, not hit[b], not (ok[b] and my[b] >= floor_y),
               not ok[b], d[b] if np.isfinite(d[b]) else np.inf)
        if best_key is None or key < best_key:
            best_key = key
            best = (c, T, bool(hit[b]), float(d[b]), float(tm[b]), float(my[b]), share, margin, d_k, chord)
    return best, best_key
