"""Benchmark ``tracking``: point error against the lab's ground truth, and speed (docs/results.md, "Benchmark records").

For each string type (quick: types 1 and 5) the lab films the campaign's first planned
motion (``planning.run_first_plan``, played through ``executor.execute``) with the
default camera; the workflow's own stages then calibrate (intrinsics from one board clip
shared by all types), sync (``video.yaml``) and track it. Figures, measured in this run:

* median_mm, p95_mm: distance of every *valid* tracked point 1..n to the lab's ground
  truth of the same frame (point 0, the grasp, is forward kinematics and left out);
  valid_share: the share of points 1..n marked valid.
* fps: frames per second of ``tracking.run_tracking`` (whole call, incl. background) as the
  workflow's ``track`` rule runs it: from the video decoded once by the ``decode`` rule
  (``frames.npy``), with one worker process per core; reference: plain decoding of the same
  video with ``video.open_video`` in the same run; ratio_to_reference = fps / reference.
  The decode itself is the ``decode`` rule's, paid once per trial for sync, the sweep and
  tracking together: ``decode_to_frames_npy_fps`` is its rate, and ``turnaround.json``
  counts it. ``fps_from_video`` (and its ratio) is tracking that decodes the video itself, as
  a caller without ``frames.npy`` does; its table must equal the other's, or the run fails.

Run: ``python -m benchmarks.tracking [--quick] [--types 2,3] [--work DIR]`` -> results/bench/tracking.json and
results/bench/tracking_errors.png (error distribution per string type); a run over chosen
``--types`` writes tracking_partial.json and tracking_partial_errors.png instead (same keys,
with ``types``), so it never replaces the full run's figures. ``--work`` keeps the filmed trials
in DIR and reuses them in a later run (tracking is always run anew), so a tracking change can be
measured on the same footage.
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.common import (
    BENCH_DIR,
    cores,
    film_first_motion,
    header,
    lab_calibration_clip,
    write,
)


def _decode_fps(video: Path) -> float:
    from stringcast.api import open_video

    t0 = time.perf_counter()
    n = sum(1 for _ in open_video(video))
    return n / (time.perf_counter() - t0)


def track_string(string_type: int, config: dict, settings, calib_dir: Path, work: Path, seed: int) -> dict:
    """Film, calibrate, sync, sweep and track one string type's first motion; errors and timings.
    ``settings``: every stage's settings (:class:`stringcast.core.Settings`)."""
    from stringcast_lab.campaign import tracking_errors
    from stringcast.core import resolve_campaign, stage_kwargs
    from stringcast.sync import run_sweep, run_sync
    from stringcast.api import run_tracking
    from stringcast.video import write_frame_cache

    d = work / f"string_{string_type}"
    trial = d / "trial_1"
    if (d / "sync.json").exists() and (trial / "ground_truth.parquet").exists():
        campaign = resolve_campaign({"string": string_type, "target": 1}, config, f"bench_{string_type}")
    else:
        campaign, d, trial = film_first_motion(string_type, config, work, seed, calib_dir)
        run_sync(trial, d / "calibration.json", campaign, d / "sync.json", sync=settings.sync,
                 board_check=settings.board_check)
    if not (d / "clock.json").exists() or (d / "clock.json").stat().st_mtime < (d / "sync.json").stat().st_mtime:
        run_sweep(trial, d / "calibration.json", d / "sync.json", campaign, d / "geometry.json", d / "clock.json",
                  **stage_kwargs(run_sweep, settings))
    decode = _decode_fps(trial / "video.mkv")
    t0 = time.perf_counter()
    frames_npy = write_frame_cache(trial / "video.mkv", d / "frames.npy")
    cache_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    tracks = run_tracking(trial, d / "geometry.json", d / "clock.json", campaign, d / "tracks.parquet",
                          frames_npy=frames_npy, workers=cores(), tracking=settings.tracking)
    seconds = time.perf_counter() - t0
    t0 = time.perf_counter()
    alone = run_tracking(trial, d / "geometry.json", d / "clock.json", campaign, d / "tracks_video.parquet",
                         tracking=settings.tracking)
    alone_s = time.perf_counter() - t0
    if not tracks.equals(alone):
        raise RuntimeError(f"string {string_type}: tracking from the decoded frames differs from tracking the video")
    for f in (frames_npy, frames_npy.with_suffix(".json")):   # the cache and its frames.json
        f.unlink()
    frames = int(tracks["frame"].nunique())
    e, valid = tracking_errors(tracks, pd.read_parquet(trial / "ground_truth.parquet"))
    return {"errors_mm": e, "valid_share": valid, "frames": frames, "track_s": seconds,
            "fps": frames / seconds, "decode_fps": decode, "decode_to_cache_fps": frames / cache_s,
            "fps_from_video": frames / alone_s}


