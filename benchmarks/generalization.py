"""Benchmark ``generalization``: the pipeline on setups it has never seen (issue 25).

Each of ``--setups`` seeded draws of the lab's family (:func:`stringcast_lab.draw_setup`:
resolution, colour, codec, fps, lens, view, light, background, board pose, the arm's look, the
calibration set, the trigger and the joint log) gets one string type (cycling 1-7) and that
type's first planned motion. The lab films it (and the draw's calibration shots); the
pipeline's own stages calibrate, sync, sweep, track and estimate it with the project's
settings, never reading the draw. Per setup, against the lab's truth (read here, by the
benchmark only):

* calibration: fx error (%), principal-point error (px), the pixel -> swing-plane mapping's
  error over the swing region (median and max, mm), and its verdict: those of the mapping the
  later stages use, the sweep's ``geometry.json`` (``*_before_sweep``: ``calibration.json``'s);
* sync: error of the offset the later stages use (``clock.json``'s) and its verdict
  (``*_before_sweep``: ``sync.json``'s);
* tracking: median and p95 point error (mm), valid share (points 1..n, every frame), and the
  valid share of the moving frames that ``tracking.json`` judges (a string that hangs behind the
  board after the motion is invisible, not mistracked: the two shares tell these apart);
* the fit: E (mm) and its verdict.

A **silent failure** is a setup whose every verdict says ok while tracking p95 > 5 mm, or the
sync error > 1 ms, or the principal point is off by more than 2 % of the image width, or fx by
more than 2 %. ``results/bench/generalization.json`` holds ``setups``, ``flagged`` (setups with
any verdict warn or fail), ``silent_failures``, ``median_mm``/``p95_mm``/``valid_share`` pooled
over the setups not flagged, ``sync_error_ms_max`` over those, ``per_setup`` (the draw and the
figures), and the library versions; ``generalization.png`` beside it plots each setup's errors
coloured by verdict.

Rendering is the cost (a 1280 x 1024 clip at 2000 fps is thousands of frames): about 1-6 min per
setup to film and 3-5 min to process, with two setups side by side on 2 cores. ``--work DIR``
keeps each setup's files and reuses the filmed ones, and the JSON is rewritten after every
setup (``complete: false`` until the last), so a run can be stopped and ``--resume``d.
``--quick``: 3 setups.

Run: ``python -m benchmarks.generalization [--setups 24] [--first 0] [--work DIR] [--jobs 2]
[--until film|...|estimate] [--from calibrate|sync|sweep|track|estimate|figures] [--resume] [--quick]
[--results NAME]``.

The stated uncertainties (sync's, the clock's, the mapping's) are held to the truth per setup:
the JSON's ``coverage`` gives per quantity the share of setups whose true error lies within the
stated interval, and ``sync_decisions`` how often the trigger kept or overruled was the nearer
candidate (:mod:`benchmarks.certainty`; ``generalization_coverage.png``).
"""
from __future__ import annotations

import argparse
import itertools
import json
import shutil
import tempfile
import time
import traceback
from contextlib import contextmanager
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.certainty import calibration_errors as _calibration_errors, plane_errors as _plane_errors
from benchmarks.common import BENCH_DIR, header, write

SILENT = {"tracking_p95_mm": 5.0, "sync_error_ms": 1.0, "principal_point_share": 0.02, "fx_share": 0.02}
"""The issue's limits beyond which an all-ok setup is a silent failure."""


def string_type(seed: int) -> int:
    """The string type (1-7) a setup's seed films: cycling with the seed, whichever seeds a run takes."""
    return 1 + seed % 7


def _filmed(trial: Path, string_type_: int) -> bool:
    """Whether ``trial`` holds a finished film of this string type: the lab writes ``ground_truth.json``
    last, and the benchmark ``film.json`` (the string type filmed) after it."""
    marker = trial.parent / "film.json"
    if not (trial / "ground_truth.json").exists():
        return False
    if marker.exists():
        return json.loads(marker.read_text()).get("string_type") == string_type_
    return True   # filmed before the marker existed


def _verdict(doc: dict | None) -> str:
    """A stage's verdict status from its JSON (``ok`` when the stage wrote none)."""
    return str(((doc or {}).get("verdict") or {}).get("status", "ok"))


STAGES = ("film", "calibrate", "sync", "sweep", "track", "estimate", "figures")
"""The steps of one setup, in order; ``--until`` stops after one of them (``figures``: as ``estimate``),
``--from figures`` reads every stage's outputs where they are there and only measures them."""


