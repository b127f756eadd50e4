"""Benchmark ``sync``: video-to-controller offset error with the trigger time withheld (DESIGN.md, "Benchmarks").

For several string types (quick: two) the lab films the campaign's first planned motion
with the default camera (1024 x 1024 at 500 fps); ``video.yaml``'s trigger time is
removed and :func:`stringcast.sync.run_sync` estimates the offset from the arm in the
video. Figures, measured in this run: offset_error_ms (estimate minus the lab's true
trigger time, per case), its median and max of |error|, the sync stage's seconds, and,
as the reference, the error of the trigger time the lab writes (U(+-2 ms) by default).

Run: ``python -m benchmarks.sync [--quick]`` -> results/bench/sync.json.
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from benchmarks.common import film_first_motion, header, write


def one_case(string_type: int, config: dict, work: Path, seed: int) -> dict:
    from stringcast.files import read_json
    from stringcast.sync import run_sync

    campaign, d, trial = film_first_motion(string_type, config, work, seed)
    truth = read_json(trial / "ground_truth.json")
    meta = yaml.safe_load((trial / "video.yaml").read_text())
    meta.pop("trigger_time_s")
    (trial / "video.yaml").write_text(yaml.safe_dump(meta))  # the benchmark's own copy: withheld
    t0 = time.perf_counter()
    doc = run_sync(trial, d / "calibration.json", campaign, config, d / "sync.json")
    return {"offset_error_ms": (doc["offset_s"] - truth["trigger_time_s"]) * 1000,
            "written_trigger_error_ms": (truth["trigger_time_written_s"] - truth["trigger_time_s"]) * 1000,
            "seconds": time.perf_counter() - t0, "time_residual_ms": doc["time_residual_ms"],
            "frames": doc["frames"], "board_check_mm": doc["residual_mm"]}


def run(quick: bool = False) -> dict:
    from stringcast.config import load_config

    config = load_config()
    config["sync"] = dict(config.get("sync", {}), method="video")
    types = [1, 5] if quick else [1, 3, 5, 7]
    cases = {}
    with tempfile.TemporaryDirectory(prefix="bench_sync_") as tmp:
        for k in types:
            cases[str(k)] = r = one_case(k, config, Path(tmp), seed=10 + k)
            print(f"  string {k}: error {r['offset_error_ms']:+.3f} ms (written trigger "
                  f"{r['written_trigger_error_ms']:+.3f} ms), {r['seconds']:.1f} s", flush=True)
    err = np.abs([c["offset_error_ms"] for c in cases.values()])
    ref = np.abs([c["written_trigger_error_ms"] for c in cases.values()])
    cam = config["cameras"][config["setups"]["default"]["camera"]]
    doc = header("sync", quick) | {
        "offset_error_ms_median": float(np.median(err)), "offset_error_ms_max": float(np.max(err)),
        "cases": cases, "fps": float(cam["fps"]), "trigger": "withheld",
        "reference": {"name": "lab_written_trigger", "offset_error_ms_median": float(np.median(ref)),
                      "offset_error_ms_max": float(np.max(ref))},
        "seconds_median": float(np.median([c["seconds"] for c in cases.values()])),
    }
    write("sync", doc)
    return doc


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="string types 1 and 5 only")
    run(ap.parse_args().quick)
