# Helpers shared by the rules: paths, input functions, the CLI command.
# No lambdas in rules: every input function is a named def here.
import functools
import os
import shlex
import sys
import time
from pathlib import Path

import yaml
from snakemake.exceptions import WorkflowError

from stringcast.check import check_campaign
from stringcast.core import (
    ConfigError,
    DataError,
    RunConflict,
    campaign_entries,
    claim_results,
    find_video,
    load_yaml,
    outputs_newer_than,
    reads_target,
    settings_from_config,
    stage_sections,
    without_target,
    workflow_stamp,
    write_by_content,
    write_job_config,
)
from stringcast.core.lifeline import ENV_PID


wildcard_constraints:
    campaign=r"[A-Za-z0-9_\-]+",
    trial=r"[0-9]+",


# Jobs run the package's `stringcast` command from the environment Snakemake runs in
# (the project's venv), found by PATH, and read the config this run holds (the Snakefile's
# configfile, every --configfile over it, and --config 'SECTION={KEY: VALUE}'), written once
# to results/.stringcast/config-<hash>.yaml and named in $STRINGCAST_CONFIG. No config path is
# part of a rule's command line: a rule's params are the settings its stage reads, so Snakemake
# reruns a stage when, and only when, one of them changes.
JOB_CONFIG = os.path.abspath(write_job_config(config))
# Each job's stringcast ends with this run, even one killed hard (stringcast.core.lifeline).
shell.prefix(
    f'set -euo pipefail; export PATH="{Path(sys.executable).parent}:$PATH"; '
    f'export STRINGCAST_CONFIG="{JOB_CONFIG}"; '
    f'export {ENV_PID}="{workflow_stamp()}"; '
)
CLI = "stringcast"
PLANNED_AT = time.time()
"""When this run began to plan its jobs (before it read any output's time)."""
# The run that submits the jobs checks the raw files and claims the results folders; a job
# that Slurm (or another executor) runs parses this file again and does neither.
SUBMITTER = workflow.exec_mode.name == "DEFAULT"


# Before its first job, this run claims the results folders its jobs write (one run at a time
# on each: stringcast.core.runlock) and stops if another run has made any of its outputs since
# it planned them: remaking them would delete a finished file.
onstart:
    claim_results_folders()


def claim_results_folders():
    jobs = list(workflow.dag.needrun_jobs())
    folders = {os.path.dirname(str(job.output[0])) for job in jobs if job.output}
    try:
        claim_results(f for f in folders if f.startswith("results"))
    except RunConflict as exc:
        raise WorkflowError(f"stringcast: {exc}") from None
    made = outputs_newer_than((str(f) for job in jobs for f in job.output), PLANNED_AT)
    if made:
        raise WorkflowError(
            f"stringcast: another run made {made[0]} (and {len(made) - 1} more of this run's "
            "outputs) while this one was planning; run again to take them as they are"
        )


try:
    SETTINGS = settings_from_config(config)
except ConfigError as exc:
    raise WorkflowError(f"stringcast: {exc}") from exc


def stage_settings(command):
    """The settings of the config sections that `stringcast <command>`'s stage reads (its
    entry point's settings parameters, stringcast.core.stages.stage_sections), as plain data: a
    rule's params, so that a changed setting reruns exactly the stages that read it."""
    return {s: getattr(SETTINGS, s).as_dict() for s in stage_sections(command)}


def lab_entries_for(command):
    """The params of `stringcast <command>`'s rule: an input function giving the config's
    entries this campaign resolves to (its arm, set-up, camera and string, and its target if
    the stage reads it: stringcast.core.stages.TARGET_COMMANDS; inline entries as written;
    stringcast.core.campaign_entries), so that editing one of them reruns that campaign's
    stages that read it and no other campaign's."""
    keep_target = reads_target(command)

    def entries(wildcards):
        e = _lab_entries(wildcards.campaign)
        return {k: v for k, v in e.items() if keep_target or k != "target"}

    return entries