def run_setup(seed: int, string_type: int, config: dict, work: Path, until: str = "estimate", start: str = "film",
              results: str = "results", bias: tuple[float, float] | None = None) -> dict:
    """Film one drawn setup and run the pipeline's stages on it, from ``start`` up to ``until``
    (:data:`STAGES`; a stage before ``start`` whose output is in ``work`` is read, not rerun);
    its figures against the truth."""
    from stringcast_lab.campaign import tracking_errors
    from stringcast.core import read_json, resolve_campaign, settings_from_config, stage_kwargs
    from stringcast.estimate import run_estimation
    from stringcast.execute import execute
    from stringcast_lab import apply_setup, draw_setup, write_calibration_clip
    from stringcast.plan import run_first_plan
    from stringcast.calibrate import run_calibration
    from stringcast.sync import run_sync, run_sweep
    from stringcast.track import run_tracking

    from benchmarks.certainty import sweep_figures, sync_figures

    setup = draw_setup(seed)
    cfg = apply_setup(config, setup)
    settings = settings_from_config(cfg)
    d = work / f"setup_{seed}"
    campaign = resolve_campaign({"string": string_type, "target": 1}, cfg, f"gen_{seed}")
    trial, calib = d / "trial_1", d / "calib"
    row = {"seed": seed, "string_type": string_type, "draw": asdict(setup)}
    try:   # a stage that refuses, or the lab failing to film, is a result: its message is the verdict
        t0 = time.perf_counter()
        # without ground_truth.json (the lab writes it last) a run was stopped while filming; film.json says which string
        if start != "film" and not (_filmed(trial, string_type) and (calib / "ground_truth.json").exists()):
            raise FileNotFoundError(f"{d}: not filmed (or still filming), and --from {start} films nothing")
        if not _filmed(trial, string_type):
            shutil.rmtree(trial, ignore_errors=True)
            run_first_plan(campaign, d / "motion.csv", d / "motion.json", seed=seed, **stage_kwargs(run_first_plan, settings))
            execute(d / "motion.csv", "virtual", trial, campaign, settings.executor, cfg, seed=seed)
            (d / "film.json").write_text(json.dumps({"seed": seed, "string_type": string_type}))
        if not (calib / "ground_truth.json").exists():
            shutil.rmtree(calib, ignore_errors=True)
            write_calibration_clip(campaign, cfg, calib, seed=seed)
        row["film_seconds"] = time.perf_counter() - t0
        row["codec_written"] = read_json(trial / "ground_truth.json")["video"].get("codec_written")
        if until == "film":
            return row
        out = d / results
        out.mkdir(parents=True, exist_ok=True)
        if not _kept("calibrate", start, out / "calibration.json"):
            with biased_intrinsics(*(bias or (0.0, 0.0))):
                run_calibration(trial, calib, campaign, out / "calibration.json", **stage_kwargs(run_calibration, settings))
        cal_doc = read_json(out / "calibration.json")
        row["fx_error_pct"], row["principal_point_error_px"] = _calibration_errors(cal_doc, setup)
        row["calibration_verdict"] = _verdict(cal_doc)
        row["calibration_reasons"] = list((cal_doc.get("verdict") or {}).get("reasons") or [])
        truth = read_json(trial / "ground_truth.json")
        row["plane_error_median_mm"], row["plane_error_max_mm"] = _plane_errors(out / "calibration.json", truth["camera"])
        if until == "calibrate":
            return row
        sync_doc = (read_json(out / "sync.json") if _kept("sync", start, out / "sync.json") else
                    run_sync(trial, out / "calibration.json", campaign, out / "sync.json", **stage_kwargs(run_sync, settings)))
        row["sync_error_ms"] = (sync_doc["offset_s"] - truth["trigger_time_s"]) * 1000
        row["sync_verdict"] = _verdict(sync_doc)
        row.update(sync_figures(sync_doc, truth["trigger_time_s"], settings.sync.evidence_k))
        if until == "sync":
            return row
        geo, clock = ((read_json(out / "geometry.json"), read_json(out / "clock.json"))
                      if _kept("sweep", start, out / "clock.json") else
                      run_sweep(trial, out / "calibration.json", out / "sync.json", campaign, out / "geometry.json",
                                out / "clock.json", **stage_kwargs(run_sweep, settings)))
        # what the later stages use and plan on: the sweep's mapping and clock, and their verdicts
        for k in ("calibration_verdict", "calibration_reasons", "plane_error_median_mm", "plane_error_max_mm",
                  "sync_error_ms", "sync_verdict"):
            row[f"{k}_before_sweep"] = row[k]
        row["calibration_verdict"], row["calibration_reasons"] = _verdict(geo), list(geo["verdict"]["reasons"])
        row["plane_error_median_mm"], row["plane_error_max_mm"] = _plane_errors(out / "geometry.json", truth["camera"])
        row["sync_error_ms"] = (clock["offset_s"] - truth["trigger_time_s"]) * 1000
        row["sync_verdict"] = _verdict(clock)
        row["sweep"] = geo.get("sweep")
        row.update(sweep_figures(geo, clock, truth["trigger_time_s"], truth["camera"], out / "calibration.json",
                                 out / "geometry.json", campaign, trial / "joints.csv"))
        if until == "sweep":
            return row
        tracks = (pd.read_parquet(out / "tracks.parquet") if _kept("track", start, out / "tracking.json") else
                  run_tracking(trial, out / "geometry.json", out / "clock.json", campaign, out / "tracks.parquet",
                               **stage_kwargs(run_tracking, settings)))
        e, share = tracking_errors(tracks, pd.read_parquet(trial / "ground_truth.parquet"))
        row.update(tracking_median_mm=float(np.median(e)) if len(e) else None,
                   tracking_p95_mm=float(np.percentile(e, 95)) if len(e) else None, valid_share=float(share))
        row["tracking_errors_mm"] = np.asarray(e, float)
        row["tracking_verdict"] = _verdict(read_json(out / "tracking.json"))
        row["valid_share_moving"] = read_json(out / "tracking.json").get("valid_share")
        if until == "track":
            return row
        if not _kept("estimate", start, out / "params.json"):
            run_estimation(out / "tracks.parquet", trial / "joints.csv", campaign, None, 1, out / "params.json",
                           out / "fit.parquet", **stage_kwargs(run_estimation, settings))
        params = read_json(out / "params.json")
        row["E_mm"], row["fit_verdict"] = params["E_mm"], _verdict(params)
    except Exception as exc:   # a stage that refuses is a result: its message is the verdict
        row["error"] = f"{type(exc).__name__}: {exc}"
        row["traceback"] = traceback.format_exc(limit=3)
    return row


