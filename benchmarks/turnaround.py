"""Benchmark ``turnaround``: from a new trial folder to the next ``motion.csv``, through Snakemake and through ``stringcast next``.

Between two executions a person waits at the arm for the next motion file; this is that wait.
The lab films one trial of the default camera (the campaign's first motion, string 1,
target 1: about 1000 frames at 1024 x 1024); the benchmark then deletes the trial's results
and asks the workflow for ``results/<campaign>/trial_1/motion.csv`` with ``--cores`` cores,
as ``stringcast campaign`` does. What the campaign prepared before its first trial stays: the first
motion and the calibration clip's board views (``calib_views.npz``, found once per campaign). Figures, measured in this run:

* seconds_total: wall time of that Snakemake call (job start-up, imports and
  Snakemake's own bookkeeping included);
* seconds_per_stage: each rule's wall seconds from its ``benchmark:`` file (the ``s`` column);
* decode_seconds: a plain decode of the same video (``video.open_video``, every frame, one
  pass), in the same run;
* ratio_to_decode = seconds_total / decode_seconds;
* next_seconds: the same trial through ``stringcast next data/<c>/trial_1`` (one process, no
  Snakemake; its results deleted first), until its ``motion.csv`` is written (``next_seconds_total``:
  until the command ends, the trial's and the campaign's pages included);
  next_ratio_to_decode = next_seconds / decode_seconds.

With ``--repeats`` the whole Snakemake call is repeated (results deleted each time) and the
median is kept, with every run's figures. The filmed trial is kept in ``--work`` and reused.

Run: ``python -m benchmarks.turnaround [--quick] [--work DIR] [--repeats N] [--cores C]``
-> results/bench/turnaround.json.
"""
from __future__ import annotations

import argparse
import csv
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import ROOT, header, play_on_lab, write

CAMPAIGN = "turnaround"
STAGES = ("decode", "calibrate", "sync", "sweep", "track", "estimate", "plan")


def _project(work: Path) -> Path:
    """A project root in ``work`` that runs this checkout's workflow and config on its own data/
    (links left by another checkout, or dangling, are pointed here again)."""
    root = work / "project"
    root.mkdir(parents=True, exist_ok=True)
    for name in ("Snakefile", "workflow", "config"):
        link = root / name
        if link.is_symlink() and link.readlink() != ROOT / name:
            link.unlink()
        if not link.exists():
            link.symlink_to(ROOT / name)
    return root


def _film(root: Path) -> Path:
    """The campaign's first motion, planned by the workflow and played on the lab: data/<c>/trial_1."""
    from stringcast_lab.campaign import campaign_config
    from stringcast.core import load_yaml, resolve_campaign, settings_from_config, write_yaml
    from stringcast_lab import write_calibration_clip

    data = root / "data" / CAMPAIGN
    trial = data / "trial_1"
    if (trial / "joints.csv").exists():
        return trial
    config, _ = campaign_config(root)
    data.mkdir(parents=True, exist_ok=True)
    doc = {"string": 1, "target": 1, "setup": "default", "seed": 0}
    write_yaml(data / "campaign.yaml", doc)
    campaign = resolve_campaign(load_yaml(data / "campaign.yaml"), config, CAMPAIGN, data / "campaign.yaml")
    if not (data / "calib").is_dir():
        write_calibration_clip(campaign, config, data / "calib", 0)
    _snakemake(root, f"results/{CAMPAIGN}/first_motion/motion.csv", cores=2)
    return play_on_lab(root / "results" / CAMPAIGN / "first_motion" / "motion.csv", trial, data / "campaign.yaml",
                       settings_from_config(config).executor, config, seed=1)


def _snakemake(root: Path, target: str, cores: int) -> float:
    """Run the workflow for ``target``; wall seconds. Raises RuntimeError naming the logs on failure."""
    cmd = [sys.executable, "-m", "snakemake", target, "--cores", str(cores), "--directory", str(root),
           "--quiet", "rules"]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=root, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"snakemake {target} failed (exit {proc.returncode}); logs under "
                           f"{root / 'results' / CAMPAIGN / 'logs'}\n{proc.stderr[-3000:]}")
    return time.perf_counter() - t0


def _next(root: Path) -> tuple[float, float]:
    """``stringcast next`` on trial 1, as a person runs it: (seconds until its motion.csv is written,
    seconds until the command ends). Raises RuntimeError on failure."""
    motion = root / "results" / CAMPAIGN / "trial_1" / "motion.csv"
    cmd = [str(Path(sys.executable).parent / "stringcast"), "next", f"data/{CAMPAIGN}/trial_1"]
    t0, wall0 = time.perf_counter(), time.time()
    proc = subprocess.run(cmd, cwd=root, capture_output=True, text=True)
    total = time.perf_counter() - t0
    if proc.returncode != 0 or not motion.is_file():
        raise RuntimeError(f"stringcast next failed (exit {proc.returncode})\n{proc.stdout[-3000:]}{proc.stderr[-2000:]}")
    return motion.stat().st_mtime - wall0, total


