"""Estimation diagnostics (issue 4): which parameters a trial's motion pins down.

From every candidate a search evaluated (chi (N, D) in eq. (2)'s exponent space,
E (N,) in m) this module builds the report-ready ``diagnostics`` block of
``params.json``:

* ``ensemble`` (written as params.json's ``top``, not here): the best K parameter sets
  (K = ``estimation.top_k``, :func:`best_k`): the ensemble the robust planner
  (:mod:`stringcast.plan.planning`, ``motion.planner: robust``) scores motions under. With
  ``estimation.top_grasp_basins`` (off in ours), half of them from the hand spring's other
  basin when its best E is within ``near_best_tol`` of the best (:func:`best_k_two_basins`).
* ``near_best``: the candidates whose E is within ``estimation.near_best_tol`` (5 % by
  default) of the best, or the best K if fewer: the parameter sets this trial
  cannot tell apart.
* per parameter (the ten coefficients of Table 2, mu_others, one mu per special point):
  the best value, the log10 min/max and quartiles over ``near_best``, and the
  ``spread``: the near-best sets' chi range (max - min), which is the log10 range over
  Table 2's log10 range (0 = one value, 1 = the whole table range); ``iqr`` likewise
  with the quartiles. ``status`` is ``"pinned"`` when spread <= ``estimation.pinned_spread``
  and ``"loose"`` otherwise.

The settings are the estimation settings (:class:`~stringcast.core.EstimationSettings`).

Our choice, and why: the best K alone measure the optimizer more than the trial (the
paper's search samples ever closer to chi_best, so its best K sit close whatever the
motion); the sets within a tolerance of the best E, drawn from the whole search (its
wide early samples included), measure how flat E is along each parameter. A parameter
the motion does not excite stays "loose" because sets far apart in it reach nearly the
same E.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from stringcast.core import EstimationSettings


def checked(estimation: EstimationSettings) -> tuple[int, float, float]:
    """(top_k, near_best_tol, pinned_spread) of the estimation settings, checked.

    Raises:
        ValueError: top_k < 1, a negative tolerance or a spread outside (0, 1].
    """
    k = int(estimation.top_k)
    tol = float(estimation.near_best_tol)
    pinned = float(estimation.pinned_spread)
    if k < 1 or tol < 0 or not 0 < pinned <= 1:
        raise ValueError(f"estimation.top_k >= 1, near_best_tol >= 0 and 0 < pinned_spread <= 1 "
                         f"(got {k}, {tol}, {pinned})")
    return k, tol, pinned


BASIN_SPLIT = 0.5
"""The exponent chi of eq. (2) that splits a parameter's range into its lower and upper basin (for the
hand spring k_ph: weak and stiff grasp; :func:`best_k_two_basins`, ``optimizers.flipped_grasp``)."""


def upper_basin(chi):
    """True where chi (any shape, exponents of eq. (2) in [0, 1]) lies in the upper basin (>= BASIN_SPLIT)."""
    return np.asarray(chi) >= BASIN_SPLIT


def best_k(chi: np.ndarray, E: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The k lowest-E candidates: chi (min(k, N), D) and E (min(k, N),), best first (stable order)."""
    chi, E = np.asarray(chi, float), np.asarray(E, float)
    if chi.ndim != 2 or E.shape != chi.shape[:1]:
        raise ValueError(f"best_k: chi (N, D) and E (N,) expected, got {chi.shape}, {E.shape}")
    order = np.argsort(E, kind="stable")[:k]
    return chi[order], E[order]


