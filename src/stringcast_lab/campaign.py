"""The casting loop on the virtual lab (the paper's Fig. 2), end to end.

``run_campaign`` plays the role of the person at the arm: it creates
``data/<name>/`` (campaign.yaml and a ChArUco clip for intrinsics), asks the
Snakemake workflow for the first motion, plays it on the virtual lab with the
executor's command (``stringcast execute --backend virtual``), asks the workflow to process the trial (calibrate, sync, track,
estimate, plan, report; from trial 2 on also the previous estimate's prediction of it,
``prediction.json``), plays the next motion, and so on until the lab says the
tip hit the target or ``max_executions`` is reached.

Only this loop, standing where the experimenter stands, reads the lab's ground
truth: its verdict (``ground_truth.json``: did the real tip hit?) to decide when
to stop, and, once a trial is processed, the tracked points' error against the
lab's true points (``ground_truth.parquet``), which it prints and keeps in
``campaign_summary.json``. The workflow's stages, reports included, never read
either: footage from a real camera has no ground truth.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from collections.abc import Callable, Iterator, Sequence

import numpy as np
import pandas as pd

from stringcast.core import ConfigError, load_config, load_yaml, read_parquet, resolve_campaign, write_yaml
from .calib_clip import write_calibration_clip


_RULE = re.compile(r"^(?:local)?rule (\w+):")
_JOBID = re.compile(r"^\s+jobid: (\d+)")
_FINISHED = re.compile(r"Finished jobid: (\d+)")
_STEPS = re.compile(r"(\d+) of (\d+) steps")
_JOB_LINE = re.compile(r"^(?:[a-z][\w ()-]*: (?:ok|warn|fail)[^:]*: |stringcast [\w-]+: (?:error|internal error): )")
"""A job's own line on the terminal: its verdict or its error (:class:`stringcast.cli.JobLog`)."""


class StageProgress:
    """A line when each workflow stage starts and one when it is done, with its seconds, from
    Snakemake's own log lines as they come.

    Snakemake announces a job with ``rule sync:`` and ``jobid: 6``, and ends it with ``Finished
    jobid: 6 (...)`` and ``3 of 7 steps (43%) done``; this prints ``[label] sync ...`` and then
    ``[label] sync done, 7.0 s (3/7)``; a job's own verdict or error line is passed on, indented.
    Stages side by side are timed each on its own. The last 40 lines are kept for an error message."""

    def __init__(self, label: str, out=None):
        self.label, self.out = label, out or sys.stdout
        self.rule: str | None = None
        self.started: dict[str, tuple[str, float]] = {}
        self.done: str | None = None
        self.tail: list[str] = []

    def feed(self, line: str) -> None:
        self.tail = (self.tail + [line.rstrip()])[-40:]
        if m := _RULE.match(line):
            self.rule = m.group(1)
        elif (m := _JOBID.match(line)) and self.rule:
            if self.rule != "all":
                self.started[m.group(1)] = (self.rule, time.perf_counter())
                print(f"[{self.label}] {self.rule} ...", file=self.out, flush=True)
            self.rule = None
        elif m := _FINISHED.search(line):
            self.done = m.group(1)
        elif _JOB_LINE.match(line):
            print(f"[{self.label}]   {line.rstrip()}", file=self.out, flush=True)
        elif (m := _STEPS.search(line)) and self.done in self.started:
            rule, t0 = self.started.pop(self.done)
            print(f"[{self.label}] {rule} done, {time.perf_counter() - t0:.1f} s ({m.group(1)}/{m.group(2)})",
                  file=self.out, flush=True)
            self.done = None