@functools.cache
def _lab_entries(campaign):
    """lab_entries_for's entries, read once per campaign (every rule of every trial asks)."""
    path, doc = _campaign_doc(campaign)
    try:
        e = campaign_entries(doc, config, path)
    except (ConfigError, KeyError) as exc:
        raise WorkflowError(f"stringcast: {path}: {exc}") from exc
    return {k: (v[1] if isinstance(v, tuple) else v) for k, v in e.items()}


@functools.cache
def _campaign_doc(campaign):
    """(path, mapping) of data/<campaign>/campaign.yaml, read once per run."""
    path = Path("data", campaign, "campaign.yaml")
    try:
        return path, load_yaml(path) or {}
    except ConfigError as exc:
        raise WorkflowError(f"stringcast: {path}: {exc}") from exc


def campaigns():
    """Campaign names: folders data/<campaign>/ holding a campaign.yaml."""
    return sorted(p.parent.name for p in Path("data").glob("*/campaign.yaml"))


def campaign_problems(campaign):
    """Every error the check of data/<campaign>/'s raw files finds (stringcast.check,
    `stringcast check data/<campaign>`), one line each; none in a job that Slurm runs (the
    submitting run checked). Read once per campaign, before any job: a campaign with an error
    is not built, and the other campaigns are. A run whose --allowed-rules leave out every
    stage that reads the video (VIDEO_RULES: the loop benchmark's state mode) is not refused
    for the video, video.yaml or calib/, which it does not read."""
    allowed = workflow.dag_settings.allowed_rules if workflow.dag_settings else ()
    return _campaign_problems(campaign, not allowed or bool(set(allowed) & VIDEO_RULES))


VIDEO_RULES = {
    "decode",
    "calib_views",
    "calibrate",
    "sync",
    "sweep",
    "track",
    "report_trial",
}
"""The rules that read a trial's video, video.yaml or calib/."""


@functools.cache
def _campaign_problems(campaign, video):
    if not SUBMITTER:
        return ()
    return tuple(
        str(p)
        for p in check_campaign(Path("data", campaign), config, video=video)
        if p.is_error
    )


def checked(campaign):
    """Refuse a target of a campaign whose raw files have errors, naming each (before any job)."""
    problems = campaign_problems(campaign)
    if problems:
        raise WorkflowError(
            f"stringcast: data/{campaign} has {len(problems)} problem(s); none of its jobs is built:\n"
            + "\n".join(f"  {p}" for p in problems)
        )


def campaign_yaml(wildcards):
    """data/<campaign>/campaign.yaml, its campaign checked first (checked): the input of the
    rules whose stage reads the target (stringcast.core.stages.TARGET_COMMANDS)."""
    checked(wildcards.campaign)
    return f"data/{wildcards.campaign}/campaign.yaml"


def campaign_lab_yaml(wildcards):
    """The campaign.yaml less its target (stringcast.core.without_target), written by content
    to results/.stringcast/<campaign>/campaign-<hash>.yaml: the input of the rules whose stage
    never reads the target, so that a new target reruns only those that do."""
    checked(wildcards.campaign)
    return _lab_yaml(wildcards.campaign)


@functools.cache
def _lab_yaml(campaign):
    doc = _campaign_doc(campaign)[1]
    text = "# data/{0}/campaign.yaml less its target, for the stages that do not read it\n{1}".format(
        campaign, yaml.safe_dump(without_target(doc), sort_keys=True)
    )
    return str(
        write_by_content(text, Path("results", ".stringcast", campaign), "campaign")
    )


def campaign_for(command):
    """The campaign input of `stringcast <command>`'s rule: campaign_yaml if its stage reads the
    target (stringcast.core.stages.TARGET_COMMANDS), else campaign_lab_yaml."""
    return campaign_yaml if reads_target(command) else campaign_lab_yaml


def trials(campaign):
    """Trial indices present under data/<campaign>/ (those with a joints.csv)."""
    ks = []
    for p in Path("data", campaign).glob("trial_*/joints.csv"):
        suffix = p.parent.name.split("_", 1)[1]
        if suffix.isdigit():
            ks.append(int(suffix))
    return sorted(ks)


