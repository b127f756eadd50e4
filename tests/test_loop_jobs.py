"""The loop benchmark's campaigns as separate Snakemake jobs (benchmarks/loop.smk): one job per
campaign, then a gather into loop.json with the same summary as the in-process run."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks.loop import run_dir, summarize

ROOT = Path(__file__).resolve().parents[1]


def _record(k: int, seed: int, method: str, executions: int, hit: bool) -> dict:
    """A finished campaign's run.json, as benchmarks.loop.run_one writes it."""
    return {"string": k, "target": 1, "seed": seed, "method": method, "campaign": f"c{k}{seed}{method}",
            "git_commit": "test", "libraries": {}, "error": None, "executions": executions, "hit": hit,
            "closest_approach_mm": [50.0] * (executions - 1) + [5.0], "E_mm": [20.0] * executions,
            "wall_s": 1.0, "s_per_execution": 1.0, "timings_s": {}}


def _snakemake(tmp_path, *args):
    env = dict(os.environ, STRINGCAST_BENCH_DIR=str(tmp_path / "bench"))
    return subprocess.run([sys.executable, "-m", "snakemake", "-s", str(ROOT / "benchmarks" / "loop.smk"),
                           "--directory", str(tmp_path), "--cores", "2", *args],
                          capture_output=True, text=True, env=env)


def test_one_job_per_campaign_then_one_gather(tmp_path):
    proc = _snakemake(tmp_path, "-n", "--config", f"work={tmp_path / 'w'}", "types=1 5", "seeds=0 1")
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    jobs = [line for line in out.splitlines() if line.strip().startswith("wildcards:")]
    assert len(jobs) == 2 * 2 * 2, out                     # types x seeds x methods
    assert out.count("rule gather:") == 1 and out.count("rule campaign:") == 8


def test_gather_summarises_the_campaign_jobs_run_json(tmp_path):
    """Campaigns already finished (their run.json) are not run again; the gather writes loop.json
    with the summary benchmarks.loop.summarize gives for the same runs."""
    work = tmp_path / "w"
    runs = [_record(1, 0, "paper", 3, True), _record(1, 0, "ours", 2, True),
            _record(5, 0, "paper", 8, False), _record(5, 0, "ours", 1, True)]
    for r in runs:
        d = run_dir(work, r["string"], r["seed"], r["method"])
        d.mkdir(parents=True)
        (d / "run.json").write_text(json.dumps(r))
    proc = _snakemake(tmp_path, "--config", f"work={work}", "types=1 5", "seeds=0")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "rule campaign" not in proc.stdout + proc.stderr    # nothing re-run
    doc = json.loads((tmp_path / "bench" / "loop.json").read_text())
    expect = summarize(runs, [1, 5], ["paper", "ours"])
    for key in ("mean_ours", "mean_paper_method", "max_ours", "all_hit_ours", "per_string"):
        assert doc[key] == expect[key], key
    assert doc["mean_ours"] == pytest.approx(1.5) and doc["all_hit_ours"] and doc["complete"]
