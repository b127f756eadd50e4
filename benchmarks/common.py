"""What every benchmark JSON carries (DESIGN.md, Benchmarks): name, cores, time, commit."""
from __future__ import annotations

import os
import subprocess
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BENCH_DIR = ROOT / "results" / "bench"


def cores() -> int:
    """CPU cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def git_commit() -> str | None:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def header(name: str, quick: bool) -> dict:
    """The keys every benchmark JSON starts with."""
    return {"benchmark": name, "cores": cores(), "created": datetime.now(timezone.utc).isoformat(),
            "git_commit": git_commit(), "quick": bool(quick)}


def write(name: str, doc: dict) -> Path:
    """Write results/bench/<name>.json atomically and return its path."""
    from stringcast.files import write_json

    path = BENCH_DIR / f"{name}.json"
    write_json(path, doc)
    return path
