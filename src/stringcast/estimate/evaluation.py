"""The evaluation value E of the paper, eqs. (4)-(6) (docs/string_model.md, "Evaluation value E").

For frame k and mass point i (1..n):

    d_i(k) = sqrt((x_r,i(k) - x_s,i(k))^2 + (y_r,i(k) - y_s,i(k))^2)      (4)
    E_i    = mean of d_i(k) over the frames where point i was tracked     (5)
    E      = sum_i E_i (1 + w (i - 1)) / n                                (6)

with (x_r, y_r) tracked and (x_s, y_s) simulated (the seed's eq. (4) mixes x and y;
this is the distance the paper's Fig. 4 draws). Invalid tracked entries are left
out of the means. A point with no valid frame at all is left out of the sum, and
n counts only the points that have data, so E stays a weighted mean distance; the
weight (1 + w (i - 1)) still uses the point's own index i. All values in m.
"""
from __future__ import annotations

import numpy as np


def _check(tracked, valid, simulated):
    tr = np.asarray(tracked, dtype=float)
    va = np.asarray(valid)
    sim = np.asarray(simulated, dtype=float)
    if tr.ndim != 3 or tr.shape[2] != 2:
        raise ValueError(f"tracked: expected (F, n, 2), got shape {tr.shape}")
    if va.shape != tr.shape[:2]:
        raise ValueError(f"valid: expected {tr.shape[:2]} like tracked, got shape {va.shape}")
    if va.dtype != bool:
        raise ValueError(f"valid: expected a bool array, got {va.dtype}")
    if sim.shape[-3:] != tr.shape or sim.ndim not in (3, 4):
        raise ValueError(f"simulated: expected {tr.shape} or (B, *{tr.shape}), got shape {sim.shape}")
    if not np.all(np.isfinite(tr[va])):
        raise ValueError("tracked: non-finite positions marked valid")
    return tr, va, sim


def _per_point(tr, va, sim):
    """E_i (..., n): NaN where no valid frame, inf where a used distance is not finite."""
    with np.errstate(invalid="ignore", over="ignore"):
        d = np.linalg.norm(np.where(va[..., None], tr - sim, 0.0), axis=-1)     # (..., F, n)
    finite = np.isfinite(d)
    counts = va.sum(axis=0)                                                    # (n,)
    with np.errstate(invalid="ignore", divide="ignore"):
        e_i = np.where(finite, d, 0.0).sum(axis=-2) / counts
    e_i = np.where(np.any(~finite, axis=-2), np.inf, e_i)
    return np.where(counts > 0, e_i, np.nan)


def per_point_errors(tracked, valid, simulated) -> np.ndarray:
    """E_i of eq. (5): mean distance of point i over its valid frames.

    Args:
        tracked: (F, n, 2) m, tracked points 1..n. valid: (F, n) bool.
        simulated: (F, n, 2) or (B, F, n, 2) m, simulated at the same frame times.

    Returns:
        (n,) or (B, n) E_i in m; NaN for a point with no valid frame, inf for a
        point whose simulated position is not finite at one of its valid frames.

    Raises:
        ValueError: shapes that do not match, or non-finite tracked values marked valid.
    """
    return _per_point(*_check(tracked, valid, simulated))


def evaluation_value(tracked, valid, simulated, w):
    """E of eq. (6): tip-weighted mean of the per-point errors E_i.

    Args:
        tracked: (F, n, 2) m, valid: (F, n) bool, simulated: (F, n, 2) or (B, F, n, 2) m.
        w: tip weighting of eq. (6) (>= 0; the evaluation setting ``w``, :class:`~stringcast.core.EvaluationSettings`).

    Returns:
        E in m: a float for one simulation, a (B,) array for a batch. A candidate with
        a non-finite simulated position at a valid entry (a blow-up) gets +inf.

    Raises:
        ValueError: bad shapes, w < 0, or no valid tracked point at all.
    """
    if not (w >= 0 and np.isfinite(w)):
        raise ValueError(f"w must be finite and >= 0, got {w}")
    tr, va, sim = _check(tracked, valid, simulated)
    e_i = _per_point(tr, va, sim)
    has = va.any(axis=0)
    if not has.any():
        raise ValueError("evaluation_value: no valid tracked point in any frame")
    i = np.arange(1, tr.shape[1] + 1)
    weight = np.where(has, 1.0 + w * (i - 1), 0.0)
    E = np.sum(np.where(has, e_i, 0.0) * weight, axis=-1) / has.sum()
    return float(E) if np.ndim(E) == 0 else E
