"""How well the fitted model reproduces the tracked string, in figures the trial itself gives.

:func:`fit_figures` compares the simulated points of the estimate (``simulate_fit``) with the
tracked ones over the frames the fit compared (:class:`EstimationProblem`), never with ground
truth. Every figure is a share of the string's length L, a ratio of two errors of the same
trial, a correlation, or a count of frame periods, so that it means the same on any camera,
frame rate, string or arm: :mod:`stringcast.estimate.verdict` judges them.

The phases (controller time): *rest*, the compared frames before the joint log starts to move
(:func:`stringcast.core.arm.motion_start`); *moving*, every compared frame from then on (the
motion and the free flight after it), cut into three equal spans of time: *early*, *middle*,
*late*.

Figures (``None`` where the frames to compute one are missing):

* ``valid_share``: the share of (frame, point) entries tracked (valid) in the moving frames.
* ``error_median_mm``, ``error_p90_mm``: the distance tracked - simulated over the valid
  moving entries (eq. 4's d_i(k)); ``tip_error_median_mm``: the same for the tip p_n;
  ``error_share``: error_median / L.
* ``null_error_median_mm`` and ``skill``: the error of a model that does not swing at all (the
  rest state carried rigidly by the grasp point, :func:`rigid_pendant`) and 1 - error / that
  error: 0 means the fit explains no more of the string's motion than no dynamics at all.
* ``rest_error_mm``: the median error over the valid rest entries (None with fewer than
  ``MIN_FRAMES`` rest frames tracked); ``rest_gap_share``: how far beyond its own length any
  tracked rest point hangs from the grasp point, max_i (|p_i - grasp| - i l0) / L (0 when none
  does): a hanging string cannot do that, however stiff or heavy it is; ``rest_folded_points``:
  the tracked rest points nearer the point above than :data:`~stringcast.model.FOLD_CHORD_SHARE`
  l0 (:func:`~stringcast.model.folded_points`): the string folds within a segment there, which the model's
  straight segments cannot start from, so it moves while the arm is still.
* ``best_shift_ms``, ``best_shift_frames``, ``shift_gain``: the time that, added to the frames'
  times, makes tracked and simulated points agree best (the median error over the moving
  entries, searched over whole frame periods up to a quarter of the motion), and the error
  there over the error at no shift (1: no shift helps).
* ``speed_median_mm_s``: the model's point speed, median over the valid moving entries: what a
  clock error of dt moves a point by is dt times it (the fit's verdict weighs the clock's stated
  uncertainty with it).
* ``speed_correlation``: the rank correlation, over the moving frames, of the frame's median
  error with the model's median point speed: a clock error makes the error follow the speed.
* ``bias_share``: |mean residual vector| / mean residual length over the moving entries: 1
  for a constant offset (the whole string shifted), near 0 when errors point every way;
  ``bias_mm``: that mean vector (tracked - simulated, x and y); ``offset_gain``: the median
  error once that one offset is taken off every entry, over the median error (1: no offset
  helps; the twin of ``shift_gain`` for geometry).
* ``early_error_mm``, ``late_error_mm``: the median error of the early and late spans.
* ``frame_period_ms``: the median step between compared frames.
* ``inertia_share``, ``rotation_coupling``, ``swing_period_s``, ``inertia_points``: how the tracked
  string's chords answer the grasp's acceleration, against a pendulum of their own swing period, with no
  string model (:func:`stringcast.estimate.inertia.string_response`): about 1 for any string hanging in
  air; None where the motion or the tracked frames do not state it.
"""
from __future__ import annotations

import numpy as np

from stringcast.model import FOLD_CHORD_SHARE, folded_points
from .inertia import string_response
from .problem import EstimationProblem

MIN_FRAMES = 3
"""Fewest frames (with a valid point) a phase needs before a figure is computed on it."""


def rigid_pendant(problem: EstimationProblem) -> np.ndarray:
    """The null model: the rest state p_init carried rigidly by the grasp point (no swing).

    Returns:
        (F, n, 2) m at ``problem.frame_t``: p_init - grasp(t_0) + grasp(t).
    """
    g = np.stack([np.interp(problem.frame_t, problem.hand_t, problem.hand[:, j]) for j in (0, 1)], -1)
    return problem.p_init[None] - g[:1, None] + g[:, None]


