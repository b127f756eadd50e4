"""Benchmark ``estimation``: E reached against evaluations and seconds, per optimizer (docs/results.md).

For each string type (quick: types 1 and 5) the lab films the campaign's first planned
motion (:func:`benchmarks.common.film_first_motion`) and the workflow's own stages
calibrate, sync (``video.yaml``) and track it, exactly as for ``benchmarks.tracking``.
The trial is then estimated as the workflow does for trial 1 (chi_best = the first
plan's set, M = 1, seed = estimation.seed + 1, ``estimation.run_estimation``):

* ``default``: the config's own settings, timed (``seconds_default``; goal <= 60 s).
* the reference, the paper's random search (eqs. 2-3), and CMA-ES and differential
  evolution, all at the same budget (``estimation.iterations``), each recording the
  best E after every evaluation. When the default optimizer is the random search,
  the default run *is* the paper's run (one run, not two). CMA-ES is run with three
  seeds (``--cmaes-seeds``): its evaluations to the paper's E are the median over them
  (the search is noisy; one seed's count varies by about 2x).

Figures, measured in this run, per string type: ``paper_E_mm`` (the random search's
final E), ``paper_evals`` (its budget), ``cmaes_evals_to_paper_E`` /
``de_evals_to_paper_E`` (the first evaluation whose best-so-far E is <= paper_E_mm;
null if never within the budget), the E traces (subsampled) and seconds per optimizer;
overall ``median_eval_ratio_cmaes`` (cmaes_evals_to_paper_E / paper_evals, a type where
CMA-ES never gets there counts as inf; goal <= 0.2) and ``seconds_default_max``.
``ruggedness``: E along ``PROBE_DIRECTIONS`` random unit directions u in chi space from the
paper search's final set chi*, at the steps ``PROBE_STEPS``: E(chi* + h u) / E(chi*) per
direction and step, and ``basin_radius_chi`` (median over the directions of the smallest
step at which E rises by more than 10 %). A radius of a few 1e-3 says the paper's final E
sits in a narrow pocket of a rugged surface, which its eq. (3) finds by sampling ever closer
around its best set for thousands of evaluations; no optimizer finds such pockets in a few
hundred. ``pocket``: the share of ``POCKET_SAMPLES`` uniform samples in the box chi* +- r
(r in ``POCKET_RADII``, clipped) whose E is <= E(chi*), and their median E / E(chi*): a share
of 1e-3 means even a sampler that already knows chi* needs about a thousand evaluations to
match it. ``dt_halved_mm``: the largest point distance between the model at chi* run with
dt and with dt / 2 at 25/50/75/100 % of the compared window; where it grows to tens of mm
late in the window, E there compares the film with the integrator's chaos (the whip after
the arm stops), which is why the surface is rugged (the stiffness switch k_sh / k_h is not the
cause: E is nearly as rugged with it removed, measured once by hand on type 7).
Figure: best E against evaluations per type, the three optimizers
(results/bench/estimation.png).

``--prediction`` (issue 27: an estimate is judged by how it predicts the next motion): the
workflow's next motion is planned from the default run's estimate (``plan.run_plan``, the
config's planner), played on the lab and calibrated, synced and tracked like the first; then
each optimizer's estimate (the CMA-ES seeds' each) predicts it
(:func:`stringcast.estimate.prediction.run_prediction`: driven by its measured joints, the
model's tip against the tracked tip from the motion's start to the tip's closest approach).
Per type and optimizer ``prediction``: ``median_mm``, ``p95_mm``, ``valid_frames``, ...; overall
``prediction_error_mm`` per optimizer (the median over the types; CMA-ES: of each type's median
over its seeds). It films and tracks a second trial per type (about as long as the first), so it
is an option; without it these keys are absent.

Run: ``python -m benchmarks.estimation [--quick] [--prediction] [--work DIR]`` ->
results/bench/estimation.json. ``--work`` keeps the filmed and tracked trials in DIR and reuses
them in a later run (the estimations are always run anew).
"""
from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import (
    BENCH_DIR,
    film_first_motion,
    header,
    lab_calibration_clip,
    write,
)

