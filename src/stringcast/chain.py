"""One trial's stages in one process, in the workflow's order (``stringcast next``).

``stringcast next data/<campaign>/trial_<k>`` is what a person at the arm runs after an execution:
decode, calibrate (the campaign's intrinsics first, once, where it has ``calib/``), sync, sweep,
track, estimate, predict (from trial 2 on), plan and the trial's report, then the campaign's page.
Each step is the ``stringcast`` subcommand the workflow's rule runs, with the same arguments, the
same log file (``results/<campaign>/logs/<rule>_<k>.log``) and the same outputs, so the two write
the same files (``tests/workflow/test_workflow.py`` compares them) and Snakemake takes the files
``next`` wrote as its own on a later batch run. Snakemake stays the tool for reprocessing many
trials, for profiles and for Slurm; ``next`` needs neither it nor a server.

The step list mirrors ``workflow/rules/*.smk``: a change to a rule's command line is a change here.
"""
from __future__ import annotations

import contextlib
import os
import time
from dataclasses import dataclass
from pathlib import Path

from stringcast.check import check_campaign
from stringcast.core import DataError, TrialFiles, claim_results, load_config

RULE_WORKERS = {"sync": 4, "sweep": 2, "track": 4}
"""The rules' ``threads`` for the stages that take ``--workers`` (capped at this machine's CPUs)."""


@dataclass(frozen=True)
class Step:
    """One stage of the chain.

    Attributes:
        rule: the workflow rule whose outputs it writes.
        argv: the ``stringcast`` arguments, paths relative to the project root.
        outputs: what it writes, relative to the project root.
        log: the rule's log file, relative to the project root.
    """

    rule: str
    argv: tuple[str, ...]
    outputs: tuple[str, ...]
    log: str


def trial_location(trial_dir: str | Path) -> tuple[Path, str, int]:
    """(project root, campaign, k) of ``<root>/data/<campaign>/trial_<k>``.

    Raises:
        DataError: the folder is not a trial folder of a project's ``data/``.
    """
    d = Path(os.path.abspath(trial_dir))   # links kept: a campaign folder linked into data/ is in this project
    suffix = d.name.partition("_")[2]
    if not (d.name.startswith("trial_") and suffix.isdigit() and d.parent.parent.name == "data"):
        raise DataError(f"{trial_dir}: not a trial folder: expected <project>/data/<campaign>/trial_<k> "
                        "(docs/data_contract.md)")
    if not d.is_dir():
        raise DataError(f"{trial_dir}: no such folder")
    return d.parent.parent.parent, d.parent.name, int(suffix)


def trial_steps(campaign: str, k: int, has_calib: bool, workers: int) -> list[Step]:
    """The steps that make trial ``k``'s results, as the workflow's rules run them.

    Args:
        campaign, k: the trial (``data/<campaign>/trial_<k>``). has_calib: the campaign has ``calib/``.
        workers: the most worker processes a stage may use.
    """
    data, res = f"data/{campaign}", f"results/{campaign}"
    trial, out = f"{data}/trial_{k}", f"{res}/trial_{k}"
    camp = f"{data}/campaign.yaml"
    logs = {"calib_views": f"{res}/logs/calib_views.log", "report_trial": f"{res}/logs/report_{k}.log"}

    def _step(rule: str, argv: tuple[str, ...], outputs: tuple[str, ...]) -> Step:
        return Step(rule, argv, outputs, logs.get(rule, f"{res}/logs/{rule}_{k}.log"))   # the log the rule names

    w = {rule: str(min(n, workers)) for rule, n in RULE_WORKERS.items()}
    raw = TrialFiles.in_folder(trial)           # the files the workflow's trial_video and rules name
    video, joints = ("--video", str(raw.video)), ("--joints", str(raw.joints))
    played = ("--played-motion", str(raw.played))
    frames = ("--frames", f"{out}/frames.npy")
    geo, clock = f"{out}/geometry.json", f"{out}/clock.json"
    steps = [_step("decode", ("decode", *video, "--out", f"{out}/frames.npy"),
                   (f"{out}/frames.npy", f"{out}/frames.json"))]
    calib: tuple[str, ...] = ("--calib-views", "--intrinsics")      # none: the rule's empty inputs
    if has_calib:
        views, intrinsics = f"{res}/calib_views.npz", f"{res}/intrinsics.json"
        calib = ("--calib-views", views, "--intrinsics", intrinsics)
        steps.append(_step("calib_views", ("calib-views", "--calib-dir", f"{data}/calib", "--campaign", camp,
                                          "--out", views, "--out-intrinsics", intrinsics), (views, intrinsics)))
    steps += [
        _step("calibrate", ("calibrate", *video, *joints, *calib, "--campaign", camp,
                           "--out", f"{out}/calibration.json"), (f"{out}/calibration.json",)),
        _step("sync", ("sync", *video, "--video-meta", str(raw.video_meta), *joints, "--calibration",
                      f"{out}/calibration.json", "--campaign", camp, "--out", f"{out}/sync.json", *frames,
                      "--workers", w["sync"]), (f"{out}/sync.json",)),
        _step("sweep", ("sweep", *video, *joints, "--calibration", f"{out}/calibration.json", "--sync",
                       f"{out}/sync.json", "--campaign", camp, "--out-geometry", geo, "--out-clock", clock, *frames,
                       "--workers", w["sweep"]), (geo, clock)),
        _step("track", ("track", *video, *joints, "--geometry", geo, "--clock", clock, "--campaign", camp,
                       "--out", f"{out}/tracks.parquet", "--out-quality", f"{out}/tracking.json", "--overlay",
                       f"{out}/tracking_overlay.png", *frames, "--workers", w["track"]),
             (f"{out}/tracks.parquet", f"{out}/tracking.json", f"{out}/tracking_overlay.png")),
    ]
    prev = ("--prev", f"{res}/trial_{k - 1}/params.json") if k > 1 else ("--prev",)
    steps.append(_step("estimate", ("estimate", "--tracks", f"{out}/tracks.parquet", *joints, "--campaign", camp,
                                   *prev, "--geometry", geo, "--clock", clock, "--tracking", f"{out}/tracking.json",
                                   "--trial", str(k), "--out-params", f"{out}/params.json", "--out-fit",
                                   f"{out}/fit.parquet"),
                      (f"{out}/params.json", f"{out}/fit.parquet")))
    if k > 1:
        steps.append(_step("predict", ("predict", "--params", f"{res}/trial_{k - 1}/params.json", "--tracks",
                                      f"{out}/tracks.parquet", *joints, "--campaign",
                                      camp, "--out", f"{out}/prediction.json"), (f"{out}/prediction.json",)))
    steps += [
        _step("plan", ("plan", "--params", f"{out}/params.json", *played,
                      "--tracks", f"{out}/tracks.parquet", *joints, "--campaign", camp,
                      "--seed", str(k), "--out-dir", out), (f"{out}/motion.csv", f"{out}/motion.json")),
        _step("report_trial", ("report-trial", *video, *joints, *played,
                               "--geometry", geo, "--clock", clock, "--tracks", f"{out}/tracks.parquet",
                               "--tracking", f"{out}/tracking.json", "--params", f"{out}/params.json",
                               "--fit", f"{out}/fit.parquet", "--next-motion", f"{out}/motion.csv",
                               "--next-motion-meta", f"{out}/motion.json", "--prediction",
                               *((f"{out}/prediction.json",) if k > 1 else ()), "--campaign", camp,
                               "--out", f"{out}/report.html"), (f"{out}/report.html",)),
    ]
    return steps