def _median(d: np.ndarray, mask: np.ndarray) -> float | None:
    return float(np.median(d[mask])) if mask.any() else None


def _ranks(x: np.ndarray) -> np.ndarray:
    r = np.empty(len(x))
    r[np.argsort(x, kind="stable")] = np.arange(len(x))
    return r


def _rank_correlation(a: np.ndarray, b: np.ndarray) -> float | None:
    """Spearman's rank correlation of a and b (no ties correction); None with < MIN_FRAMES or a constant."""
    if len(a) < MIN_FRAMES:
        return None
    ra, rb = _ranks(a), _ranks(b)
    sa, sb = ra.std(), rb.std()
    if sa == 0 or sb == 0:
        return None
    return float(np.mean((ra - ra.mean()) * (rb - rb.mean())) / (sa * sb))


def best_shift(tracked: np.ndarray, valid: np.ndarray, sim: np.ndarray, rows: np.ndarray,
               max_shift: int) -> tuple[int, float, float]:
    """The whole-frame shift s that best matches tracked[k] with sim[k + s] over the frames ``rows``.

    Args:
        tracked, sim: (F, n, 2) m; valid: (F, n) bool; rows: (R,) frame indices compared;
        max_shift: the largest |s| tried (frames).

    Returns:
        (s, median error at s, median error at 0), m; (0, nan, nan) without valid entries.
        A shift that leaves fewer than half the entries in range is not tried.
    """
    rows = np.asarray(rows, int)
    f = len(sim)
    need = valid[rows].sum() / 2
    errs = {}
    for s in range(-max_shift, max_shift + 1):
        r = rows[(rows + s >= 0) & (rows + s < f)]
        m = valid[r]
        if m.sum() == 0 or m.sum() < need:
            continue
        errs[s] = float(np.median(np.linalg.norm(tracked[r] - sim[r + s], axis=-1)[m]))
    if 0 not in errs:
        return 0, float("nan"), float("nan")
    s_best = min(errs, key=lambda s: (errs[s], abs(s)))
    return s_best, errs[s_best], errs[0]


def fit_figures(problem: EstimationProblem, sim: np.ndarray, length_m: float, t_stop: float) -> dict:
    """The figures of the module doc for one trial's fit.

    Args:
        problem: the trial's problem (tracked points, rest state, grasp path, frame times).
        sim: (F, n, 2) m, the model's points at ``problem.frame_t`` with the estimate (NaN: blew up).
        length_m: the string's length L, m. t_stop: when the joint log stops moving, s (controller).

    Returns:
        A JSON-ready dict (module doc); lengths in mm, times in ms.

    Raises:
        ValueError: sim's shape is not the problem's (F, n, 2), or L <= 0.
    """
    tr, va, ft = problem.tracked, problem.valid, problem.frame_t
    sim = np.asarray(sim, float)
    if sim.shape != tr.shape or not length_m > 0:
        raise ValueError(f"fit_figures: sim {tr.shape} and L > 0 expected, got {sim.shape}, {length_m}")
    L = float(length_m)
    va = va & np.all(np.isfinite(sim), axis=-1)
    d = np.linalg.norm(tr - sim, axis=-1)                                    # (F, n)
    rest = ft < problem.t_motion_start
    moving = ~rest
    mv = va & moving[:, None]
    period = float(np.median(np.diff(ft)))
    out: dict = {"length_mm": L * 1000, "frame_period_ms": period * 1000, "frames_moving": int(moving.sum()),
                 "valid_share": float(problem.valid[moving].mean()) if moving.any() else None}
    err = _median(d, mv)
    out["error_median_mm"] = None if err is None else err * 1000
    out["error_p90_mm"] = float(np.percentile(d[mv], 90) * 1000) if mv.any() else None
    out["tip_error_median_mm"] = None if _median(d[:, -1], mv[:, -1]) is None else _median(d[:, -1], mv[:, -1]) * 1000
    out["error_share"] = None if err is None else err / L
    null = _median(np.linalg.norm(tr - rigid_pendant(problem), axis=-1), mv)
    out["null_error_median_mm"] = None if null is None else null * 1000
    out["skill"] = None if err is None or not null else 1.0 - err / null
    out.update(_rest_figures(problem, d, va, rest, L))
    out.update(_time_figures(problem, sim, d, va, moving, period, t_stop))
    inertia = string_response(problem.frame_t, problem.tracked, problem.valid, problem.hand_t, problem.hand)
    out.update({"inertia_share": inertia["inertia_share"], "rotation_coupling": inertia["rotation_coupling"],
                "swing_period_s": inertia["swing_period_s"], "inertia_points": inertia["points"]})
    return out