def run_workflow(root: Path, targets: list[str], cores: int, config_files: list[Path], label: str = "workflow",
                 extra_args: Sequence[str] = ()) -> float:
    """Run the workflow for ``targets``, printing a line per finished stage (:class:`StageProgress`);
    returns wall seconds. ``extra_args``: more Snakemake arguments (e.g. ``--allowed-rules ...``).
    Raises RuntimeError on failure, with Snakemake's last lines."""
    cmd = [sys.executable, "-m", "snakemake", *targets, "--cores", str(cores), "--snakefile",
           str(root / "Snakefile"), "--directory", str(root), "--rerun-incomplete", *extra_args]
    if config_files:
        cmd += ["--configfile", *map(str, config_files)]
    t0 = time.perf_counter()
    progress = StageProgress(label)
    with subprocess.Popen(cmd, cwd=root, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) as proc:
        for line in proc.stdout:
            progress.feed(line)
    if proc.returncode != 0:
        tail = "\n".join(progress.tail[-15:])
        raise RuntimeError(f"snakemake failed for {' '.join(targets)} (exit {proc.returncode}); "
                           f"see the logs under {root / 'results'}/<campaign>/logs/\n{tail}")
    return time.perf_counter() - t0


def campaign_config(root: Path, config_path: str | Path | list | None = None) -> tuple[dict, list[Path]]:
    """The config a campaign under ``root`` runs with: ``root/config/config.yaml`` with the given
    file(s) merged over it, in order, and those files (the workflow's ``--configfile`` list)."""
    # the lab reads the config the workflow's jobs read: the project's, then the given files over it
    given = [] if config_path is None else [config_path] if isinstance(config_path, (str, Path)) else config_path
    base = Path(root).resolve() / "config" / "config.yaml"
    # the project's own file is read anyway; passed again it would change every job's command line
    given = [q for q in (Path(p).resolve() for p in given) if not (base.exists() and q == base.resolve())]
    return load_config(read_config_files(root, given)), given


def read_config_files(root: Path, given: list[Path]) -> list[Path]:
    """The files the workflow's jobs and the lab read, in order: ``root/config/config.yaml`` (where it
    is), then ``given`` (:func:`campaign_config`'s second value)."""
    base = Path(root).resolve() / "config" / "config.yaml"
    return ([base] if base.exists() else []) + list(given)


def _prepare_campaign(root: Path, name: str, string: str, target: str, seed: int,
                      config: dict) -> tuple[Path, Path, object, dict[str, float]]:
    """``data/<name>/campaign.yaml`` (written once, validated first; an existing one must be for the
    same string and target) and the lab's calibration clip. Returns (data folder, campaign.yaml,
    the resolved campaign, the lab's timings). Raises ConfigError as :func:`run_campaign`."""
    data = root / "data" / name
    camp_yaml = data / "campaign.yaml"
    doc = {"string": _id(string), "target": _id(target), "setup": "default", "seed": int(seed)}
    if camp_yaml.exists():
        old = load_yaml(camp_yaml)
        if str(old.get("string")) != str(doc["string"]) or str(old.get("target")) != str(doc["target"]):
            raise ConfigError(f"{camp_yaml}: exists for string {old.get('string')} target "
                              f"{old.get('target')}; choose another campaign name")
    else:
        resolve_campaign(doc, config, name, camp_yaml)  # validate before writing anything
        write_yaml(camp_yaml, doc)
    campaign = resolve_campaign(load_yaml(camp_yaml), config, name, camp_yaml)
    timings: dict[str, float] = {}
    if not (data / "calib").is_dir():
        t0 = time.perf_counter()
        with folder_in_place(data / "calib") as tmp:
            write_calibration_clip(campaign, config, tmp, seed)
        timings["lab_calibration_clip_s"] = time.perf_counter() - t0
    return data, camp_yaml, campaign, timings


