"""The campaign page: one row per execution (the paper's Table 3), with what decides the next one.

Per execution: E, each stage's verdict (geometry, clock, tracking, fit: a letter-coded badge each), the
played motion's predicted and the measured closest approach, the hit, the share of frames the tip was
tracked in, and the next-motion prediction check (``prediction.json``: the previous estimate driven by
this execution's measured joints, its tip against the tracked tip). An execution is marked where its
motion was planned on a failed fit (its prediction is not to be trusted) or for another target than
the campaign's now (its predicted closest approach was to that target). Below the table, the next
motion file to play: the last trial's ``motion.csv``.

The campaign page is the one stage that reads folders: it lists every trial under ``data/<campaign>/``
and reads each one's results by the data contract's names.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from stringcast.core import (Campaign, DataError, Settings, TrialFiles, read_json, read_parquet, trial_result,
                             write_text)
from . import figures as figs
from .pages import (MALFORMED, _common, _env, _fmt, _motion_window, _tracked, closest_approach, floor_clearance,
                    measured_hit)
from .verdicts import stage_verdicts

STAGES = ("geometry", "clock", "tracking", "fit", "plan")
"""The campaign table's verdict columns (geometry and clock: the files they refine where the trial has
no sweep, :func:`stringcast.core.trial_result`; fit: params.json's verdict; plan: the verdict of the next motion
planned from this execution, its motion.json, :mod:`stringcast.plan.verdict`)."""


def _stage_times(results: Path) -> tuple[list, list]:
    """Wall seconds per rule from Snakemake's ``benchmark:`` files, per trial."""
    rows: dict[str, dict] = {}
    stages: list[str] = []
    for f in sorted((results / "benchmarks").glob("*.tsv")):
        stem = f.stem
        stage, _, k = stem.rpartition("_")
        if not k.isdigit():
            stage, k = stem, "-"
        try:
            s = float(pd.read_csv(f, sep="\t")["s"].iloc[0])
        except Exception:  # a benchmark file being written by a running job
            continue
        if stage not in stages:
            stages.append(stage)
        rows.setdefault(k, {})[stage] = f"{s:.1f}"
    return sorted(rows.items(), key=lambda kv: (not kv[0].isdigit(), int(kv[0]) if kv[0].isdigit() else 0)), stages


def write_campaign_report(data_dir: Path, results_dir: Path, campaign: Campaign, out: Path, *,
                          settings: Settings) -> None:
    """Write ``results/<campaign>/report.html``: one row per execution (paper Table 3; module doc).

    Parameters
    ----------
    data_dir : Path
        ``data/<campaign>/``: the trials' raw files (``trial_<k>/``).
    results_dir : Path
        ``results/<campaign>/``: the trials' products (``trial_<k>/``) and Snakemake's ``benchmarks/``.
    campaign : Campaign
        The resolved campaign (its target, string and arm).
    out : Path
        Where to write the page.
    settings : Settings
        Every stage's: the page names the method they make (:mod:`.provenance`) and
        reads the flight window (``motion``).

    Raises
    ------
    DataError
        A result file that is missing or malformed (named).
    """
    try:
        _write_campaign_report(Path(data_dir), Path(results_dir), campaign, Path(out), settings)
    except MALFORMED as exc:
        raise DataError(f"{results_dir}: a result file the campaign report reads is malformed "
                        f"({type(exc).__name__}: {exc})") from exc


def _fit_cell(params: dict) -> dict:
    """The campaign table's fit cell from a trial's ``params.json``: ``fit_status`` (ok, warn, fail or
    "not judged") and ``fit_cause`` (the likely cause where not ok, else "")."""
    row = stage_verdicts({"fit": params})["rows"][0]
    return {"fit_status": row["status"], "fit_cause": row["cause"] if row["status"] in ("warn", "fail") else ""}


def stage_cells(results: Path, params: dict) -> list[dict]:
    """The verdict columns of one execution (:data:`STAGES`): ``[{"stage", "status", "reason"}]`` (the
    status "not run" where the stage wrote no file; the first reason where it is not ok)."""
    cells = []
    for stage in STAGES:
        path = results / "motion.json" if stage == "plan" else trial_result(results, stage)[1]
        doc = params if stage == "fit" else (read_json(path) if path.is_file() else None)
        rows = stage_verdicts({stage: doc})["rows"]
        if not rows:
            cells.append({"stage": stage, "status": "not run", "reason": ""})
            continue
        row = rows[0]
        reason = row["reasons"][0] if row["reasons"] and row["status"] in ("warn", "fail") else ""
        cells.append({"stage": stage, "status": row["status"], "reason": reason})
    return cells


