"""Benchmark ``loop_prediction``: estimators compared on the same data and the same next motion (issue 27).

The loop benchmark's prediction error (``loop.json``) compares each method on the motions *it*
played: ours, which hits sooner, is judged on fewer and harder steps than the paper's method, on
other motions. This benchmark takes the estimator alone. For every paper-method campaign of a
loop run (``--work``) with a second execution, each variant estimates trial 1 as the workflow's
``estimate`` rule does (its tracked points and joint log, the campaign's config with ours' estimate
sections and the variant's overlay merged last, ``stringcast estimate``), and then predicts trial 2's tip from
trial 2's measured joint log (``stringcast predict``, :mod:`stringcast.estimate.prediction`). Every
variant sees the same training trial and the same test motion. ``--methods`` takes other methods'
campaigns (ours' steps are the near misses a planner must refine), ``--all-pairs`` every trial k
-> k + 1 of them, not only 1 -> 2.

Variants: ``paper`` (the paper's estimator, ``estimation.optimizer: random_search``, ``w`` 0.1),
``ours`` (the settings' defaults: no overlay) and any ``--overlay
NAME=FILE`` (a YAML merged over ours). Each runs on the campaign's config with the method's estimate
sections (``SECTIONS``) taken out, so a variant is the same estimator on every campaign, whichever
method played it.

Figures per physics and variant: ``median_mm`` (the median over trial pairs of each pair's median
tip error, mm), ``mean_mm``, ``p95_median_mm`` (the median of each pair's 95th percentile: the
flight's end, where a prediction goes wrong first), ``campaigns``, ``pairs``; per variant other than
``--reference`` (default ``paper``), ``paired_diff_mm`` and ``paired_p95_diff_mm`` (the mean over pairs
of its error minus the reference's) with 95 % bootstrap intervals (pairs resampled, as ``loop.json``'s
intervals), and ``E_lower_share`` (the share of pairs where its fit reached a lower E than the
reference's: between variants with the same evaluation settings, how well each search does on
the same objective). ``rows``: every pair's figures, and the E the fit reached. The estimates are
cached under ``--out`` (rerunning skips what exists).

Run: ``python -m benchmarks.loop_prediction --work /path/to/loop/work [--physics mujoco] [--seeds 0 1 2]
[--methods paper ours] [--all-pairs] [--builtin ours] [--reference ours] [--overlay NAME=FILE]``
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


def campaigns(work: Path, physics: list[str], seeds: list[int], methods: tuple[str, ...] = ("paper",),
              all_pairs: bool = False) -> list[tuple[Path, str, int, int, int]]:
    """The trial pairs to predict: (folder, physics, type, seed, k), trial k's estimate predicting trial
    k + 1, of the ``methods``' campaigns in ``work`` (names as :data:`benchmarks.loop.RUN_NAME`) with a
    processed trial k + 1: k = 1 only, or with ``all_pairs`` every k."""
    from benchmarks.loop import RUN_NAME

    out = []
    for camp in sorted(work.glob("loop_*")):
        m = RUN_NAME.match(camp.name)
        if not m or m["method"] not in methods or m["physics"] not in physics or int(m["seed"]) not in seeds:
            continue
        res, k = camp / "results" / camp.name, 1
        while (res / f"trial_{k + 1}" / "tracks.parquet").exists() and (k == 1 or all_pairs):
            out.append((camp, m["physics"], int(m["type"]), int(m["seed"]), k))
            k += 1
    return out


def _cli(args: list[str], config_files: list[Path]) -> None:
    env = dict(os.environ, STRINGCAST_CONFIG=os.pathsep.join(map(str, config_files)))
    proc = subprocess.run([sys.executable, "-m", "stringcast.cli", *args], env=env, capture_output=True, text=True)
    if proc.returncode:
        raise RuntimeError(f"stringcast {args[0]} failed:\n{proc.stdout[-2000:]}{proc.stderr[-2000:]}")


def ours_config(path: Path) -> dict:
    """The campaign's config (``path``) with its method's estimate sections taken out (``SECTIONS``; the
    estimator's seed kept): ours' settings, over which every variant's overlay is merged, whichever
    method played the campaign (a paper-method campaign's config carries the paper's estimator)."""
    cfg = yaml.safe_load(Path(path).read_text()) or {}
    seed = (cfg.get("estimation") or {}).get("seed")
    cfg = {k: v for k, v in cfg.items() if k not in SECTIONS}
    if seed is not None:
        cfg["estimation"] = {"seed": seed}
    return cfg


def one(camp: Path, name: str, overlay: dict, out: Path, k: int = 1) -> dict:
    """Estimate ``camp``'s trial ``k`` under ``overlay`` and predict its trial k + 1; the figures (cached in ``out``)."""
    res, data = camp / "results" / camp.name, camp / "data" / camp.name
    d = out / camp.name / f"trial_{k}" / name
    if not (d / "prediction.json").exists():
        d.mkdir(parents=True, exist_ok=True)
        (d / "config.yaml").write_text(yaml.safe_dump(ours_config(camp / "config" / "config.yaml")))
        (d / "overlay.yaml").write_text(yaml.safe_dump(overlay))
        files = [d / "config.yaml", d / "overlay.yaml"]
        trial = res / f"trial_{k}"
        _cli(["estimate", "--tracks", str(trial / "tracks.parquet"), "--joints",
              str(data / f"trial_{k}" / "joints.csv"), "--campaign", str(data / "campaign.yaml"), "--trial", str(k),
              *(a for stage in ("geometry", "clock", "tracking") for a in (f"--{stage}", str(trial / f"{stage}.json"))),
              "--out-params", str(d / "params.json"), "--out-fit", str(d / "fit.parquet")], files)
        _cli(["predict", "--params", str(d / "params.json"), "--tracks", str(res / f"trial_{k + 1}" / "tracks.parquet"),
              "--joints", str(data / f"trial_{k + 1}" / "joints.csv"), "--campaign", str(data / "campaign.yaml"),
              "--out", str(d / "prediction.json")], files)
    pred = json.loads((d / "prediction.json").read_text())
    est = json.loads((d / "params.json").read_text())
    return {"median_mm": pred.get("median_mm"), "p95_mm": pred.get("p95_mm"), "E_mm": est["E_mm"],
            "verdict": pred.get("verdict", {}).get("status")}


def paired(diffs: list[float], name: str = "paired_diff") -> dict:
    """The mean of paired differences, mm (``<name>_mm``), with its 95 % bootstrap interval
    (``<name>_ci95``; pairs resampled, :func:`benchmarks.loop_summary.bootstrap_ci` with one stratum)."""
    return {f"{name}_mm": float(np.mean(diffs)), f"{name}_ci95": bootstrap_ci({"all": diffs})}


def summarize(rows: list[dict], names: list[str], reference: str = "paper") -> dict:
    """Per physics and variant: median and mean over the pairs of each pair's median tip error, the
    median of their p95; per variant other than ``reference``, the paired differences to it (median and
    p95 error) and ``E_lower_share``, the share of pairs where its fit reached a lower E than the
    reference's (E compares only between variants with the same evaluation settings)."""
    out = {}
    for phys in sorted({r["physics"] for r in rows}):
        rs = [r for r in rows if r["physics"] == phys and all(r[n]["median_mm"] is not None for n in names)]
        out[phys] = {"campaigns": len({r["campaign"] for r in rs}), "pairs": len(rs)}
        for n in names:
            vals = [r[n]["median_mm"] for r in rs]
            p95 = [r[n]["p95_mm"] for r in rs if r[n].get("p95_mm") is not None]
            out[phys][n] = {"median_mm": float(np.median(vals)) if vals else None,
                            "mean_mm": float(np.mean(vals)) if vals else None,
                            "p95_median_mm": float(np.median(p95)) if p95 else None}
            if n != reference and vals:
                out[phys][n] |= paired([r[n]["median_mm"] - r[reference]["median_mm"] for r in rs])
                d95 = [r[n]["p95_mm"] - r[reference]["p95_mm"] for r in rs
                       if r[n].get("p95_mm") is not None and r[reference].get("p95_mm") is not None]
                if d95:
                    out[phys][n] |= paired(d95, "paired_p95_diff")
                out[phys][n]["E_lower_share"] = float(np.mean([r[n]["E_mm"] < r[reference]["E_mm"] for r in rs]))
    return out


def _mm(x: float | None) -> str:
    """A figure for the progress line; None (no compared frame, or the model blew up) as '-'."""
    return "-" if x is None else f"{x:.1f}"


def run(work: Path, physics: list[str], seeds: list[int], out: Path, extra: dict[str, Path],
        methods: tuple[str, ...] = ("paper",), all_pairs: bool = False, builtin: tuple[str, ...] = ("paper", "ours"),
        reference: str = "paper") -> dict:
    var = {n: o for n, o in variants(extra).items() if n in builtin or n in extra}
    if reference not in var:
        raise ValueError(f"--reference {reference}: not one of the variants run ({', '.join(var)})")
    rows = []
    for camp, phys, t, seed, k in campaigns(work, physics, seeds, methods, all_pairs):
        row = {"campaign": camp.name, "physics": phys, "type": t, "seed": seed, "trial": k}
        for name, overlay in var.items():
            row[name] = one(camp, name, overlay, out, k)
        rows.append(row)
        print(f"  {camp.name} {k} -> {k + 1}: " + ", ".join(
            f"{n} {_mm(row[n]['median_mm'])} / p95 {_mm(row[n]['p95_mm'])} mm (E {_mm(row[n]['E_mm'])})" for n in var),
            flush=True)
    doc = header("loop_prediction", False) | {
        "work": str(work), "physics": physics, "seeds": seeds, "methods": list(methods), "all_pairs": all_pairs,
        "variants": var, "reference": reference, "summary": summarize(rows, list(var), reference), "rows": rows}
    print(f"loop_prediction: {len(rows)} trial pairs -> {write('loop_prediction', doc)}")
    return doc


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, required=True, help="a loop benchmark's --work folder")
    ap.add_argument("--physics", nargs="+", default=["mujoco", "elastica"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--out", type=Path, help="where the estimates are kept (default: WORK/prediction_ab)")
    ap.add_argument("--overlay", action="append", default=[], metavar="NAME=FILE",
                    help="another variant: a YAML merged over ours' settings (each campaign's config)")
    ap.add_argument("--methods", nargs="+", default=["paper"],
                    help="whose campaigns give the trial pairs (loop method or variant names; default paper)")
    ap.add_argument("--all-pairs", action="store_true", help="every trial k -> k + 1, not only 1 -> 2")
    ap.add_argument("--builtin", nargs="*", choices=["paper", "ours"], default=["paper", "ours"],
                    help="which of the two built-in estimators run beside the overlays")
    ap.add_argument("--reference", default="paper", help="the variant the others are paired with")
    a = ap.parse_args(argv)
    extra = dict(s.split("=", 1) for s in a.overlay)
    try:
        run(a.work, a.physics, a.seeds, a.out or a.work / "prediction_ab", {k: Path(v) for k, v in extra.items()},
            tuple(a.methods), a.all_pairs, tuple(a.builtin), a.reference)
    except ValueError as exc:
        ap.error(str(exc))


if __name__ == "__main__":
    main()