@contextmanager
def biased_intrinsics(fx_share: float = 0.0, pp_share: float = 0.0):
    """Within the block, every intrinsics the calibration stage judges comes out with fx and fy
    scaled by ``1 + fx_share`` and the principal point moved by ``pp_share`` of the image width
    along x: a calibration set that misleads by that much (the benchmark's emulation, for
    ``benchmarks/intrinsics_bias.py``; the stage's checks then judge these intrinsics, and the
    later stages use them). No change when both are 0."""
    if not (fx_share or pp_share):
        yield
        return
    from unittest import mock

    import stringcast.calibrate.calibration as stage

    real = stage.judged_intrinsics

    def biased(views, flags, st, *args, **kwargs):
        intr, quality, verdict = real(views, flags, st, *args, **kwargs)
        K = np.array(intr.K, float)
        K[0, 0] *= 1 + fx_share
        K[1, 1] *= 1 + fx_share
        K[0, 2] += pp_share * intr.image_size[0]
        return replace(intr, K=K), quality, verdict

    with mock.patch.object(stage, "judged_intrinsics", biased):
        yield


def _kept(stage: str, start: str, output: Path) -> bool:
    """Whether ``stage`` comes before ``start`` and its output is there to be read instead."""
    return STAGES.index(stage) < STAGES.index(start) and output.exists()


def _judge(row: dict, width_px: int) -> dict:
    """flagged (any verdict warn/fail, or a stage refused) and silent (all ok, yet beyond a limit)."""
    verdicts = [row.get(k, "ok") for k in ("calibration_verdict", "sync_verdict", "tracking_verdict", "fit_verdict")]
    flagged = "error" in row or any(v != "ok" for v in verdicts)
    beyond = []
    if (row.get("tracking_p95_mm") or 0) > SILENT["tracking_p95_mm"]:
        beyond.append("tracking p95")
    if abs(row.get("sync_error_ms") or 0) > SILENT["sync_error_ms"]:
        beyond.append("sync")
    if (row.get("principal_point_error_px") or 0) > SILENT["principal_point_share"] * width_px:
        beyond.append("principal point")
    if abs(row.get("fx_error_pct") or 0) > SILENT["fx_share"] * 100:
        beyond.append("fx")
    return {"flagged": bool(flagged), "beyond_limits": beyond, "silent_failure": bool(beyond and not flagged)}