OPTIMIZERS = ("random_search", "cmaes", "de")
TRACE_POINTS = 200
PROBE_STEPS = (1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 1e-1)
PROBE_DIRECTIONS = 6
POCKET_RADII = (0.0025, 0.01)
POCKET_SAMPLES = 500


def prepare(string_type: int, config: dict, settings, calib_dir: Path, work: Path, seed: int):
    """Film, calibrate, sync and track one string type's first motion (reused if ``work`` has it).

    ``settings``: the stages' settings (:class:`stringcast.core.Settings`) of ``config``.
    Returns (campaign, d): ``d`` holds tracks.parquet and trial_1/joints.csv."""
    from stringcast.core import resolve_campaign

    d = work / f"string_{string_type}"
    if (d / "tracks.parquet").exists() and (d / "trial_1" / "joints.csv").exists():
        return resolve_campaign({"string": string_type, "target": 1}, config, f"bench_{string_type}"), d
    campaign, d, trial = film_first_motion(string_type, config, work, seed, calib_dir)
    _sync_and_track(trial, d, campaign, settings)
    return campaign, d


def _sync_and_track(trial: Path, d: Path, campaign, settings) -> None:
    """Sync, sweep and track a calibrated trial (``d/calibration.json``) into ``d``, as the workflow does."""
    from stringcast.core import stage_kwargs
    from stringcast.sync import run_sweep, run_sync
    from stringcast.api import run_tracking

    run_sync(trial, d / "calibration.json", campaign, d / "sync.json", **stage_kwargs(run_sync, settings))
    run_sweep(trial, d / "calibration.json", d / "sync.json", campaign, d / "geometry.json", d / "clock.json",
              **stage_kwargs(run_sweep, settings))
    run_tracking(trial, d / "geometry.json", d / "clock.json", campaign, d / "tracks.parquet",
                 **stage_kwargs(run_tracking, settings))


def prepare_next(campaign, d: Path, config: dict, settings, calib_dir: Path, seed: int) -> Path:
    """The next motion, planned from ``d``'s default estimate (``params_<default optimizer>.json``),
    played on the lab, calibrated, synced and tracked into ``d/next`` (reused if there). Returns
    ``d/next``: tracks.parquet and trial_2/joints.csv."""
    from stringcast.api import run_calibration
    from stringcast.core import stage_kwargs
    from stringcast.api import execute
    from stringcast.api import run_plan

    nxt = d / "next"
    if (nxt / "tracks.parquet").exists() and (nxt / "trial_2" / "joints.csv").exists():
        return nxt
    default = str(settings.estimation.optimizer)
    run_plan(d / f"params_{default}.json", d / "trial_1" / "motion.json", campaign, nxt / "motion.csv",
             nxt / "motion.json", seed, d / "tracks.parquet", d / "trial_1" / "joints.csv",
             **stage_kwargs(run_plan, settings))
    trial = nxt / "trial_2"
    execute(nxt / "motion.csv", "virtual", trial, campaign, settings.executor, config, seed=seed + 1000)
    run_calibration(trial, calib_dir, campaign, nxt / "calibration.json", **stage_kwargs(run_calibration, settings))
    _sync_and_track(trial, nxt, campaign, settings)
    return nxt


def predict_next(campaign, d: Path, nxt: Path, settings, tags: list[str]) -> dict:
    """Each estimate ``d/params_<tag>.json`` predicting the next trial in ``nxt`` (module doc): per tag
    :func:`stringcast.estimate.prediction.run_prediction`'s figures, or ``error`` when it cannot."""
    from stringcast.core import DataError, stage_kwargs
    from stringcast.api import run_prediction

    out = {}
    for tag in tags:
        try:
            doc = run_prediction(d / f"params_{tag}.json", nxt / "tracks.parquet", nxt / "trial_2" / "joints.csv",
                                 campaign, nxt / f"prediction_{tag}.json", **stage_kwargs(run_prediction, settings))
            out[tag] = {k: v for k, v in doc.items() if k not in ("params", "tracks", "joints")}
        except DataError as exc:
            out[tag] = {"error": str(exc)}
    return out