@contextmanager
def folder_in_place(folder: Path) -> Iterator[Path]:
    """A new folder of its own beside ``folder`` (a hidden, unique name) to fill; renamed onto ``folder`` when
    the block ends, removed when it raises: the lab's trial appears whole or not at all."""
    tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=folder.parent))
    try:
        yield tmp
        os.replace(tmp, folder)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def play(motion: Path, out: Path, campaign_yaml: Path, root: Path, given: list[Path], seed: int) -> None:
    """Play ``motion`` on the virtual lab into ``out`` as the person at the arm does: ``stringcast execute
    --backend virtual`` (its limit checks, pre- and post-roll), with the config the workflow reads
    (the project's, then ``given``).

    Raises:
        RuntimeError: the executor refused the motion or failed (its output is named).
    """
    configs = [a for p in read_config_files(root, given) for a in ("--config", str(p))]
    proc = subprocess.run([sys.executable, "-m", "stringcast.cli", *configs, "execute", str(motion), "--backend",
                           "virtual", "--campaign", str(campaign_yaml), "--out", str(out), "--seed", str(int(seed))],
                          capture_output=True, text=True)
    if proc.returncode:
        raise RuntimeError(f"stringcast execute {motion} failed (exit {proc.returncode}):\n"
                           f"{(proc.stdout + proc.stderr)[-3000:]}")


def run_campaign(name: str, string: str, target: str, config_path: str | Path | list | None = None,
                 max_executions: int = 5, cores: int = 2, seed: int = 0,
                 root: Path = Path("."), reports: bool = True, keep_frames: bool = True,
                 before_processing: Callable[[int, Path, Path], None] | None = None,
                 workflow_args: Sequence[str] = ()) -> dict:
    """Run (or resume) a campaign on the virtual lab.

    Args:
        name: campaign name: data/<name>/ and results/<name>/.
        string, target: ids from the config.
        config_path: config file(s) merged over the project's ``config/config.yaml``, passed to
            Snakemake as ``--configfile``; the lab reads the same merge.
        max_executions: stop after this many executions without a hit.
        reports: False: only what the loop needs (no HTML reports, and the hitting trial is
            not processed); the loop benchmark's setting, about a third faster.
        keep_frames: False: delete each trial's decoded video (``frames.npy``, F x H x W bytes)
            once the trial is processed; the loop benchmark's setting, where hundreds of trials
            would fill the disk. The results stay up to date; a stage rerun later decodes again.
        before_processing: called as ``(k, data/<name>/trial_<k>, results/<name>/trial_<k>)`` after
            execution k is recorded and before the workflow processes it (not for a hitting trial
            left unprocessed). The loop benchmark's state mode writes the trial's tracked points
            there (``benchmarks/loop_state.py``); None: nothing.
        workflow_args: more Snakemake arguments for every workflow call (the state mode's
            ``--allowed-rules``).

    Returns:
        dict with per-trial rows (lab hit, closest approach mm; for processed trials the tracking
        error against the lab's truth, :func:`tracking_error_mm`) and the report path.

    Raises:
        ConfigError: bad ids, or an existing campaign.yaml for another string/target.
        RuntimeError: a workflow step failed (its log path is named).
    """

    root = Path(root).resolve()
    config, given = campaign_config(root, config_path)
    data, camp_yaml, campaign, timings = _prepare_campaign(root, name, string, target, seed, config)

    timings["plan_first_s"] = run_workflow(root, [f"results/{name}/first_motion/motion.csv"], cores, given,
                                           f"campaign {name}", workflow_args)
    motion = root / "results" / name / "first_motion" / "motion.csv"
    rows = []
    for k in range(1, max_executions + 1):
        trial = data / f"trial_{k}"
        if not (trial / "joints.csv").exists():
            print(f"[campaign {name}] execution {k}: the virtual lab plays {motion.relative_to(root)}, "
                  f"simulating the string and filming it ...", flush=True)
            t0 = time.perf_counter()
            with folder_in_place(trial) as tmp:
                play(motion, tmp, camp_yaml, root, given, seed * 1000 + k)
            timings[f"execute_{k}_s"] = time.perf_counter() - t0
            print(f"[campaign {name}] execution {k}: played and filmed in {timings[f'execute_{k}_s']:.0f} s "
                  f"-> {trial.relative_to(root)}", flush=True)
        truth = json.loads((trial / "ground_truth.json").read_text())
        rows.append({"trial": k, "hit": bool(truth["hit"]),
                     "closest_approach_mm": float(truth["closest_approach_mm"])})
        floor = truth.get("floor_clearance_mm")
        why = f" (the string or the arm below the floor by {-floor:.1f} mm)" if floor is not None and floor < 0 else ""
        print(f"[campaign {name}] execution {k}: lab tip closest approach "
              f"{truth['closest_approach_mm']:.1f} mm -> {'HIT' if truth['hit'] else 'miss'}{why}", flush=True)
        if truth["hit"] and not reports:
            break
        if before_processing is not None:
            before_processing(k, trial, root / "results" / name / f"trial_{k}")
        extra = [f"results/{name}/trial_{k}/report.html"] + [f"results/{name}/trial_{k}/prediction.json"] * (k > 1)
        timings[f"process_{k}_s"] = run_workflow(
            root, [f"results/{name}/trial_{k}/motion.csv"] + extra * reports, cores, given,
            f"campaign {name}, trial {k}", workflow_args)
        if not keep_frames:
            for cache in ("frames.npy", "frames.json"):
                (root / "results" / name / f"trial_{k}" / cache).unlink(missing_ok=True)
        err = tracking_error_mm(root / "results" / name / f"trial_{k}" / "tracks.parquet",
                                trial / "ground_truth.parquet")
        rows[-1].update(tracking_error_median_mm=err[0], tracking_error_p95_mm=err[1])
        print(f"[campaign {name}] execution {k}: tracked points vs the lab's truth: median {err[0]:.2f} mm, "
              f"95th percentile {err[1]:.2f} mm", flush=True)
        if truth["hit"]:
            break
        motion = root / "results" / name / f"trial_{k}" / "motion.csv"
    if reports:
        timings["campaign_report_s"] = run_workflow(root, [f"results/{name}/report.html"], cores, given,
                                                   f"campaign {name}", workflow_args)
    report = root / "results" / name / "report.html"
    summary = {"campaign": name, "string": campaign.string_id, "target": campaign.target.name,
               "executions": len(rows), "hit": any(r["hit"] for r in rows), "trials": rows,
               "timings_s": timings, "report": str(report) if reports else None}
    (root / "results" / name / "campaign_summary.json").write_text(json.dumps(summary, indent=2))
    verdict = f"hit after {len(rows)} execution(s)" if summary["hit"] else f"no hit in {len(rows)} execution(s)"
    print(f"[campaign {name}] {verdict}")
    if reports:
        print(f"report: {report}")
    return summary