def summarise(rows: list[dict], complete: bool, quick: bool) -> dict:
    """The benchmark's JSON from the per-setup rows (``coverage``, ``sync_decisions``:
    :mod:`benchmarks.certainty`)."""
    from benchmarks.certainty import PAIRS_BEFORE, coverage, overrule_confusion

    kept = [r for r in rows if not r["flagged"]]
    errors = np.concatenate([r["tracking_errors_mm"] for r in kept if "tracking_errors_mm" in r] or [np.zeros(0)])
    shares = [r["valid_share"] for r in kept if r.get("valid_share") is not None]
    syncs = [abs(r["sync_error_ms"]) for r in kept if r.get("sync_error_ms") is not None]
    moving = [r["valid_share_moving"] for r in kept if r.get("valid_share_moving") is not None]
    per_setup = [{k: v for k, v in r.items() if k != "tracking_errors_mm"} for r in rows]
    return {**header("generalization", quick), "complete": complete, "setups": len(rows),
            "flagged": sum(r["flagged"] for r in rows), "silent_failures": sum(r["silent_failure"] for r in rows),
            "median_mm": float(np.median(errors)) if errors.size else None,
            "p95_mm": float(np.percentile(errors, 95)) if errors.size else None,
            "valid_share": float(np.mean(shares)) if shares else None,
            "valid_share_moving": float(np.mean(moving)) if moving else None,
            "sync_error_ms_max": float(max(syncs)) if syncs else None, "silent_limits": SILENT,
            "coverage": coverage(rows), "coverage_goal": 0.9, "sync_decisions": overrule_confusion(rows),
            "coverage_before": coverage(rows, PAIRS_BEFORE),
            "sync_decisions_before": overrule_confusion(rows, "before_sync_chosen"),
            "per_setup": per_setup}