def _figure(per: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.5))
    keys = sorted(per, key=int)
    ax.boxplot([per[k]["errors_mm"] for k in keys], whis=(5, 95), showfliers=False)
    ax.set_xticks(range(1, len(keys) + 1), [f"type {k}" for k in keys])
    ax.axhline(1.0, color="C2", ls="--", lw=1, label="1 mm (median goal)")
    ax.axhline(3.0, color="C3", ls=":", lw=1, label="3 mm (p95 goal)")
    ax.set_ylabel("point error vs ground truth (mm)")
    ax.set_title("tracking: valid points 1..n, whiskers 5-95 %")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(quick: bool = False, types: list[int] | None = None, work: Path | None = None) -> dict:
    from stringcast.core import settings_from_config
    from stringcast.core import load_config

    config = load_config()
    settings = settings_from_config(config)
    name = "tracking_partial" if types else "tracking"
    types = sorted(types) if types else ([1, 5] if quick else sorted(int(k) for k in config["strings"]))
    unknown = [k for k in types if str(k) not in config["strings"]]
    if unknown:
        raise SystemExit(f"--types: no string type(s) {unknown} in the config")
    per = {}
    with tempfile.TemporaryDirectory(prefix="bench_tracking_") as tmp:
        work = Path(work) if work else Path(tmp)
        calib = work / "calib"
        if not calib.exists():
            lab_calibration_clip(config, work)
        for k in types:
            t0 = time.perf_counter()
            per[str(k)] = track_string(k, config, settings, calib, work, seed=k)
            r = per[str(k)]
            print(f"  string {k}: median {np.median(r['errors_mm']):.2f} mm, p95 "
                  f"{np.percentile(r['errors_mm'], 95):.2f} mm, valid {r['valid_share']:.3f}, "
                  f"{r['fps']:.1f} fps (decode {r['decode_fps']:.1f}), {time.perf_counter() - t0:.0f} s", flush=True)
    e_all = np.concatenate([r["errors_mm"] for r in per.values()])
    frames = sum(r["frames"] for r in per.values())
    fps = frames / sum(r["track_s"] for r in per.values())
    decode = frames / sum(r["frames"] / r["decode_fps"] for r in per.values())
    alone = frames / sum(r["frames"] / r["fps_from_video"] for r in per.values())
    to_cache = frames / sum(r["frames"] / r["decode_to_cache_fps"] for r in per.values())
    figure = BENCH_DIR / f"{name}_errors.png"
    _figure(per, figure)
    doc = header(name, quick) | {"types": types,
        "median_mm": float(np.median(e_all)), "p95_mm": float(np.percentile(e_all, 95)),
        "valid_share": float(np.mean([r["valid_share"] for r in per.values()])),
        "fps": fps, "reference": {"name": "decode_only", "fps": decode}, "ratio_to_reference": fps / decode,
        "workers": cores(),
        "fps_from_video": alone, "ratio_to_reference_from_video": alone / decode,
        "decode_to_frames_npy_fps": to_cache,
        "frames": frames, "camera": config["setups"]["default"]["camera"], "figure": str(figure.name),
        "per_string": {k: {"median_mm": float(np.median(r["errors_mm"])),
                           "p95_mm": float(np.percentile(r["errors_mm"], 95)), "valid_share": r["valid_share"],
                           "fps": r["fps"], "decode_fps": r["decode_fps"], "fps_from_video": r["fps_from_video"],
                           "frames": r["frames"]}
                       for k, r in per.items()},
    }
    write(name, doc)
    return doc


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="string types 1 and 5 only")
    ap.add_argument("--types", default=None, help="comma-separated string types (e.g. 2,3): writes tracking_partial.json")
    ap.add_argument("--work", type=Path, help="keep (and reuse) the filmed trials here")
    args = ap.parse_args()
    run(args.quick, [int(k) for k in args.types.split(",")] if args.types else None, args.work)
