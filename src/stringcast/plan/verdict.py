"""How sure is a planned motion's hit? The plan stage's verdict (``motion.json``'s ``verdict``).

A planned hit is a prediction of the model; how far to trust it depends on what the plan rests on,
and that is known when the plan is made. Measured over the lab's string families (both engines, the
default cord and the drawn materials; ``benchmarks/plan_verdict.py`` tabulates the stored loop runs'
steps, docs/method.md, "How sure is the next motion"):

* a **perturbation of the played motion** whose residual correction is small (the model's tip within
  the target's radius of the played motion's tracked tip, median over the motion) hits about nine
  times in ten (98 of 105 at stop 76; 0.87-0.97, 95 %): the correction is first order
  (:mod:`stringcast.plan.residual`), and a small error stays small under a small change of the motion;
* the same with the model further off than the target's radius hits about three times in five (44 of
  71; 0.50-0.72; by lab from 13 of 31 on MuJoCo's drawn materials to 8 of 10 on Elastica's default
  cord): the correction it rests on is larger than the hit's tolerance, and it moves with the motion;
* a **new motion** (random posture and T, after a far miss) has no measured correction and hits about
  two times in five (17 of 39), a **first motion** (no fit of this string yet) about one time in three
  (46 of 143);
* a plan on a **failed fit** rests on no usable estimate at all (``fail``);
* a plan whose best candidate **misses** under the model, or hits on a **slack** string (the note of
  :mod:`stringcast.plan.planning`), is doubtful by its own prediction.

The thresholds are in the target's own units (its radius), not the lab's: what decides whether a
first-order correction lands is its size against the tolerance it must land within.
"""
from __future__ import annotations

import math

from stringcast.core import Verdict

RESIDUAL_WARN_RADII = 1.0
"""A residual correction (median over the played motion) beyond this many target radii: warn."""
HIT_RATE = {"small_residual": "about nine times in ten", "large_residual": "about three times in five",
            "new": "about two times in five", "first": "about one time in three"}
"""How often such plans hit over the lab's families (module doc; ``results/bench/plan_verdict.json``)."""


def plan_basis(origin: str, hit: bool, radius_m: float, residual: dict | None = None,
               failed_fit: dict | None = None) -> str:
    """What a plan rests on, the first of :data:`BASES` that applies (module doc).

    Args:
        origin, hit, radius_m, residual, failed_fit: as :func:`plan_verdict`'s.

    Returns:
        ``failed_fit``, ``predicted_miss``, ``first``, ``new``, ``no_residual`` (no residual correction, or
        not finite), ``large_residual`` (beyond :data:`RESIDUAL_WARN_RADII` target radii) or ``small_residual``.
    """
    size = None if residual is None else residual.get("median_mm")
    if failed_fit is not None:
        return "failed_fit"
    if not hit:
        return "predicted_miss"
    if origin in ("first", "new"):
        return origin
    if size is None or not math.isfinite(size):
        return "no_residual"
    return "large_residual" if size > RESIDUAL_WARN_RADII * radius_m * 1000 else "small_residual"


BASES = ("failed_fit", "predicted_miss", "first", "new", "large_residual", "small_residual", "no_residual")
"""The bases :func:`plan_basis` names."""


def plan_verdict(origin: str, hit: bool, d_min_m: float, radius_m: float, residual: dict | None = None,
                 slack: bool = False, failed_fit: dict | None = None,
                 observed_miss_m: float = float("nan")) -> Verdict:
    """The plan stage's verdict on a planned motion (module doc).

    Parameters
    ----------
    origin : str
        How the motion was made (``motion.json``'s ``origin``): ``first``, ``perturbation``,
        ``wide_perturbation`` or ``new``.
    hit : bool
        Whether the model (residual-corrected where it was) predicts a hit.
    d_min_m, radius_m : float
        The predicted closest approach and the target's radius, m.
    residual : dict, optional
        The residual correction's summary (:meth:`stringcast.plan.residual.TipResidual.summary`:
        ``median_mm``), None without one.
    slack : bool
        The predicted hit is on a slack model string (first and new plans).
    failed_fit : dict, optional
        The fit verdict the plan was made on, where it is ``fail``.
    observed_miss_m : float
        The played motion's tracked miss, m (NaN: not read), for the reasons' wording.

    Returns
    -------
    Verdict
        ``fail`` on a failed fit; ``warn`` where the hit is doubtful; ``ok`` otherwise, its reason the
        certainty the families bear out (no reason where nothing was measured, e.g. no residual
        correction).
    """
    v, radius_mm = Verdict(), radius_m * 1000
    if failed_fit is not None:
        cause = failed_fit.get("likely_cause") or "not named"
        v = v.add("fail", f"planned on a failed fit (likely cause: {cause}): the estimate is not usable, so neither is "
                          "this motion's predicted hit: check before playing it")
    if not hit:
        v = v.add("warn", f"no candidate hits under the model: the best passes {d_min_m * 1000:.0f} mm from the "
                          f"target's centre (radius {radius_mm:.0f} mm)")
    if slack:
        v = v.add("warn", "the predicted hit is on a slack string, whose tip the model's guessed bending, damping and "
                          "drag place (such hits land about one time in six)")
    basis = plan_basis(origin, True, radius_m, residual)        # the motion's own basis, beside the above
    if basis == "first":
        return v.add("warn", "the first motion, planned before any fit of this string: first motions hit "
                             f"{HIT_RATE['first']} over the lab's string families; the next plan corrects this one's "
                             "tracked miss")
    if basis == "new":
        miss = f" after a tracked miss of {observed_miss_m * 1000:.0f} mm" if math.isfinite(observed_miss_m) else ""
        return v.add("warn", f"a new motion (random posture and T){miss}: no measured correction carries over to it, "
                             f"and such plans hit {HIT_RATE['new']} over the lab's string families")
    if basis == "no_residual":
        return v
    size = residual["median_mm"]
    if basis == "large_residual":
        return v.add("warn", f"the model is {size:.0f} mm off the played motion's tracked tip (median), more than the "
                             f"target's radius {radius_mm:.0f} mm: the hit rests on a correction larger than its "
                             f"tolerance, and such plans hit {HIT_RATE['large_residual']} over the lab's string families")
    return v.add("ok", f"the model is {size:.0f} mm off the played motion's tracked tip (median), within the target's "
                       f"radius {radius_mm:.0f} mm: such perturbations hit {HIT_RATE['small_residual']} over the lab's "
                       "string families")
