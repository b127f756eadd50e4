"""The model's parameter sets: the paper's eq. (2) chi space, and the sets plans use.

* :func:`decode` / :func:`encode`: chi in [0, 1]^(10 + G) <-> the ten coefficients
  (k_s, c_s, k_h, c_h, k_sh, c_sh, C_c1, C_c2, k_ph, c_ph) on log scales over Table 2's
  ranges, and G group masses mu (Table 4's special points plus one shared value).
* :func:`first_parameters`: the first plan's set (no estimate yet).
* :func:`planned_parameters`, :func:`ensemble_parameters`: the estimate's best set and
  best K sets, read from ``params.json``.
* :func:`start_chi`: where the estimation's search starts (eq. 3's chi_best at m = 0).

Shared by the estimation and planning stages, so neither reaches into the other.
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from stringcast.core import ConfigError, DataError, ModelSettings, MotionSettings, PARAM_NAMES, model_ranges


# ---------------------------------------------------------------------------
# Parameter sets the model is simulated with
# ---------------------------------------------------------------------------
def first_parameters(model: ModelSettings, motion: MotionSettings, string) -> tuple[np.ndarray, np.ndarray]:
    """The first plan's set: coeffs (10,) Table 2 minima, mu (n,) = ``model.first_mu``; k_s per
    ``motion.first_k_s`` (below). ``model``, ``motion``: model and motion settings
    (:class:`~stringcast.core.ModelSettings`, :class:`~stringcast.core.MotionSettings`).

    ``carrying`` (default): at Table 2's minimum k_s = 1e3 N/m/kg the model's string cannot
    carry its own weight: the top segment of a hanging 10-point string (mu = 1) stretches by
    g n / k_s = 98 mm, 4.3 l0, beyond the 3 l0 blow-up limit. k_s is raised to the least value
    keeping the top segment's static strain at ``motion.first_max_strain`` (default 0.05):
    k_s = g sum(mu) / (strain l0). Such a string still stretches by tens of percent under a
    swing's centrifugal load.

    ``max`` (ours): Table 2's maximum k_s (but at least the carrying value): strings barely
    stretch. Re-planned offline over 28 first motions (types 1-7, motion seeds 0-3, the lab's
    physics as judge) the lab's tip missed by a median of 28 mm (8 hits, 20 within 45 mm)
    against 52 mm (6 hits, 12 within 45 mm) with ``carrying`` (docs/method.md, "First set").

    Raises:
        ConfigError: ``motion.first_k_s`` is neither ``carrying`` nor ``max``.
    """
    lo, hi, _ = model_ranges(model)
    mu = np.full(string.n_points, float(model.first_mu))
    coeffs = lo.copy()
    mode = str(motion.first_k_s)
    if mode not in ("carrying", "max"):
        raise ConfigError(f"motion.first_k_s: unknown {mode!r} (known: carrying, max)")
    coeffs[0] = max(lo[0], _k_s_carrying(motion, string, mu))
    if mode == "max":
        coeffs[0] = max(coeffs[0], hi[0])
    return coeffs, mu


def _k_s_carrying(motion: MotionSettings, string, mu: np.ndarray) -> np.ndarray:
    """The least k_s at which the top segment's static strain is ``motion.first_max_strain``:
    g sum(mu) / (strain l0), for mu (..., n) -> (...)."""
    strain = float(motion.first_max_strain)
    return 9.81 * np.sum(mu, axis=-1) / (strain * string.l0)


def planned_parameters(n_points: int, params: Mapping, source: str = "params.json") -> tuple[np.ndarray, np.ndarray]:
    """coeffs (10,), mu (n,) from an estimate's params.json. Raises DataError naming ``source``."""
    try:
        coeffs = np.array([float(params["coefficients"][k]) for k in PARAM_NAMES])
        mu = np.asarray(params["mu"], float)
    except (KeyError, TypeError, ValueError) as exc:
        raise DataError(f"{source}: needs 'coefficients' ({', '.join(PARAM_NAMES)}) and 'mu' ({exc})") from exc
    if mu.shape != (n_points,) or not np.all(np.isfinite(coeffs) & (coeffs > 0)) or not np.all(np.isfinite(mu) & (mu > 0)):
        raise DataError(f"{source}: mu must hold {n_points} positive values and the coefficients be positive and "
                        "finite (as Table 2's ranges)")
    return coeffs, mu


