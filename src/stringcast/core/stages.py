"""The workflow's stages as the command line runs them: each subcommand's entry point
(``module:function``), the config sections it reads and whether it reads the campaign's target.

One table, read by the CLI (:mod:`stringcast.cli`, which runs a stage), the workflow
(``workflow/rules/common.smk``: a rule's params are the sections its stage reads, so a changed
setting reruns exactly the stages that read it) and config/README.md's generated reference.
"""
from __future__ import annotations

import importlib

from .sections import sections_read_from_source


STAGES = {
    "decode": "stringcast.video:write_frame_cache",
    "calib-views": "stringcast.calibrate:write_calib_views",
    "calibrate": "stringcast.calibrate:run_calibration",
    "sync": "stringcast.sync:run_sync",
    "sweep": "stringcast.sync:run_sweep",
    "track": "stringcast.track:run_tracking",
    "estimate": "stringcast.estimate:run_estimation",
    "predict": "stringcast.estimate:run_prediction",
    "plan-first": "stringcast.plan:run_first_plan",
    "plan": "stringcast.plan:run_plan",
    "report-trial": "stringcast.report:write_trial_report",
    "report-campaign": "stringcast.report:write_campaign_report",
}
"""Each workflow subcommand's stage entry point, ``module:function``."""


def stage_entry(command: str):
    """The stage function a subcommand runs (imported on demand: each loads only its stage)."""
    module, _, name = STAGES[command].partition(":")
    return getattr(importlib.import_module(module), name)


def stage_sections(command: str) -> tuple[str, ...]:
    """The config sections a workflow subcommand reads: those of its stage entry's settings
    parameters, read from the source without importing the stage
    (:func:`stringcast.core.sections_read_from_source`). The rules' params are these sections."""
    return sections_read_from_source(STAGES[command])


TARGET_COMMANDS = ("predict", "plan-first", "plan", "report-trial", "report-campaign")
"""The workflow subcommands that read the campaign's target: the workflow gives the others its
campaign.yaml without the target, so that a new target reruns only these."""


def reads_target(command: str) -> bool:
    """Whether a subcommand reads the campaign's target (:data:`TARGET_COMMANDS`)."""
    return command in TARGET_COMMANDS


REFERENCE_MARK = "<!-- below: made by `stringcast settings --markdown`; tests/test_cli.py keeps it in step -->"


def settings_reference(tables: str) -> str:
    """config/README.md's generated part: which sections each workflow stage reads, then
    ``tables`` (every setting's default and meaning)."""
    rows = [f"| `{cmd}` | {', '.join(f'`{s}`' for s in stage_sections(cmd))} |" for cmd in STAGES]
    return "\n".join([REFERENCE_MARK, "", "## What each stage reads", "",
                      "| stage (`stringcast` command) | sections read |", "| --- | --- |", *rows, "",
                      "## Every setting", "", tables])
