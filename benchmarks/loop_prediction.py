"""Benchmark ``loop_prediction``: estimators compared on the same data and the same next motion (issue 27).

The loop benchmark's prediction error (``loop.json``) compares each method on the motions *it*
played: ours, which hits sooner, is judged on fewer and harder steps than the paper's method, on
other motions. This benchmark takes the estimator alone. For every paper-method campaign of a
loop run (``--work``) with a second execution, each variant estimates trial 1 as the workflow's
``estimate`` rule does (its tracked points and joint log, the campaign's own config with the
variant's overlay merged last, ``stringcast estimate``), and then predicts trial 2's tip from
trial 2's measured joint log (``stringcast predict``, :mod:`stringcast.estimate.prediction`). Every
variant sees the same training trial and the same test motion.

Variants: ``paper`` (the paper's estimator, ``estimation.optimizer: random_search``, ``w`` 0.1),
``ours`` (``config/ours.yaml``'s model, evaluation and estimation sections) and any ``--overlay
NAME=FILE`` (a YAML merged over the campaign's config, as the other two).

Figures per physics and variant: ``median_mm`` (the median over campaigns of each campaign's
median tip error, mm), ``mean_mm``, ``campaigns``; per variant other than ``paper``,
``paired_diff_mm`` (the mean over campaigns of its error minus the paper's) with a 95 % bootstrap
interval (campaigns resampled, as ``loop.json``'s intervals). ``rows``: every campaign's figures, and the E the
fit reached. The estimates are cached under ``--out`` (rerunning skips what exists).

Run: ``python -m benchmarks.loop_prediction --work /path/to/loop/work [--physics mujoco] [--seeds 0 1 2]``
-> ``results/bench/loop_prediction.json``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import yaml

from benchmarks.common import ROOT, header, write
from benchmarks.loop_summary import bootstrap_ci

SECTIONS = ("model", "evaluation", "estimation")
"""The config sections an estimate reads that a variant may set (ours' motion settings plan, not fit)."""
def variants(extra: dict[str, Path]) -> dict[str, dict]:
    """{name: config overlay}: the paper's estimator (``config/paper.yaml``'s estimate sections), ours
    (the settings' defaults: no overlay) and ``extra``'s files.

    Raises:
        FileNotFoundError: an overlay file is missing.
    """
    paper = yaml.safe_load((ROOT / "config" / "paper.yaml").read_text())
    out = {"paper": {k: v for k, v in paper.items() if k in SECTIONS}, "ours": {}}
    for name, path in extra.items():
        out[name] = yaml.safe_load(Path(path).read_text()) or {}
    return out


def campaigns(work: Path, physics: list[str], seeds: list[int]) -> list[tuple[Path, str, int, int]]:
    """The paper-method campaigns in ``work`` with a processed second trial: (folder, physics, type, seed)."""
    out = []
    for camp in sorted(work.glob("loop_*_*_s*_seed*_paper")):
        phys, _mode, s, seed, _ = camp.name.split("_")[-5:]       # loop_[family_]<physics>_<mode>_s<k>_seed<s>_paper
        res = camp / "results" / camp.name
        if phys in physics and int(seed[4:]) in seeds and (res / "trial_2" / "tracks.parquet").exists():
            out.append((camp, phys, int(s[1:]), int(seed[4:])))
    return out


def _cli(args: list[str], config_files: list[Path]) -> None:
    env = dict(os.environ, STRINGCAST_CONFIG=os.pathsep.join(map(str, config_files)))
    proc = subprocess.run([sys.executable, "-m", "stringcast.cli", *args], env=env, capture_output=True, text=True)
    if proc.returncode:
        raise RuntimeError(f"stringcast {args[0]} failed:\n{proc.stdout[-2000:]}{proc.stderr[-2000:]}")


def one(camp: Path, name: str, overlay: dict, out: Path) -> dict:
    """Estimate ``camp``'s trial 1 under ``overlay`` and predict its trial 2; the figures (cached in ``out``)."""
    res, data = camp / "results" / camp.name, camp / "data" / camp.name
    d = out / camp.name / name
    if not (d / "prediction.json").exists():
        d.mkdir(parents=True, exist_ok=True)
        (d / "overlay.yaml").write_text(yaml.safe_dump(overlay))
        files = [camp / "config" / "config.yaml", d / "overlay.yaml"]
        _cli(["estimate", "--tracks", str(res / "trial_1" / "tracks.parquet"), "--joints",
              str(data / "trial_1" / "joints.csv"), "--campaign", str(data / "campaign.yaml"), "--trial", "1",
              *(a for stage in ("geometry", "clock", "tracking")
                for a in (f"--{stage}", str(res / "trial_1" / f"{stage}.json"))), "--out-params", str(d / "params.json"), "--out-fit", str(d / "fit.parquet")], files)
        _cli(["predict", "--params", str(d / "params.json"), "--tracks", str(res / "trial_2" / "tracks.parquet"),
              "--joints", str(data / "trial_2" / "joints.csv"), "--campaign", str(data / "campaign.yaml"),
              "--out", str(d / "prediction.json")], files)
    pred = json.loads((d / "prediction.json").read_text())
    est = json.loads((d / "params.json").read_text())
    return {"median_mm": pred.get("median_mm"), "p95_mm": pred.get("p95_mm"), "E_mm": est["E_mm"],
            "verdict": pred.get("verdict", {}).get("status")}


def paired(diffs: list[float]) -> dict:
    """The mean of paired differences, mm, with its 95 % bootstrap interval (campaigns resampled,
    :func:`benchmarks.loop_summary.bootstrap_ci` with one stratum)."""
    return {"paired_diff_mm": float(np.mean(diffs)), "paired_diff_ci95": bootstrap_ci({"all": diffs})}


def summarize(rows: list[dict], names: list[str]) -> dict:
    """Per physics and variant: median and mean error over campaigns, and the paired difference to ``paper``."""
    out = {}
    for phys in sorted({r["physics"] for r in rows}):
        rs = [r for r in rows if r["physics"] == phys and all(r[n]["median_mm"] is not None for n in names)]
        out[phys] = {"campaigns": len(rs)}
        for n in names:
            vals = [r[n]["median_mm"] for r in rs]
            out[phys][n] = {"median_mm": float(np.median(vals)) if vals else None,
                            "mean_mm": float(np.mean(vals)) if vals else None}
            if n != "paper" and vals:
                out[phys][n] |= paired([r[n]["median_mm"] - r["paper"]["median_mm"] for r in rs])
    return out


def run(work: Path, physics: list[str], seeds: list[int], out: Path, extra: dict[str, Path]) -> dict:
    var = variants(extra)
    rows = []
    for camp, phys, t, seed in campaigns(work, physics, seeds):
        row = {"campaign": camp.name, "physics": phys, "type": t, "seed": seed}
        for name, overlay in var.items():
            row[name] = one(camp, name, overlay, out)
        rows.append(row)
        print(f"  {camp.name}: " + ", ".join(f"{n} {row[n]['median_mm']:.1f} mm" for n in var), flush=True)
    doc = header("loop_prediction", False) | {
        "work": str(work), "physics": physics, "seeds": seeds, "variants": var,
        "summary": summarize(rows, list(var)), "rows": rows}
    print(f"loop_prediction: {len(rows)} campaigns -> {write('loop_prediction', doc)}")
    return doc


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, required=True, help="a loop benchmark's --work folder")
    ap.add_argument("--physics", nargs="+", default=["mujoco", "elastica"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--out", type=Path, help="where the estimates are kept (default: WORK/prediction_ab)")
    ap.add_argument("--overlay", action="append", default=[], metavar="NAME=FILE",
                    help="another variant: a YAML merged over each campaign's config")
    a = ap.parse_args(argv)
    extra = dict(s.split("=", 1) for s in a.overlay)
    run(a.work, a.physics, a.seeds, a.out or a.work / "prediction_ab", {k: Path(v) for k, v in extra.items()})


if __name__ == "__main__":
    main()