def ensemble_parameters(n_points: int, params: Mapping, source: str = "params.json") -> tuple[np.ndarray, np.ndarray]:
    """The robust planner's ensemble from an estimate's params.json ``top`` (best K sets, best first).

    Returns:
        coeffs (K, 10), mu (K, n) (group masses expanded with ``mass_groups``).

    Raises:
        DataError: naming ``source``, when ``top`` or ``mass_groups`` is missing or malformed.
    """
    try:
        groups = np.asarray(params["mass_groups"], int)
        top = params["top"]
        coeffs = np.array([[float(m["coefficients"][k]) for k in PARAM_NAMES] for m in top])
        mu = np.array([np.asarray(m["mu_groups"], float)[groups] for m in top])
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise DataError(f"{source}: the robust planner needs 'top' (entries with 'coefficients' and "
                        f"'mu_groups') and 'mass_groups' ({exc!r})") from exc
    if (len(top) < 1 or mu.shape != (len(top), n_points) or not np.all(np.isfinite(coeffs) & (coeffs > 0))
            or not np.all(np.isfinite(mu) & (mu > 0))):
        raise DataError(f"{source}: 'top' must hold >= 1 set of positive, finite coefficients and {n_points} "
                        "positive masses")
    return coeffs, mu


# ---------------------------------------------------------------------------
# Parameter vector (eq. 2)
# ---------------------------------------------------------------------------
def decode(chi: np.ndarray, model: ModelSettings, mass_groups: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (2): chi (..., 10 + G) -> coefficients (..., 10) and per-point mu (..., n), over the
    ranges of the model settings (:class:`~stringcast.core.ModelSettings`)."""
    lo, hi, (mlo, mhi) = model_ranges(model)
    chi = np.clip(np.asarray(chi, float), 0.0, 1.0)
    coeffs = lo * (hi / lo) ** chi[..., :len(lo)]
    mu_groups = mlo * (mhi / mlo) ** chi[..., len(lo):]
    return coeffs, mu_groups[..., np.asarray(mass_groups)]


def encode(coeffs: np.ndarray, mu_groups: np.ndarray, model: ModelSettings) -> np.ndarray:
    """Inverse of eq. (2): coefficients (10,) and group masses (G,) -> chi (10 + G,), clipped to [0, 1]."""
    lo, hi, (mlo, mhi) = model_ranges(model)
    c = np.log(np.asarray(coeffs, float) / lo) / np.log(hi / lo)
    m = np.log(np.asarray(mu_groups, float) / mlo) / np.log(mhi / mlo)
    return np.clip(np.concatenate([c, m]), 0.0, 1.0)


def start_chi(prev_params: Mapping | None, string, model: ModelSettings, motion: MotionSettings,
              source="params.json") -> np.ndarray:
    """chi_best at m = 0: the previous estimate's chi, else that of the first plan's set
    (:func:`first_parameters`: Table 2 minima but k_s, its masses per mass group)."""
    groups = string.mass_groups()
    n_groups = int(groups.max()) + 1
    if prev_params is None:
        coeffs, mu = first_parameters(model, motion, string)
        mu_groups = np.full(n_groups, float(model.first_mu))
        mu_groups[groups] = mu          # group 0 the plain points, g >= 1 the g-th special point
        return encode(coeffs, mu_groups, model)
    chi = prev_params.get("chi")
    if chi is not None and len(chi) == len(PARAM_NAMES) + n_groups:
        return np.clip(np.asarray(chi, float), 0.0, 1.0)
    try:
        coeffs = [prev_params["coefficients"][k] for k in PARAM_NAMES]
        mu_groups = prev_params["mu_groups"]
    except (KeyError, TypeError) as exc:
        raise DataError(f"{source}: needs 'chi' of length {len(PARAM_NAMES) + n_groups} or "
                        f"'coefficients' and 'mu_groups' ({exc})") from exc
    if len(mu_groups) != n_groups:
        raise DataError(f"{source}: mu_groups has {len(mu_groups)} entries, this string has {n_groups}")
    return encode(coeffs, mu_groups, model)