def _clear_trial(root: Path) -> None:
    """Delete trial 1's results, logs and rule benchmarks (the first motion stays)."""
    res = root / "results" / CAMPAIGN
    shutil.rmtree(res / "trial_1", ignore_errors=True)
    for sub in ("logs", "benchmarks"):
        for f in (res / sub).glob("*_1.*"):
            f.unlink()


def _stage_seconds(root: Path) -> dict[str, float]:
    """Each rule's wall seconds for trial 1, from its Snakemake ``benchmark:`` TSV."""
    out = {}
    for stage in STAGES:
        path = root / "results" / CAMPAIGN / "benchmarks" / f"{stage}_1.tsv"
        if path.exists():
            with path.open() as fh:
                out[stage] = float(next(csv.DictReader(fh, delimiter="\t"))["s"])
    return out


def _decode_seconds(video: Path) -> tuple[float, int]:
    """Seconds of one plain decoding pass over ``video``, and its frame count."""
    from stringcast.video import open_video

    t0 = time.perf_counter()
    n = sum(1 for _ in open_video(video))
    return time.perf_counter() - t0, n


def run(quick: bool = False, work: Path | None = None, repeats: int | None = None, cores: int = 2) -> dict:
    repeats = repeats or 1
    from stringcast.core import find_video

    with tempfile.TemporaryDirectory(prefix="bench_turnaround_") as tmp:
        root = _project(Path(work) if work else Path(tmp))
        trial = _film(root)
        _snakemake(root, f"results/{CAMPAIGN}/calib_views.npz", cores)   # the campaign's, found once before its trials
        video = find_video(trial)
        runs = []
        for r in range(repeats):
            _clear_trial(root)
            decode_s, frames = _decode_seconds(video)
            total = _snakemake(root, f"results/{CAMPAIGN}/trial_1/motion.csv", cores)
            stages = _stage_seconds(root)
            _clear_trial(root)
            to_motion, next_total = _next(root)
            runs.append({"seconds_total": total, "seconds_per_stage": stages, "decode_seconds": decode_s,
                         "next_seconds": to_motion, "next_seconds_total": next_total})
            print(f"  run {r + 1}: {total:.1f} s total, decode {decode_s:.1f} s, next {to_motion:.1f} s "
                  f"({next_total:.1f} s with the reports), stages "
                  + ", ".join(f"{k} {v:.1f}" for k, v in stages.items()), flush=True)
    total = float(np.median([x["seconds_total"] for x in runs]))
    decode = float(np.median([x["decode_seconds"] for x in runs]))
    stages = {k: float(np.median([x["seconds_per_stage"].get(k, np.nan) for x in runs])) for k in STAGES}
    next_s = float(np.median([x["next_seconds"] for x in runs]))
    next_total = float(np.median([x["next_seconds_total"] for x in runs]))
    doc = header("turnaround", quick) | {
        "video": {"frames": frames, "file": video.name}, "workflow_cores": cores, "repeats": repeats,
        "seconds_total": total, "seconds_per_stage": stages, "decode_seconds": decode,
        "ratio_to_decode": total / decode, "next_seconds": next_s, "next_seconds_total": next_total,
        "next_ratio_to_decode": next_s / decode, "runs": runs}
    write("turnaround", doc)
    return doc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one run (the default too; kept for benchmarks.run)")
    ap.add_argument("--work", type=Path, help="keep the filmed trial here and reuse it")
    ap.add_argument("--repeats", type=int, default=1, help="Snakemake runs; the median is kept")
    ap.add_argument("--cores", type=int, default=2, help="Snakemake --cores")
    a = ap.parse_args()
    doc = run(a.quick, a.work, a.repeats, a.cores)
    print(f"turnaround: {doc['seconds_total']:.1f} s to the next motion.csv, decode {doc['decode_seconds']:.1f} s "
          f"(ratio {doc['ratio_to_decode']:.1f}); stringcast next {doc['next_seconds']:.1f} s "
          f"(ratio {doc['next_ratio_to_decode']:.1f}); " + ", ".join(f"{k} {v:.1f} s" for k, v in
                                                                 doc["seconds_per_stage"].items()))


if __name__ == "__main__":
    main()