def prediction_summary(per: dict) -> dict:
    """Per optimizer, the median over the types of its next-motion prediction error, mm (CMA-ES: each
    type's median over its seeds; a blow-up counts as inf; None without a figure)."""
    def figure(doc):
        return np.inf if doc.get("blew_up") else doc.get("median_mm")
    out = {}
    for name in OPTIMIZERS:
        vals = []
        for r in per.values():
            pred = r.get("prediction") or {}
            tags = [t for t in pred if t == name or t.startswith(f"{name}_")]
            errs = [e for e in (figure(pred[t]) for t in tags) if e is not None]
            if errs:
                vals.append(float(np.median(errs)))
        out[name] = float(np.median(vals)) if vals else None
    return out


def _estimate(campaign, d: Path, settings, optimizer: str | None, tag: str, seed_offset: int = 0):
    from stringcast.core import stage_kwargs
    from stringcast.api import run_estimation

    estimation = dataclasses.replace(settings.estimation, seed=int(settings.estimation.seed) + seed_offset,
                                     **({} if optimizer is None else {"optimizer": optimizer}))
    kwargs = stage_kwargs(run_estimation, settings) | {"estimation": estimation}
    return run_estimation(d / "tracks.parquet", d / "trial_1" / "joints.csv", campaign, None, 1,
                          d / f"params_{tag}.json", d / f"fit_{tag}.parquet", **kwargs)


def evals_to_reach(trace: np.ndarray, level: float) -> int | None:
    """The first evaluation count (1-based) at which the best-so-far ``trace`` is <= ``level``, else None."""
    hit = np.nonzero(np.asarray(trace) <= level * (1 + 1e-12))[0]
    return int(hit[0]) + 1 if len(hit) else None


def ruggedness(campaign, d: Path, settings, chi_star: np.ndarray, seed: int = 0) -> dict:
    """E around ``chi_star`` (module doc): {"steps", "E_ratio" (dirs, steps), "basin_radius_chi",
    "pocket" (per radius), "dt_halved_mm"}."""
    from stringcast.api import build_problem, make_objective
    from stringcast.core import TRACK_COLUMNS, read_parquet
    from stringcast.core import read_joint_table

    t_j, q_j = read_joint_table(d / "trial_1" / "joints.csv", n_joints=campaign.arm.n_joints,
                                 arm_name=campaign.arm.name)
    problem = build_problem(read_parquet(d / "tracks.parquet", TRACK_COLUMNS), t_j, q_j, campaign,
                            model=settings.model, evaluation=settings.evaluation, estimation=settings.estimation,
                            tracking=settings.tracking)
    objective = make_objective(problem, settings.model)
    u = np.random.default_rng(seed).standard_normal((PROBE_DIRECTIONS, len(chi_star)))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    h = np.array(PROBE_STEPS)
    chi = np.clip(chi_star[None, None] + h[None, :, None] * u[:, None], 0.0, 1.0).reshape(-1, len(chi_star))
    E0 = float(objective(np.asarray(chi_star, float)[None])[0])
    ratio = objective(chi).reshape(PROBE_DIRECTIONS, len(h)) / E0
    first = [float(h[np.argmax(r > 1.1)]) if np.any(r > 1.1) else None for r in ratio]
    radius = float(np.median([np.inf if f is None else f for f in first]))
    rng = np.random.default_rng(seed + 1)
    pocket = {}
    for r in POCKET_RADII:
        E = objective(np.clip(chi_star + r * rng.uniform(-1, 1, (POCKET_SAMPLES, len(chi_star))), 0.0, 1.0))
        pocket[str(r)] = {"share_at_or_below_E0": float(np.mean(E <= E0)),
                          "median_E_ratio": float(np.median(E[np.isfinite(E)]) / E0) if np.isfinite(E).any() else None}
    return {"steps": list(PROBE_STEPS), "E_ratio": ratio.tolist(), "E0_mm": E0 * 1000,
            "rise_10pct_step": first, "basin_radius_chi": radius if np.isfinite(radius) else None,
            "pocket": pocket, "dt_halved_mm": dt_halved(problem, settings.model, chi_star)}