def figure(rows: list[dict], path: Path) -> None:
    """Each setup's tracking p95, sync error and principal-point error, coloured by its worst verdict."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colour = {"ok": "tab:green", "warn": "tab:orange", "fail": "tab:red"}
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
    for ax, key, label in zip(axes, ("tracking_p95_mm", "sync_error_ms", "principal_point_error_px"),
                              ("tracking p95 (mm)", "sync error (ms)", "principal point error (px)")):
        for r in rows:
            worst = "fail" if "error" in r else max((r.get(k, "ok") for k in (
                "calibration_verdict", "sync_verdict", "tracking_verdict", "fit_verdict")), key=("ok", "warn", "fail").index)
            v = r.get(key)
            ax.scatter(r["seed"], abs(v) if v is not None else np.nan, c=colour[worst], s=18)
        ax.set_xlabel("setup (seed)")
        ax.set_ylabel(label)
        ax.set_yscale("symlog", linthresh=1.0)
    fig.suptitle("generalization: each drawn setup, coloured by its worst verdict (green ok, orange warn, red fail)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _resumed(work: Path, seeds: list[int], until: str, results: str = "results") -> dict[int, dict]:
    """The rows of ``seeds`` that the last JSON holds for the same ``work`` and ``until`` (their
    tracking errors read back from each setup's files), by seed."""
    from stringcast_lab.campaign import tracking_errors

    path = BENCH_DIR / f"{bench_name(results)}.json"
    if not path.exists():
        return {}
    doc = json.loads(path.read_text())
    if doc.get("work", str(work)) != str(work) or doc.get("until", "estimate") != until:
        return {}
    rows = {}
    for r in doc.get("per_setup", []):
        d = work / f"setup_{r['seed']}"
        if r["seed"] not in seeds or "error" in r or not (d / results / "tracks.parquet").exists():
            continue
        r = {k: v for k, v in r.items() if k not in ("flagged", "beyond_limits", "silent_failure")}
        if "valid_share_moving" not in r and (d / results / "tracking.json").exists():   # rows of older runs
            r["valid_share_moving"] = json.loads((d / results / "tracking.json").read_text()).get("valid_share")
        r["tracking_errors_mm"] = tracking_errors(pd.read_parquet(d / results / "tracks.parquet"),
                                                  pd.read_parquet(d / "trial_1" / "ground_truth.parquet"))[0]
        rows[r["seed"]] = r
    return rows


def bench_name(results: str = "results") -> str:
    """The JSON's (and figure's) name: ``generalization``, or ``generalization_<results>`` for a run whose
    stages write into another folder of each setup (two runs on one ``--work`` side by side)."""
    return "generalization" if results == "results" else f"generalization_{results}"


def run(quick: bool = False, setups: int = 24, first: int = 0, work: Path | None = None, jobs: int = 1,
        until: str = "estimate", resume: bool = False, start: str = "film", results: str = "results") -> dict:
    """Run the benchmark (``benchmarks.run``'s interface); returns the JSON it wrote last.

    ``jobs`` setups run side by side (processes); the JSON is rewritten as each one ends, its
    rows in seed order. ``until`` (:data:`STAGES`) stops every setup after that step (``film``
    only fills ``work``; the JSON then holds no figures). ``resume``: the setups that the last
    JSON (same ``work`` and ``until``) holds without an error are taken from it, not rerun. ``start``:
    the stages before it read their outputs from ``work`` where there (a tracking change measured
    on the same calibrations and syncs). ``results``: the folder of each setup the stages write into
    (and read from), and the JSON's name (:func:`bench_name`)."""
    from benchmarks import certainty
    from concurrent.futures import ProcessPoolExecutor, as_completed

    from stringcast.core import load_config

    n = 3 if quick else setups
    config = load_config()
    work = work or Path(tempfile.mkdtemp(prefix="stringcast_generalization_"))
    seeds = list(range(first, first + n))
    done = _resumed(work, seeds, until, results) if resume else {}
    rows, doc = [], {}
    with ProcessPoolExecutor(max_workers=max(1, jobs)) as pool:
        futures = [pool.submit(run_setup, seed, string_type(seed), config, work, until, start, results)
                   for seed in seeds if seed not in done]
        for k, fut in enumerate(itertools.chain(done.values(), as_completed(futures))):   # lazily: each as it ends
            row = fut if isinstance(fut, dict) else fut.result()
            row.update(_judge(row, row["draw"]["width_px"]))
            rows.append(row)
            rows.sort(key=lambda r: r["seed"])
            print(f"setup {row['seed']}: " + ", ".join(f"{key} {row.get(key)}" for key in (
                "film_seconds", "calibration_verdict", "fx_error_pct", "principal_point_error_px", "plane_error_median_mm",
                "plane_error_max_mm", "sync_verdict",
                "sync_error_ms", "sync_chosen", "sync_offset_error_ms", "sync_stated_ms", "sync_video_error_ms",
                "sync_video_stated_ms", "sync_trigger_error_ms", "clock_error_ms", "clock_stated_ms",
                "mapping_error_p95_mm", "mapping_stated_mm", "tracking_median_mm", "tracking_p95_mm", "valid_share",
                "E_mm", "fit_verdict",
                "error") if key in row), flush=True)
            doc = summarise(rows, k == n - 1, quick)
            doc["until"], doc["work"], doc["start"], doc["results"] = until, str(work), start, results
            write(bench_name(results), doc)
            figure(rows, BENCH_DIR / f"{bench_name(results)}.png")
            certainty.figure(rows, BENCH_DIR / f"{bench_name(results)}_coverage.png")
    return doc


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--setups", type=int, default=24, help="how many drawn setups")
    p.add_argument("--first", type=int, default=0, help="the first setup's seed")
    p.add_argument("--work", type=Path, default=None, help="keep (and reuse) each setup's files here")
    p.add_argument("--quick", action="store_true", help="3 setups")
    p.add_argument("--jobs", type=int, default=1, help="setups run side by side (processes)")
    p.add_argument("--until", choices=STAGES, default="estimate", help="stop each setup after this step")
    p.add_argument("--resume", action="store_true", help="take the setups the last JSON holds (same --work) from it")
    p.add_argument("--from", dest="start", choices=STAGES, default="film",
                   help="read the outputs of the stages before this one from --work where they are there")
    p.add_argument("--results", default="results",
                   help="each setup's folder the stages write into (another name: a run beside the default one)")
    args = p.parse_args(argv)
    run(args.quick, args.setups, args.first, args.work, args.jobs, args.until, args.resume, args.start, args.results)


if __name__ == "__main__":
    main()
