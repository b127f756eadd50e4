"""Does the tracking's verdict hold over the lab's string materials? -> results/bench/tracking_verdicts.json.

The filmed campaigns of a loop benchmark's video check (``benchmarks.loop --mode video --work DIR``:
drawn materials, both engines, both methods) carry the lab's truth beside each trial
(``ground_truth.parquet``, read here by the benchmark only). For every trial this compares what
``tracking.json`` says (its verdict and reasons, its stated ``error_scale_mm``, the seen length's
spread) with the tracked points' true error (median, p95, p99 over the valid points 1..n) and with
how much the lab's string truly stretched (the p95 over the frames of its true polyline's length
from the grasp to the tip, less L; a polyline through n + 1 points, so a lower bound on the arc).

With ``--retrack OUT`` the tracking stage of the code being measured is run again on each trial
(its ``geometry.json`` and ``clock.json`` as the campaign computed them) into
``OUT/<campaign>/<trial>/``, where a run already there is read, not redone; without it, the
campaign's own ``tracks.parquet`` and ``tracking.json`` are judged.

A trial is **silent** when its true p95 passes ``SILENT_P95_MM`` (the generalization benchmark's
silent-failure bound) and its verdict says ok; a **false alarm** when a reason of its verdict says the
points may be off (any but the valid share's, which says how many were not tracked, a fact) while
their true p95 is within the tracking goal ``GOAL_P95_MM``.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.common import header, write
from benchmarks.generalization import SILENT

GOAL_P95_MM = 3.0
"""The tracking goal's p95 (docs/data_contract.md): what the later stages can bear."""
SILENT_P95_MM = SILENT["tracking_p95_mm"]


def trials(work: Path):
    """(campaign folder, results trial folder, data trial folder) of every filmed trial under ``work``."""
    for camp in sorted(p for p in work.iterdir() if (p / "run.json").exists()):
        for res in sorted(camp.glob("results/*/trial_*")):
            data = camp / "data" / res.parent.name / res.name
            if (res / "tracking.json").exists() and (data / "ground_truth.parquet").exists():
                yield camp, res, data


def campaign_of(camp: Path):
    """(config, resolved campaign) a filmed campaign folder ran with."""
    import yaml

    from stringcast.core import load_campaign

    found = sorted((camp / "results" / ".stringcast").glob("*/campaign-*.yaml"))
    if not found:
        raise FileNotFoundError(f"{camp}: no results/.stringcast/*/campaign-*.yaml (the campaign's resolved file, "
                                "written when its workflow ran): not a loop benchmark's campaign folder")
    cfg = yaml.safe_load((camp / "config" / "config.yaml").read_text())
    return cfg, load_campaign(found[0], cfg, require_target=False)


def retrack(cfg: dict, campaign, res: Path, data: Path, out: Path) -> Path:
    """Run the tracking stage on one filmed trial of the campaign (``cfg``, ``campaign``: :func:`campaign_of`)
    into ``out`` (kept where done); returns ``out``."""
    from stringcast.core import settings_from_config, stage_kwargs
    from stringcast.track import run_tracking

    if (out / "tracking.json").exists():
        return out
    out.mkdir(parents=True, exist_ok=True)
    run_tracking(data, res / "geometry.json", res / "clock.json", campaign, out / "tracks.parquet",
                 **stage_kwargs(run_tracking, settings_from_config(cfg)))
    return out


def true_figures(tracks: pd.DataFrame, truth: pd.DataFrame, L: float) -> dict:
    """The valid points' true error (mm: median, p95, p99; :func:`stringcast_lab.campaign.tracking_errors`) and
    the true string's stretch (mm: p95 over the frames of its polyline's length from the grasp to the tip
    less L ``m``)."""
    from stringcast_lab.campaign import tracking_errors

    e, _ = tracking_errors(tracks, truth)
    t = truth.sort_values(["frame", "point"])
    xy = t[["x_m", "y_m"]].to_numpy(float).reshape(t["frame"].nunique(), -1, 2)
    length = np.linalg.norm(np.diff(xy, axis=1), axis=2).sum(axis=1)
    q = (lambda p: float(np.percentile(e, p))) if len(e) else (lambda p: None)
    return {"true_median_mm": q(50), "true_p95_mm": q(95), "true_p99_mm": q(99),
            "true_stretch_p95_mm": float(np.percentile(length - L, 95) * 1000)}


def judge(work: Path, retrack_dir: Path | None = None) -> list[dict]:
    """One row per filmed trial under ``work`` (module doc)."""
    rows, todo, campaigns = [], list(trials(work)), {}
    for i, (camp, res, data) in enumerate(todo, 1):
        run = json.loads((camp / "run.json").read_text())
        if camp not in campaigns:
            campaigns[camp] = campaign_of(camp)
        cfg, campaign = campaigns[camp]
        src = retrack(cfg, campaign, res, data, retrack_dir / camp.name / res.name) if retrack_dir else res
        doc = json.loads((src / "tracking.json").read_text())
        L = campaign.string.length
        row = {"campaign": camp.name, "trial": res.name, "physics": run.get("physics"), "method": run.get("method"),
               "material": run.get("material"), "string_type": run.get("string"), "verdict": doc["verdict"]["status"],
               "reasons": doc["verdict"]["reasons"], "valid_share": doc["valid_share"],
               "error_scale_mm": doc.get("error_scale_mm"), "length_mismatch_mm": doc["length_mismatch_mm"],
               "stretch": doc.get("stretch")}
        row.update(true_figures(pd.read_parquet(src / "tracks.parquet"), pd.read_parquet(data / "ground_truth.parquet"), L))
        rows.append(row)
        print(f"[{i}/{len(todo)}] {camp.name}/{res.name}: tracking {row['verdict']}, true p95 "
              f"{row['true_p95_mm'] or float('nan'):.1f} mm", flush=True)
    return rows


VALID_SHARE_REASON = "tracking: only "
"""How the valid share's reason begins (:func:`stringcast.track.quality.tracking_verdict`)."""


def claims_error(row: dict) -> bool:
    """The verdict says the tracked points may be off: a reason other than the valid share's."""
    return any(not r.startswith(VALID_SHARE_REASON) for r in row.get("reasons", ()))


def summarise(rows: list[dict]) -> dict:
    """Counts of trials, warnings, silent trials and false alarms (module doc), and which trials."""
    p95 = [r["true_p95_mm"] or 0.0 for r in rows]
    warn = [r["verdict"] != "ok" for r in rows]
    name = [f"{r['campaign']}/{r['trial']}" for r in rows]
    return {"trials": len(rows), "warn": int(sum(warn)),
            "beyond_goal": int(sum(p > GOAL_P95_MM for p in p95)),
            "silent": [n for n, p, w in zip(name, p95, warn) if p > SILENT_P95_MM and not w],
            "false_alarms": [n for n, p, r in zip(name, p95, rows) if p <= GOAL_P95_MM and claims_error(r)],
            "goal_p95_mm": GOAL_P95_MM, "silent_p95_mm": SILENT_P95_MM}


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--work", type=Path, required=True, help="a loop benchmark's video work folder")
    p.add_argument("--retrack", type=Path, default=None, help="run this code's tracking into this folder")
    args = p.parse_args(argv)
    rows = judge(args.work, args.retrack)
    doc = {**header("tracking_verdicts", False), "work": str(args.work), "retracked": args.retrack is not None,
           **summarise(rows), "per_trial": rows}
    print(json.dumps({k: v for k, v in doc.items() if k != "per_trial"}, indent=1))
    print(f"-> {write('tracking_verdicts', doc)}")


if __name__ == "__main__":
    main()