def dt_halved(problem, model, chi_star: np.ndarray) -> dict:
    """How far the model's points move when dt is halved, at chi_star: the largest distance over the
    points (mm) between the runs at dt and dt / 2, at 25, 50, 75 and 100 % of the compared window.
    Large late values say the late frames compare the film with the integrator's chaos, not physics."""
    from stringcast.api import simulate_fit

    p1, _ = simulate_fit(problem, model, chi_star)
    p2, _ = simulate_fit(dataclasses.replace(problem, dt=problem.dt / 2), model, chi_star)
    gap = np.linalg.norm(p1 - p2, axis=2).max(axis=1) * 1000
    t = problem.frame_t - problem.frame_t[0]
    at = {f"{q}%": float(gap[min(len(t) - 1, np.searchsorted(t, t[-1] * q / 100))]) for q in (25, 50, 75, 100)}
    return {"window_s": float(t[-1]), **at}


def _trace(est) -> np.ndarray:
    return np.minimum.accumulate(np.asarray(est.E_evaluated, float)) * 1000


def _subsample(trace: np.ndarray) -> dict:
    idx = np.unique(np.geomspace(1, len(trace), TRACE_POINTS).astype(int)) - 1
    return {"evaluations": (idx + 1).tolist(), "best_E_mm": [float(v) for v in trace[idx]]}


def one_string(campaign, d: Path, settings, cmaes_seeds: int = 1) -> dict:
    """Estimate one tracked trial with the default settings and with every optimizer at equal budget
    (CMA-ES with ``cmaes_seeds`` seeds: its evaluations to the paper's E are the median over them)."""
    default = str(settings.estimation.optimizer)
    t0 = time.perf_counter()
    runs = {default: _estimate(campaign, d, settings, None, default)}
    seconds_default = time.perf_counter() - t0
    for name in OPTIMIZERS:
        if name not in runs:
            runs[name] = _estimate(campaign, d, settings, name, name)
    traces = {name: _trace(est) for name, est in runs.items()}
    paper = traces["random_search"]
    paper_E = float(paper[-1])
    cma_runs = [traces["cmaes"]] + [_trace(_estimate(campaign, d, settings, "cmaes", f"cmaes_{s}", s))
                                    for s in range(1, cmaes_seeds)]
    cma_reach = [evals_to_reach(tr, paper_E) for tr in cma_runs]
    out = {"paper_E_mm": paper_E, "paper_evals": len(paper), "seconds_default": seconds_default,
           "default_optimizer": default, "frames_compared": None,
           "optimizers": {name: {"E_mm": float(tr[-1]), "evaluations": len(tr),
                                 "seconds": float(runs[name].seconds), "blown_up": int(runs[name].n_blown_up),
                                 "trace": _subsample(tr)} for name, tr in traces.items()}}
    n = evals_to_reach(traces["de"], paper_E)
    out["de_evals_to_paper_E"], out["de_eval_ratio"] = n, (n / len(paper)) if n is not None else None
    med = float(np.median([np.inf if n is None else n for n in cma_reach]))
    out["cmaes_evals_to_paper_E"] = int(med) if np.isfinite(med) else None
    out["cmaes_eval_ratio"] = med / len(paper) if np.isfinite(med) else None
    out["cmaes_seeds"] = {"evals_to_paper_E": cma_reach, "final_E_mm": [float(tr[-1]) for tr in cma_runs]}
    from stringcast.core import read_json

    out["frames_compared"] = read_json(d / f"params_{default}.json")["frames_compared"]
    out["ruggedness"] = ruggedness(campaign, d, settings, np.asarray(runs["random_search"].chi, float))
    return out


