"""Where the string model misses the string: the per-point residual of ours' fits, per physics.

Reads the loop benchmark's finished campaigns (``--work``, as ``benchmarks.loop`` left them) and,
for every fit of ours (``trial_<k>/fit.parquet``: the fitted model's points beside the tracked
points, per frame and point), the distance between the two, mm. Per physics: the first fits'
median point error (median over campaigns, with its quartiles), the same by thirds of the
string from the grasp to the tip and at the tip, per string type, and how far the tracked
string's length (the polyline through its tracked points) strays above its median (95th
percentile, %): a string that stretches where the model's segments cannot shows there.

In the state mode the tracked points are the lab's true points with the tracking's error, so
the residual is the model's (and the fit's) alone.

Run: ``python -m benchmarks.fit_residuals --work DIR`` -> results/bench/fit_residuals.json.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.common import header, write

COLUMNS = ("x_tracked_m", "y_tracked_m", "x_sim_m", "y_sim_m")


def fit_residual(fit_parquet: Path) -> dict:
    """One fit's point errors: ``median_mm`` over frames and points, ``thirds_mm`` (grasp, middle,
    tip-side third of the points), ``tip_mm``, and ``length_p95_over_median_pct`` of the tracked polyline."""
    df = pd.read_parquet(fit_parquet, columns=["frame", "point", *COLUMNS])
    x, y, xs, ys = (df.pivot(index="frame", columns="point", values=c).to_numpy() for c in COLUMNS)
    err = np.hypot(x - xs, y - ys) * 1000                                    # (frames, points) mm
    n = err.shape[1]
    seg = np.hypot(np.diff(x, axis=1), np.diff(y, axis=1))
    length = seg[np.all(np.isfinite(seg), axis=1)].sum(axis=1)
    return {"median_mm": float(np.nanmedian(err)), "tip_mm": float(np.nanmedian(err[:, -1])),
            "thirds_mm": [float(np.nanmedian(err[:, a:b])) for a, b in ((0, n // 3), (n // 3, 2 * n // 3),
                                                                          (2 * n // 3, n))],
            "length_p95_over_median_pct": (float((np.quantile(length, 0.95) / np.median(length) - 1) * 100)
                                           if len(length) else None)}


def _campaign_fits(work: Path, method: str):
    """(physics, string type, seed, trial, fit.parquet) of every finished state-mode campaign of ``method``."""
    for d in sorted(work.glob(f"loop_*_state_s*_seed*_{method}")):
        if not (d / "run.json").exists():
            continue
        run = json.loads((d / "run.json").read_text())
        for fit in sorted(d.glob("results/*/trial_*/fit.parquet")):
            yield run["physics"], int(run["string"]), int(run["seed"]), int(fit.parent.name.split("_")[1]), fit


def summarize(rows: list[dict]) -> dict:
    """Per physics: the first fits' figures (see the module's docstring) and every fit's median."""
    out = {}
    for ph in sorted({r["physics"] for r in rows}):
        mine = [r for r in rows if r["physics"] == ph]
        first = [r for r in mine if r["trial"] == 1]
        med = np.array([r["median_mm"] for r in first])
        out[ph] = {"fits": len(mine), "first_fits": len(first),
                   "first_fit_median_mm": float(np.median(med)),
                   "first_fit_quartiles_mm": [float(np.quantile(med, 0.25)), float(np.quantile(med, 0.75))],
                   "first_fit_thirds_mm": [float(np.median([r["thirds_mm"][i] for r in first])) for i in range(3)],
                   "first_fit_tip_mm": float(np.median([r["tip_mm"] for r in first])),
                   "first_fit_length_p95_over_median_pct": float(np.median(
                       [r["length_p95_over_median_pct"] for r in first if r["length_p95_over_median_pct"] is not None])),
                   "all_fits_median_mm": float(np.median([r["median_mm"] for r in mine])),
                   "first_fit_median_mm_per_type": {str(k): float(np.median([r["median_mm"] for r in first
                                                                              if r["string"] == k]))
                                                    for k in sorted({r["string"] for r in first})}}
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--work", required=True, type=Path, help="the loop benchmark's campaigns' folder")
    ap.add_argument("--method", default="ours", help="whose fits (default: ours)")
    a = ap.parse_args(argv)
    rows = [{"physics": ph, "string": k, "seed": s, "trial": t, **fit_residual(f)}
            for ph, k, s, t, f in _campaign_fits(a.work, a.method)]
    if not rows:
        raise SystemExit(f"{a.work}: no finished state-mode campaign of {a.method} with a fit")
    doc = header("fit_residuals", False) | {"method": a.method, "per_physics": summarize(rows), "fits": rows}
    print(f"fit residuals of {a.method} -> {write('fit_residuals', doc)}")
    for ph, e in doc["per_physics"].items():
        print(f"  {ph}: {e['first_fits']} first fits, median point error {e['first_fit_median_mm']:.1f} mm "
              f"(quartiles {e['first_fit_quartiles_mm'][0]:.1f}-{e['first_fit_quartiles_mm'][1]:.1f}), by thirds "
              + " / ".join(f"{v:.1f}" for v in e["first_fit_thirds_mm"])
              + f" mm, tip {e['first_fit_tip_mm']:.1f} mm; length p95 +{e['first_fit_length_p95_over_median_pct']:.1f} %")


if __name__ == "__main__":
    main()