def tracking_errors(tracks: pd.DataFrame, truth: pd.DataFrame) -> tuple[np.ndarray, float]:
    """Distances (mm) between the valid tracked points 1..n and the lab's true points of the same
    frame and point (the grasp, point 0, comes from forward kinematics, not from tracking), and
    the share of tracked points 1..n that are valid. Tables: ``frame, point, x_m, y_m`` (tracks
    also ``valid``). Used here and by ``benchmarks/tracking.py``."""
    m = tracks.merge(truth, on=["frame", "point"], suffixes=("", "_true"))
    pts = m[m["point"] > 0]
    ok = pts["valid"].to_numpy(bool)
    e = np.hypot(pts["x_m"] - pts["x_m_true"], pts["y_m"] - pts["y_m_true"]).to_numpy()[ok] * 1000
    return e, float(ok.mean()) if len(ok) else float("nan")


def tracking_error_mm(tracks_parquet: Path, truth_parquet: Path) -> tuple[float, float]:
    """Median and 95th percentile (mm) of :func:`tracking_errors` for ``tracks.parquet`` against
    ``ground_truth.parquet``; (nan, nan) when no valid point has a true one.

    Raises:
        DataError: a file is missing or lacks ``frame, point, x_m, y_m`` (tracks: and ``valid``), named.
    """
    cols = ["frame", "point", "x_m", "y_m"]
    e, _ = tracking_errors(read_parquet(tracks_parquet, cols + ["valid"]), read_parquet(truth_parquet, cols))
    if not len(e):
        return float("nan"), float("nan")
    return float(np.median(e)), float(np.percentile(e, 95))


def _id(x):
    s = str(x)
    return int(s) if s.isdigit() else s