def other_target(played: dict, campaign: Campaign) -> str:
    """``"(x, y) mm"`` of the target a played motion was planned for where it is not the campaign's now
    (its ``motion.json``'s ``target``), else ``""``."""
    t = played.get("target") or {}
    try:
        xy = np.array([float(t["x_mm"]), float(t["y_mm"])]) / 1000
    except (KeyError, TypeError, ValueError):
        return ""
    return "" if np.allclose(xy, campaign.target.xy, atol=5e-4) else f"({xy[0] * 1000:.0f}, {xy[1] * 1000:.0f}) mm"


def _execution_row(k: int, dd: Path, rd: Path, campaign: Campaign, settings: Settings) -> tuple[dict, np.ndarray]:
    """One execution's row of the table, and its tracked tip over the motion and flight window (F, 2) m."""
    n = campaign.string.n_points
    params = read_json(rd / "params.json", mapping=True)
    tracks = read_parquet(rd / "tracks.parquet")
    t0, t1, played = _motion_window(TrialFiles(Path(), dd / "joints.csv", played=dd / "motion.json"),
                                    settings.motion, campaign.arm)
    t, xy, valid = _tracked(tracks, n)
    d, _ = closest_approach(t, xy[:, n], campaign.target.xy, t0, t1)
    hit, floor_note = measured_hit(d, floor_clearance(t, xy, t0, t1, campaign.arm.floor_y), campaign.target.radius)
    window = (t >= t0) & (t <= t1)
    prediction = read_json(rd / "prediction.json") if (rd / "prediction.json").is_file() else {}
    row = {"trial": k, "E_mm": _fmt(params.get("E_mm")), "measured_mm": _fmt(d * 1000, ".1f"),
           "predicted_mm": _fmt(played.get("closest_approach_mm"), ".1f"),
           "hit_measured": hit, "floor_note": floor_note,
           "tip_valid_pct": _fmt(float(valid[window, n].mean()) * 100 if window.any() else None, ".0f"),
           **_fit_cell(params), "stages": stage_cells(rd, params),
           "prediction_mm": _fmt(prediction.get("median_mm"), ".1f"),
           "prediction_p95_mm": _fmt(prediction.get("p95_mm"), ".1f"),
           "played_on_failed_fit": bool(played.get("planned_on_failed_fit")),
           "played_slack": bool(played.get("slack_at_predicted_hit")),
           "other_target": other_target(played, campaign)}
    return row, xy[window, n]


def _write_campaign_report(data_dir: Path, results_dir: Path, campaign: Campaign, out: Path,
                           settings: Settings) -> None:
    """:func:`write_campaign_report`'s work."""
    rows, tips = [], {}
    trials = sorted(int(p.name.split("_")[1]) for p in data_dir.glob("trial_*") if p.name.split("_")[1].isdigit())
    for k in trials:
        dd, rd = data_dir / f"trial_{k}", results_dir / f"trial_{k}"
        if not (rd / "params.json").exists():
            continue
        row, tip = _execution_row(k, dd, rd, campaign, settings)
        rows.append(row)
        tips[f"execution {k}"] = tip
    figures = []
    if tips:
        figures.append({"id": "fig-campaign-tips", "caption": "Tracked tip path of each execution during the "
                        "motion and flight window.", "src": figs.campaign_tips(tips, campaign.target.xy,
                                                                                 campaign.target.radius)})
    next_motion = None
    if rows and (results_dir / f"trial_{rows[-1]['trial']}" / "motion.csv").is_file():
        last = results_dir / f"trial_{rows[-1]['trial']}"
        nxt = read_json(last / "motion.json") if (last / "motion.json").is_file() else {}
        next_motion = {"href": f"trial_{rows[-1]['trial']}/motion.csv", "after": rows[-1]["trial"],
                       "hit_measured": rows[-1]["hit_measured"],
                       "failed_fit": bool(nxt.get("planned_on_failed_fit")),
                       "slack": bool(nxt.get("slack_at_predicted_hit")),
                       "predicted_mm": _fmt(nxt.get("closest_approach_mm"), ".1f")}
    timings, stages = _stage_times(results_dir)
    ctx = _common(campaign, f"Campaign {campaign.name}", settings)
    ctx.update(rows=rows, figures=figures, timings=timings, stages=stages, next_motion=next_motion,
               verdict_stages=STAGES)
    write_text(out, _env().get_template("campaign.html.j2").render(**ctx))