def _figure(per: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = sorted(per, key=int)
    cols = min(4, len(keys))
    rows = int(np.ceil(len(keys) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.8 * rows), squeeze=False)
    for ax, k in zip(axes.ravel(), keys):
        for name, style in zip(OPTIMIZERS, ("k-", "C0-", "C1--")):
            tr = per[k]["optimizers"][name]["trace"]
            ax.plot(tr["evaluations"], tr["best_E_mm"], style, lw=1.2,
                    label={"random_search": "paper (eqs. 2-3)", "cmaes": "CMA-ES", "de": "DE"}[name])
        ax.axhline(per[k]["paper_E_mm"], color="0.6", lw=0.8, ls=":")
        n = per[k]["cmaes_evals_to_paper_E"]
        if n is not None:
            ax.axvline(n, color="C0", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(f"string type {k}", fontsize=9)
        ax.set_xlabel("evaluations", fontsize=8)
        ax.set_ylabel("best E (mm)", fontsize=8)
    for ax in axes.ravel()[len(keys):]:
        ax.axis("off")
    axes.ravel()[0].legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(quick: bool = False, work: Path | None = None, cmaes_seeds: int = 3, prediction: bool = False) -> dict:
    from stringcast.core import settings_from_config
    from stringcast.core import load_config

    config = load_config()
    settings = settings_from_config(config)
    types = [1, 5] if quick else sorted(int(k) for k in config["strings"])
    per = {}
    with tempfile.TemporaryDirectory(prefix="bench_estimation_") as tmp:
        work = Path(work) if work else Path(tmp)
        calib = work / "calib"
        if not calib.exists():
            lab_calibration_clip(config, work)
        for k in types:
            t0 = time.perf_counter()
            campaign, d = prepare(k, config, settings, calib, work, seed=k)
            t_film = time.perf_counter() - t0
            per[str(k)] = r = one_string(campaign, d, settings, cmaes_seeds)
            if prediction:
                tags = list(r["optimizers"]) + [f"cmaes_{s}" for s in range(1, cmaes_seeds)]
                r["prediction"] = predict_next(campaign, d, prepare_next(campaign, d, config, settings, calib, k),
                                               settings, tags)
            print(f"  string {k}: paper E {r['paper_E_mm']:.2f} mm in {r['paper_evals']} evals; CMA-ES reaches it "
                  f"after {r['cmaes_evals_to_paper_E']}, DE after {r['de_evals_to_paper_E']}; E rises 10 % within "
                  f"{r['ruggedness']['basin_radius_chi']} (chi) of its set, "
                  f"{r['ruggedness']['pocket'][str(POCKET_RADII[0])]['share_at_or_below_E0']:.2%} of samples "
                  f"within +-{POCKET_RADII[0]} match it; default "
                  f"{r['seconds_default']:.1f} s (film+track {t_film:.0f} s)", flush=True)
    ratios = [r["cmaes_eval_ratio"] if r["cmaes_eval_ratio"] is not None else np.inf for r in per.values()]
    figure = BENCH_DIR / "estimation.png"
    _figure(per, figure)
    est = settings.estimation
    doc = header("estimation", quick) | {
        "per_string": per, "median_eval_ratio_cmaes": float(np.median(ratios)),
        "median_eval_ratio_de": float(np.median([r["de_eval_ratio"] if r["de_eval_ratio"] is not None else np.inf
                                                 for r in per.values()])),
        "seconds_default_max": float(max(r["seconds_default"] for r in per.values())),
        "median_basin_radius_chi": float(np.median([r["ruggedness"]["basin_radius_chi"] or np.inf
                                                    for r in per.values()])),
        "median_pocket_share": {str(rad): float(np.median([r["ruggedness"]["pocket"][str(rad)]["share_at_or_below_E0"]
                                                           for r in per.values()])) for rad in POCKET_RADII},
        "goals": {"seconds_default_max": 60.0, "median_eval_ratio_cmaes": 0.2},
        "reference": {"name": "paper_random_search", "optimizer": "random_search",
                      "evaluations": int(est.iterations), "chi0": est.chi0, "beta": est.beta},
        "settings": est.as_dict(), "figure": figure.name,
    } | ({"prediction_error_mm": prediction_summary(per)} if prediction else {})
    write("estimation", doc)
    return doc


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="string types 1 and 5 only")
    ap.add_argument("--work", type=Path, help="keep (and reuse) the filmed, tracked trials here")
    ap.add_argument("--cmaes-seeds", type=int, default=3, help="CMA-ES runs per string type (median)")
    ap.add_argument("--prediction", action="store_true",
                    help="film a second (planned) motion per type and report each optimizer's prediction of it")
    a = ap.parse_args()
    run(a.quick, a.work, a.cmaes_seeds, a.prediction)
