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
from numba import njit, prange


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


def _per_point_reference(tr, va, sim):
    """E_i (..., n) in NumPy, the reference :func:`_per_point_kernel` is held to (bit for bit):
    NaN where no valid frame, inf where a used distance is not finite."""
    with np.errstate(invalid="ignore", over="ignore"):
        d = np.linalg.norm(np.where(va[..., None], tr - sim, 0.0), axis=-1)     # (..., F, n)
    finite = np.isfinite(d)
    counts = va.sum(axis=0)                                                    # (n,)
    with np.errstate(invalid="ignore", divide="ignore"):
        e_i = np.where(finite, d, 0.0).sum(axis=-2) / counts
    e_i = np.where(np.any(~finite, axis=-2), np.inf, e_i)
    return np.where(counts > 0, e_i, np.nan)


@njit(parallel=True, cache=True, fastmath=False, error_model="numpy")
def _per_point_kernel(tr, va, sim):
    """E_i (B, n) of tr (F, n, 2), va (F, n) bool, sim (B, F, n, 2), as :func:`_per_point_reference`.

    The sums run over the frames in order, as NumPy's reduction over that (non-contiguous, n >= 2)
    axis does, so the result is the reference's bit for bit; candidates in parallel (``prange``). One pass and no
    (B, F, n) temporaries: E of a batch costs about a tenth of the NumPy version's time.
    """
    B, F, n = sim.shape[0], sim.shape[1], sim.shape[2]
    counts = np.zeros(n, np.int64)
    for f in range(F):
        for i in range(n):
            if va[f, i]:
                counts[i] += 1
    out = np.empty((B, n))
    for b in prange(B):
        for i in range(n):
            s = 0.0
            bad = False
            for f in range(F):
                if va[f, i]:
                    dx = tr[f, i, 0] - sim[b, f, i, 0]
                    dy = tr[f, i, 1] - sim[b, f, i, 1]
                    d = np.sqrt(dx * dx + dy * dy)
                    if np.isfinite(d):
                        s += d
                    else:
                        bad = True
            if counts[i] == 0:
                out[b, i] = np.nan
            elif bad:
                out[b, i] = np.inf
            else:
                out[b, i] = s / counts[i]
    return out


def _per_point(tr, va, sim):
    """E_i (..., n) (:func:`_per_point_kernel`; sim (F, n, 2) or (B, F, n, 2)). A single point (n = 1)
    takes the reference: NumPy then sums its one contiguous column pairwise, not in order."""
    if tr.shape[1] < 2:
        return _per_point_reference(tr, va, sim)
    batch = sim if sim.ndim == 4 else sim[None]
    e_i = _per_point_kernel(tr, va, np.ascontiguousarray(batch))
    return e_i if sim.ndim == 4 else e_i[0]


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