def trial_video(wildcards):
    """The trial's video: a container file, a frame folder, or a Photron .cihx, the one the
    stages read (stringcast.core.find_video; its campaign checked first: checked)."""
    checked(wildcards.campaign)
    d = Path("data", wildcards.campaign, f"trial_{wildcards.trial}")
    try:
        return str(find_video(d))
    except DataError:  # none: Snakemake names the missing input
        return str(d / "video.mkv")


def calib_views_input(wildcards):
    """The campaign's board views (rule calib_views), if it has calib/; else none."""
    return _calib_products(wildcards.campaign)[:1]


def intrinsics_input(wildcards):
    """The campaign's intrinsics fitted to those views (rule calib_views), if it has calib/."""
    return _calib_products(wildcards.campaign)[1:]


def _calib_products(campaign):
    r = f"results/{campaign}"
    has = Path("data", campaign, "calib").is_dir()
    return [f"{r}/calib_views.npz", f"{r}/intrinsics.json"] if has else []


def previous_params(wildcards):
    """Eq. (3) starts from the previous trial's estimate (chi_best)."""
    k = int(wildcards.trial)
    if k <= 1:
        return []
    return [f"results/{wildcards.campaign}/trial_{k - 1}/params.json"]


def predicting_params(wildcards):
    """The estimate that predicts trial k (the predict rule): trial k - 1's params.json; trial 1
    has none."""
    k = int(wildcards.trial)
    if k <= 1:
        raise WorkflowError(
            f"stringcast: results/{wildcards.campaign}/trial_{k}/prediction.json: trial 1 has "
            "no earlier estimate to predict it"
        )
    return f"results/{wildcards.campaign}/trial_{k - 1}/params.json"


def prediction_input(wildcards):
    """Trial k's prediction check (rule predict) for its page; none for trial 1."""
    if int(wildcards.trial) <= 1:
        return []
    return [f"results/{wildcards.campaign}/trial_{wildcards.trial}/prediction.json"]


def trial_reports(wildcards):
    return [
        f"results/{wildcards.campaign}/trial_{k}/report.html"
        for k in trials(wildcards.campaign)
    ]


def all_targets(wildcards=None):
    """Every stage's product of every trial of every campaign without an error in its raw files,
    so a deleted one is made again and what depends on it reruns (Snakemake does not remake a
    missing file that no requested output needs); and, where some campaign has one, REFUSED,
    which fails last, listing them. The refused campaigns' problems are also printed now, so
    that a dry run shows them."""
    refused = refused_campaigns()
    for c in refused:
        print(
            f"stringcast: data/{c} is not built, {len(campaign_problems(c))} problem(s):\n"
            + "\n".join(f"  {p}" for p in campaign_problems(c)),
            file=sys.stderr,
        )
    return campaign_targets() + ([REFUSED] if refused else [])


REFUSED = "results/.refused_campaigns"
"""The target of the refused_campaigns job, never made: the job fails, naming the refused campaigns."""


def refused_campaigns():
    """The campaigns under data/ whose raw files have errors (campaign_problems), by name."""
    return [c for c in campaigns() if campaign_problems(c)]


def refused_report(wildcards):
    """The refused campaigns' problems, one shell-quoted line each (the refused_campaigns job's)."""
    lines = []
    for c in refused_campaigns():
        lines.append(
            f"stringcast: data/{c} was not built, {len(campaign_problems(c))} problem(s):"
        )
        lines += [f"  {p}" for p in campaign_problems(c)]
    lines.append(
        f"stringcast check data/<campaign> lists them again; the other campaigns were built"
    )
    return " ".join(map(shlex.quote, lines))


def campaign_targets(wildcards=None):
    """all_targets without REFUSED: every product of the campaigns that are built."""
    out = []
    stages = (
        "calibration.json",
        "sync.json",
        "geometry.json",
        "clock.json",
        "tracks.parquet",
        "params.json",
        "motion.csv",
        "report.html",
    )
    for c in campaigns():
        if campaign_problems(c):
            continue
        out.append(f"results/{c}/first_motion/motion.csv")
        ks = trials(c)
        out += [f"results/{c}/trial_{k}/{name}" for k in ks for name in stages]
        out += [f"results/{c}/trial_{k}/prediction.json" for k in ks if k > 1]
        if ks:
            out.append(f"results/{c}/report.html")
    return out
