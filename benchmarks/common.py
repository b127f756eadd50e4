"""What every benchmark JSON carries (docs/results.md): name, cores, time, commit, library versions."""
from __future__ import annotations

import os
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BENCH_DIR = Path(os.environ.get("STRINGCAST_BENCH_DIR") or ROOT / "results" / "bench")
"""Where the benchmark JSON files go: results/bench/, or $STRINGCAST_BENCH_DIR (the tests' own folder)."""


def cores() -> int:
    """CPU cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def git_commit() -> str | None:
    """HEAD, with ``-dirty`` where tracked files differ from it (a run on uncommitted code recorded
    the bare HEAD before); None outside a checkout (:func:`stringcast.report.provenance.git_commit`)."""
    from stringcast.report.provenance import git_commit as commit

    c = commit(ROOT)
    return None if c == "unknown" else c


# The libraries a benchmark's figures depend on: the loop's outcome on seeds 0-2 moved from 43
# to 47 executions with their versions alone (docs/method.md, "Library versions"), so each JSON records them.
LIBRARIES = ("numpy", "numba", "scipy", "opencv-contrib-python-headless", "mujoco", "pyelastica", "cma", "scikit-image")


def library_versions() -> dict[str, str | None]:
    """Installed versions of ``LIBRARIES`` (None for one not installed)."""
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for lib in LIBRARIES:
        try:
            out[lib] = version(lib)
        except PackageNotFoundError:
            out[lib] = None
    return out


def header(name: str, quick: bool) -> dict:
    """The keys every benchmark JSON starts with."""
    return {"benchmark": name, "cores": cores(), "created": datetime.now(UTC).isoformat(),
            "git_commit": git_commit(), "libraries": library_versions(), "quick": bool(quick)}


def write(name: str, doc: dict) -> Path:
    """Write results/bench/<name>.json atomically and return its path."""
    from stringcast.core import write_json

    path = BENCH_DIR / f"{name}.json"
    write_json(path, doc)
    return path


def film_first_motion(string_type: int, config: dict, work: Path, seed: int, calib_dir: Path | None = None):
    """Plan a campaign's first motion for ``string_type`` (target 1), play it on the lab and
    calibrate the trial: returns (campaign, d, trial) with ``d/calibration.json`` written."""
    from stringcast.api import run_calibration
    from stringcast.core import resolve_campaign, settings_from_config, stage_kwargs
    from stringcast.api import execute
    from stringcast.api import run_first_plan

    campaign = resolve_campaign({"string": string_type, "target": 1}, config, f"bench_{string_type}")
    settings = settings_from_config(config)
    d = work / f"string_{string_type}"
    run_first_plan(campaign, d / "motion.csv", d / "motion.json", seed=seed,
                   **stage_kwargs(run_first_plan, settings))
    trial = d / "trial_1"
    execute(d / "motion.csv", "virtual", trial, campaign, settings.executor, config, seed=seed)
    run_calibration(trial, calib_dir, campaign, d / "calibration.json", **stage_kwargs(run_calibration, settings))
    return campaign, d, trial


def play_on_lab(motion_csv: Path, trial: Path, campaign, executor, config: dict, seed: int) -> Path:
    """Play ``motion_csv`` on the virtual lab into the trial folder ``trial``
    (:func:`stringcast.api.execute`: ``campaign`` a Campaign or its campaign.yaml, ``executor`` its
    settings), recorded first into ``.<name>.partial`` beside it (one a killed run left is removed) and
    then renamed, so ``trial`` is whole or absent. Returns ``trial``."""
    import shutil

    from stringcast.api import execute

    tmp = trial.with_name(f".{trial.name}.partial")
    shutil.rmtree(tmp, ignore_errors=True)
    execute(motion_csv, "virtual", tmp, campaign, executor, config, seed=seed)
    tmp.rename(trial)
    return trial


def lab_calibration_clip(config: dict, work: Path) -> Path:
    """The lab's ChArUco clip (seed 11) that every benchmark calibrates its trials with: ``work/calib``."""
    from stringcast.core import resolve_campaign
    from stringcast_lab import write_calibration_clip

    return write_calibration_clip(resolve_campaign({"string": 1, "target": 1}, config, "bench"), config,
                                  work / "calib", seed=11)