def _rest_figures(problem: EstimationProblem, d: np.ndarray, va: np.ndarray, rest: np.ndarray, L: float) -> dict:
    """``rest_error_mm`` and ``rest_gap_share`` (module doc)."""
    rv = va & rest[:, None]
    tracked_rest = rv.any(axis=1).sum() >= MIN_FRAMES
    g0 = np.array([np.interp(problem.frame_t[0], problem.hand_t, problem.hand[:, j]) for j in (0, 1)])
    i = np.arange(1, problem.n_points + 1)
    gap = np.linalg.norm(problem.p_init - g0, axis=1) - i * problem.l0
    known = np.setdiff1d(i, problem.fallback_points) - 1
    folds = folded_points(g0, problem.p_init, problem.l0, FOLD_CHORD_SHARE)
    return {"rest_error_mm": float(np.median(d[rv]) * 1000) if tracked_rest else None,
            "rest_gap_share": float(max(0.0, gap[known].max()) / L) if len(known) else None,
            "rest_folded_points": [int(i) for i in folds]}


def _time_figures(problem: EstimationProblem, sim: np.ndarray, d: np.ndarray, va: np.ndarray, moving: np.ndarray,
                  period: float, t_stop: float) -> dict:
    """The best time shift, the error's rank correlation with speed, the bias, early and late errors."""
    ft = problem.frame_t
    rows = np.nonzero(moving)[0]
    out = {"best_shift_ms": None, "best_shift_frames": None, "shift_gain": None, "speed_correlation": None,
           "bias_share": None, "bias_mm": None, "offset_gain": None, "early_error_mm": None, "late_error_mm": None,
           "speed_median_mm_s": None}
    if len(rows) < MIN_FRAMES or not va[rows].any():
        return out
    quarter = max(1, int(round(0.25 * max(t_stop - problem.t_motion_start, period) / period)))
    s, e_s, e_0 = best_shift(problem.tracked, va, np.nan_to_num(sim), rows, quarter)
    if np.isfinite(e_0) and e_0 > 0:
        out.update(best_shift_ms=s * period * 1000, best_shift_frames=s, shift_gain=e_s / e_0)
    point_speed = np.linalg.norm(np.gradient(sim, ft, axis=0), axis=-1)                  # (F, n)
    mv = va & moving[:, None] & np.isfinite(point_speed)
    if mv.any():
        out["speed_median_mm_s"] = float(np.median(point_speed[mv]) * 1000)
    speed = np.median(point_speed, axis=1)                                               # (F,)
    seen = rows[va[rows].any(axis=1)]
    per_frame = np.array([np.median(d[k][va[k]]) for k in seen])
    ok = np.isfinite(speed[seen])
    out["speed_correlation"] = _rank_correlation(per_frame[ok], speed[seen][ok])
    r = (problem.tracked - sim)[va & moving[:, None]]
    out["bias_share"] = float(np.linalg.norm(r.mean(axis=0)) / np.linalg.norm(r, axis=1).mean())
    out["bias_mm"] = (r.mean(axis=0) * 1000).tolist()
    e_0 = np.median(np.linalg.norm(r, axis=1))
    out["offset_gain"] = float(np.median(np.linalg.norm(r - r.mean(axis=0), axis=1)) / e_0) if e_0 > 0 else None
    edges = np.linspace(ft[rows[0]], ft[rows[-1]], 4)
    for key, lo, hi in (("early_error_mm", edges[0], edges[1]), ("late_error_mm", edges[2], edges[3])):
        m = va & ((ft >= lo) & (ft <= hi))[:, None]
        if m.any(axis=1).sum() >= MIN_FRAMES:
            out[key] = float(np.median(d[m]) * 1000)
    return out
