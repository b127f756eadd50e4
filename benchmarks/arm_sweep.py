"""Benchmark ``arm_sweep``: how well the moving arm measures (and undoes) the swing plane's mapping error.

The sweep stage's fit in isolation (issue 25). On the setups a ``generalization`` run left in
its ``--work`` directory (each with the pipeline's ``calibration.json`` and ``sync.json``),
:func:`stringcast.calibrate.sweep_rows` reads the arm's links in ``--frames`` frames spread over
the trial (cached beside ``sync.json``), and :func:`stringcast.calibrate.refine_mapping` fits the
mapping's homography and the clock to them and the board's corners. Against the lab's true
camera (read here, by the benchmark only) it records, per setup:

* ``rows_vs_truth_mm``: median |row offset - n . e_true| over the slow rows (how well one row
  measures the error along its normal);
* the true mapping error over the swing region (13 x 13 grid; median, max mm) and at the
  string's true points (every 7th; median, p95 mm), before and after the refinement;
* the rows used, their rms before and after the fit, and the clock correction (ms).

``results/bench/arm_sweep.json`` holds the rows and their medians over the setups.

Run: ``python -m benchmarks.arm_sweep --work DIR [--frames 40] [--jobs 2] [--seeds 3,5,6]`` after
``python -m benchmarks.generalization --work DIR``.
"""
from __future__ import annotations

import argparse
import time
from functools import partial
from pathlib import Path

import numpy as np

from benchmarks.common import header, write
from benchmarks.certainty import mapping_error, swing_grid


def run_setup(seed: int, string_type: int, config: dict, work: Path, n_frames: int) -> dict:
    """The sweep's rows and fitted field on one filmed and processed setup, against the truth."""
    import pandas as pd

    from stringcast.calibrate import Calibration
    from stringcast.calibrate import board_corner_points, refine_mapping, sweep_rows
    from stringcast.core import find_video, read_json, resolve_campaign, settings_from_config
    from stringcast.core import read_joint_table
    from stringcast_lab import apply_setup, draw_setup
    from stringcast.sync import frame_times
    from stringcast.sync.sweep import read_frames

    d = work / f"setup_{seed}"
    cfg = apply_setup(config, draw_setup(seed))
    st = settings_from_config(cfg)
    campaign = resolve_campaign({"string": string_type, "target": 1}, cfg, f"gen_{seed}")
    cal = Calibration.from_json(d / "results" / "calibration.json")
    t_frames = frame_times(read_json(d / "results" / "sync.json"))
    t_j, q_j = read_joint_table(d / "trial_1" / "joints.csv", n_joints=campaign.arm.n_joints)
    cam = read_json(d / "trial_1" / "ground_truth.json")["camera"]

    e_true = partial(mapping_error, cal, cam)
    t0 = time.perf_counter()
    keep = set(np.linspace(0, len(t_frames) - 1, n_frames).astype(int).tolist())
    cache = d / f"sweep_rows_{n_frames}.npy"  # the rows of this calibration and sync: refit without re-reading
    if cache.exists() and cache.stat().st_mtime > (d / "results" / "sync.json").stat().st_mtime:
        rows = np.load(cache)
    else:
        rows = sweep_rows(read_frames(find_video(d / "trial_1"), sorted(keep)), cal, campaign.arm, t_frames, t_j,
                          q_j, st.board_check)
        np.save(cache, rows)
    seconds = time.perf_counter() - t0
    fit = refine_mapping(cal, rows, board_corner_points(cal, campaign.setup.board.make()))
    slow = rows[np.abs(rows[:, 6]) <= 0.3]
    grid = swing_grid()
    gt = pd.read_parquet(d / "trial_1" / "ground_truth.parquet")
    string = gt[gt["point"] > 0][["x_m", "y_m"]].to_numpy()[::7]
    row = {"seed": seed, "string_type": string_type, "seconds": seconds, "rows": int(len(rows)), "rows_used": fit["rows"],
           "rms_before_mm": fit["rms_before_mm"], "rms_after_mm": fit["rms_after_mm"], "clock_ms": fit["dt_s"] * 1000,
           "rows_vs_truth_mm": float(np.median(np.abs(slow[:, 5] - np.sum(e_true(slow[:, 1:3]) * slow[:, 3:5], 1))) * 1000)}
    for name, pts in (("region", grid), ("string", string)):
        e, after = e_true(pts), mapping_error(fit["calibration"], cam, pts)
        for when, v in (("before", e), ("after", after)):
            n = np.linalg.norm(v, axis=1) * 1000
            row[f"{name}_{when}_median_mm"] = float(np.median(n))
            row[f"{name}_{when}_{'max' if name == 'region' else 'p95'}_mm"] = float(np.max(n) if name == "region"
                                                                                    else np.percentile(n, 95))
    return row


def run(quick: bool = False, setups: int = 24, work: Path | None = None, frames: int = 40, jobs: int = 1,
        seeds: list[int] | None = None) -> dict:
    """Run the experiment on the setups of ``work`` (``seeds``, default 0..setups-1) that have ``results/sync.json``."""
    from concurrent.futures import ProcessPoolExecutor

    from stringcast.core import load_config

    if work is None:
        raise SystemExit("arm_sweep: --work DIR (a generalization run's work directory) is needed")
    config = load_config()
    seeds = [s for s in (seeds or range(3 if quick else setups)) if (work / f"setup_{s}" / "results" / "sync.json").exists()]
    with ProcessPoolExecutor(max_workers=max(1, jobs)) as pool:
        rows = list(pool.map(run_setup, seeds, [1 + s % 7 for s in seeds], [config] * len(seeds), [work] * len(seeds),
                             [frames] * len(seeds)))
    keys = [k for k in rows[0] if k.endswith("_mm")] if rows else []
    doc = {**header("arm_sweep", quick), "work": str(work), "frames": frames, "setups": len(rows),
           "medians": {k: float(np.median([r[k] for r in rows if r[k] is not None])) for k in keys},
           "per_setup": rows}
    write("arm_sweep", doc)
    for r in rows:
        print(f"setup {r['seed']}: region max {r['region_before_max_mm']:.2f} -> {r['region_after_max_mm']:.2f} mm, "
              f"string p95 {r['string_before_p95_mm']:.2f} -> {r['string_after_p95_mm']:.2f} mm, rows {r['rows_used']}")
    return doc


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--work", type=Path, required=True, help="a generalization run's --work directory")
    p.add_argument("--setups", type=int, default=24, help="setups 0..N-1 (those processed)")
    p.add_argument("--frames", type=int, default=40, help="frames per trial, spread evenly")
    p.add_argument("--jobs", type=int, default=1, help="setups side by side (processes)")
    p.add_argument("--seeds", type=lambda t: [int(x) for x in t.split(",")], default=None, help="these setups only, e.g. 3,5,6")
    p.add_argument("--quick", action="store_true", help="the first 3 setups")
    args = p.parse_args(argv)
    run(args.quick, args.setups, args.work, args.frames, args.jobs, args.seeds)


if __name__ == "__main__":
    main()