def campaign_step(campaign: str) -> Step:
    """The campaign's page (the ``report_campaign`` rule), once every trial has its report."""
    res = f"results/{campaign}"
    return Step("report_campaign", ("report-campaign", "--data-dir", f"data/{campaign}", "--results-dir", res,
                                    "--campaign", f"data/{campaign}/campaign.yaml", "--out", f"{res}/report.html"),
                (f"{res}/report.html",), f"{res}/logs/report_campaign.log")


def run_next(trial_dir: str | Path, config_paths: list[str], main, say=print) -> Path:
    """Run trial ``trial_dir``'s stages in this process (:func:`trial_steps`), then the campaign's page.

    Args:
        trial_dir: ``<root>/data/<campaign>/trial_<k>``.
        config_paths: the config files, merged in order (the workflow's: the project's
            config/config.yaml, then each ``--configfile``).
        main: :func:`stringcast.cli.main` (each step runs its subcommand through it).
        say: where the progress lines go.

    Returns:
        The next motion: ``results/<campaign>/trial_<k>/motion.csv`` (absolute).

    Raises:
        DataError: not a trial folder; the campaign's raw files have errors (each named, as
            ``stringcast check`` names them); trial k - 1 has no estimate yet; a stage failed (its
            own error line was printed above, and its log is named).
    """
    root, campaign, k = trial_location(trial_dir)
    paths = [str(Path(p).resolve()) for p in config_paths]
    config = load_config(paths)
    with contextlib.chdir(root):
        errors = [p for p in check_campaign(Path("data", campaign), config) if p.is_error]
        if errors:
            raise DataError(f"data/{campaign} has {len(errors)} problem(s); nothing was run:\n"
                            + "\n".join(f"  {p}" for p in errors))
        prev = Path(f"results/{campaign}/trial_{k - 1}/params.json")
        if k > 1 and not prev.is_file():
            raise DataError(f"{root / prev}: missing: trial {k}'s estimate starts from trial {k - 1}'s "
                            f"(eq. 3): run `stringcast next data/{campaign}/trial_{k - 1}` first")
        steps = trial_steps(campaign, k, Path("data", campaign, "calib").is_dir(), os.cpu_count() or 1)
        if Path(f"results/{campaign}/intrinsics.json").is_file() and Path(f"results/{campaign}/calib_views.npz").is_file():
            steps = [s for s in steps if s.rule != "calib_views"]          # once per campaign
        claim_results({str(Path(o).parent) for s in steps for o in s.outputs})
        reports = [f"results/{campaign}/{j.parent.name}/report.html" for j in Path("data", campaign).glob("trial_*/joints.csv")]
        for i, step in enumerate(steps, 1):
            _run_step(step, f"{i}/{len(steps)}", paths, main, say)
        if all(Path(r).is_file() for r in reports):
            _run_step(campaign_step(campaign), "+", paths, main, say)
        else:
            say(f"[next] the campaign's page waits for every trial's report (results/{campaign}/report.html)")
    return root / "results" / campaign / f"trial_{k}" / "motion.csv"


def _run_step(step: Step, label: str, paths: list[str], main, say) -> None:
    """One step through ``main``, with a progress line before and after; DataError where it failed."""
    say(f"[next {label}] {step.argv[0]} ...")
    t0 = time.monotonic()
    code = main([*(a for p in paths for a in ("--config", p)), "--log", step.log, *step.argv])
    if code:
        raise DataError(f"{step.argv[0]} failed (exit status {code}); its log: {Path(step.log).resolve()}")
    say(f"[next {label}] {step.argv[0]} done, {time.monotonic() - t0:.1f} s")