def best_k_two_basins(chi: np.ndarray, E: np.ndarray, k: int, index: int, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """The robust planner's ensemble over both basins of one parameter (``estimation.top_grasp_basins``).

    chi[:, index] splits the candidates at BASIN_SPLIT into two basins (for the hand spring k_ph: weak and
    stiff, docs/method.md "Two basins of the hand spring"). When the other basin's best E is within
    ``tol`` of the best (E_other <= E_best (1 + tol)), the k sets are the best k - k // 2 of the
    best's basin and the best k // 2 of the other, sorted by E; else :func:`best_k`.

    Args:
        chi: (N, D) candidates, exponents of eq. (2) in [0, 1]. E: (N,) their E, m.
        k: sets kept (>= 1). index: the splitting parameter's column in chi. tol: share of E_best.

    Returns:
        chi (min(k, N), D), E (min(k, N),), best first; chi[0] and E[0] are :func:`best_k`'s.
    """
    top_chi, top_E = best_k(chi, E, k)
    if k < 2 or not np.isfinite(top_E[0]):
        return top_chi, top_E
    chi, E = np.asarray(chi, float), np.asarray(E, float)
    other = upper_basin(chi[:, index]) != upper_basin(top_chi[0, index])
    if not other.any() or not np.nanmin(E[other]) <= top_E[0] * (1 + tol):
        return top_chi, top_E
    own_chi, own_E = best_k(chi[~other], E[~other], k - k // 2)
    oth_chi, oth_E = best_k(chi[other], E[other], k // 2)
    return best_k(np.concatenate([own_chi, oth_chi]), np.concatenate([own_E, oth_E]), k)


def near_best(chi: np.ndarray, E: np.ndarray, k: int, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Candidates with E <= E_best (1 + tol), at least the best k: chi (S, D), E (S,), best first.

    With no finite E at all (every candidate blew up) the best k (all inf) are returned.
    """
    chi_s, E_s = best_k(chi, E, len(E))  # all, sorted
    s = min(k, len(E_s))
    if np.isfinite(E_s[0]):
        s = max(s, int(np.searchsorted(E_s, E_s[0] * (1 + tol), side="right")))
    return chi_s[:s], E_s[:s]


def parameter_spread(chi_set: np.ndarray, log10_lo: np.ndarray, log10_hi: np.ndarray, names: Sequence[str],
                     pinned_spread: float) -> list[dict]:
    """Per parameter: the spread of ``chi_set`` (S, D), best first, as in the module doc.

    Args:
        chi_set: (S, D) exponents of eq. (2) in [0, 1]. log10_lo, log10_hi: (D,) the
            Table 2 range of each parameter in log10. names: (D,) parameter names.

    Returns:
        D dicts: name, best, log10_best, log10_min, log10_max, log10_q25, log10_q75,
        table_decades, spread, iqr, status ("pinned" / "loose").
    """
    chi_set = np.asarray(chi_set, float)
    lo, hi = np.asarray(log10_lo, float), np.asarray(log10_hi, float)
    d = chi_set.shape[1] if chi_set.ndim == 2 else -1
    if chi_set.ndim != 2 or len(chi_set) < 1 or lo.shape != (d,) or hi.shape != (d,) or len(names) != d:
        raise ValueError(f"parameter_spread: chi_set (S >= 1, D), ranges (D,) and D names expected; got "
                         f"{chi_set.shape}, {lo.shape}, {hi.shape}, {len(names)}")
    span = hi - lo
    logs = lo + chi_set * span
    q25, q75 = np.percentile(chi_set, [25, 75], axis=0)
    spread = chi_set.max(axis=0) - chi_set.min(axis=0)
    out = []
    for j, name in enumerate(names):
        out.append({"name": str(name), "best": float(10 ** logs[0, j]), "log10_best": float(logs[0, j]),
                    "log10_min": float(logs[:, j].min()), "log10_max": float(logs[:, j].max()),
                    "log10_q25": float(lo[j] + q25[j] * span[j]), "log10_q75": float(lo[j] + q75[j] * span[j]),
                    "table_decades": float(span[j]), "spread": float(spread[j]), "iqr": float(q75[j] - q25[j]),
                    "status": "pinned" if spread[j] <= pinned_spread else "loose"})
    return out


def diagnostics(chi: np.ndarray, E: np.ndarray, log10_lo: np.ndarray, log10_hi: np.ndarray,
                names: Sequence[str], estimation: EstimationSettings) -> dict:
    """The ``diagnostics`` block of params.json (module doc).

    Args:
        chi: (N, D) every evaluated candidate; E: (N,) their E in m (inf = blew up).
        log10_lo, log10_hi: (D,) Table 2 ranges in log10; names: (D,).
        estimation: ``top_k``, ``near_best_tol``, ``pinned_spread`` (:class:`~stringcast.core.EstimationSettings`).

    Returns:
        {"top_k", "near_best_tol", "pinned_spread", "spread_measure", "near_best": {"count",
        "E_mm_max"}, "parameters": [per parameter, :func:`parameter_spread`], "pinned": [names],
        "loose": [names], "blown_up_share"}.

    Raises:
        ValueError: bad shapes or settings.
    """
    k, tol, pinned = checked(estimation)
    E = np.asarray(E, float)
    chi_nb, E_nb = near_best(chi, E, k, tol)
    params = parameter_spread(chi_nb, log10_lo, log10_hi, names, pinned)
    return {"top_k": k, "near_best_tol": tol, "pinned_spread": pinned,
            "spread_measure": "near-best sets' chi range (log10 range over Table 2's log10 range)",
            "near_best": {"count": len(E_nb), "E_mm_max": float(E_nb[-1] * 1000)},
            "parameters": params,
            "pinned": [p["name"] for p in params if p["status"] == "pinned"],
            "loose": [p["name"] for p in params if p["status"] == "loose"],
            "blown_up_share": float(np.mean(~np.isfinite(E))) if len(E) else 0.0}
