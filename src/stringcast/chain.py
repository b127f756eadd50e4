"""One trial's stages in one process, in the workflow's order (``stringcast next``).

``stringcast next data/<campaign>/trial_<k>`` is what a person at the arm runs after an execution:
decode, calibrate (the campaign's intrinsics first, once, where it has ``calib/``), sync, sweep,
track, estimate, predict (from trial 2 on), plan and the trial's report, then the campaign's page.
Each step is the ``stringcast`` subcommand the workflow's rule runs, with the same arguments, the
same log file (``results/<campaign>/logs/<rule>_<k>.log``) and the same outputs, so the two write
the same files (``tests/workflow/test_workflow.py`` compares them) and Snakemake takes the files
``next`` wrote as its own on a later batch run. Snakemake stays the tool for reprocessing many
trials, for profiles and for Slurm; ``next`` needs neither it nor a server.

The steps' input files come from the contract the rules are checked against
(:mod:`stringcast.core.ports`); their outputs and other options mirror ``workflow/rules/*.smk``.
"""
from __future__ import annotations

import contextlib
import os
import time
from dataclasses import dataclass
from pathlib import Path

from stringcast.check import check_campaign
from stringcast.core import DataError, TrialFiles, claim_results, input_argv, load_config, trial_inputs

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
    """The steps that make trial ``k``'s results, as the workflow's rules run them: each command's
    input files from :data:`stringcast.core.ports.INPUTS` (:func:`~stringcast.core.ports.input_argv`),
    its outputs and other options as its rule writes them.

    Args:
        campaign, k: the trial (``data/<campaign>/trial_<k>``). has_calib: the campaign has ``calib/``.
        workers: the most worker processes a stage may use.
    """
    res, out = f"results/{campaign}", f"results/{campaign}/trial_{k}"
    logs = {"calib_views": f"{res}/logs/calib_views.log", "report_trial": f"{res}/logs/report_{k}.log"}
    # the files the workflow's rules name (the video found as its trial_video finds it)
    files = trial_inputs(campaign, k, TrialFiles.in_folder(f"data/{campaign}/trial_{k}"), has_calib)
    w = {rule: str(min(n, workers)) for rule, n in RULE_WORKERS.items()}

    def _step(rule: str, rest: tuple[str, ...], outputs: tuple[str, ...]) -> Step:
        command = rule.replace("_", "-")
        return Step(rule, (command, *input_argv(command, files), *rest), outputs,
                    logs.get(rule, f"{res}/logs/{rule}_{k}.log"))   # the log the rule names

    geo, clock = files["geometry"], files["clock"]
    steps = [_step("decode", ("--out", files["frames"]), (files["frames"], f"{out}/frames.json"))]
    if has_calib:
        views, intrinsics = files["calib_views"], files["intrinsics"]
        steps.append(_step("calib_views", ("--out", views, "--out-intrinsics", intrinsics), (views, intrinsics)))
    tracked = (files["tracks"], files["tracking"], f"{out}/tracking_overlay.png")
    steps += [
        _step("calibrate", ("--out", files["calibration"]), (files["calibration"],)),
        _step("sync", ("--out", files["sync"], "--workers", w["sync"]), (files["sync"],)),
        _step("sweep", ("--out-geometry", geo, "--out-clock", clock, "--workers", w["sweep"]), (geo, clock)),
        _step("track", ("--out", tracked[0], "--out-quality", tracked[1], "--overlay", tracked[2],
                        "--workers", w["track"]), tracked),
        _step("estimate", ("--trial", str(k), "--out-params", files["params"], "--out-fit", files["fit"]),
              (files["params"], files["fit"])),
    ]
    if k > 1:
        steps.append(_step("predict", ("--out", files["prediction"]), (files["prediction"],)))
    motion = (files["next_motion"], files["next_motion_meta"])
    steps += [
        _step("plan", ("--seed", str(k), "--out-dir", out), motion),
        _step("report_trial", ("--out", f"{out}/report.html"), (f"{out}/report.html",)),
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
