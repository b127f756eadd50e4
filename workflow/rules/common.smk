# Helpers shared by the rules: paths, input functions, the CLI command.
# No lambdas in rules: every input function is a named def here.
import functools
import os
import sys
from pathlib import Path

from snakemake.exceptions import WorkflowError

from stringcast.cli import stage_sections
from stringcast.core import (
    ConfigError,
    DataError,
    campaign_entries,
    check_joint_header,
    load_campaign,
    load_yaml,
    settings_from_config,
)


wildcard_constraints:
    campaign=r"[A-Za-z0-9_\-]+",
    trial=r"[0-9]+",


# Jobs run the package's `stringcast` command from the environment Snakemake runs in
# (the project's venv), found by PATH, and read the config files Snakemake read: the
# Snakefile's configfile, then every --configfile over it (stringcast merges them the same
# way), named in $STRINGCAST_CONFIG. Neither is part of a rule's command line: a rule's
# params are the settings its stage reads, so Snakemake reruns a stage when, and only
# when, one of them changes. --config KEY=VALUE overrides would not reach the jobs, so
# they are refused.
if workflow.config_settings.config:
    raise WorkflowError(
        "stringcast: --config KEY=VALUE overrides do not reach the jobs, which read config "
        "files; put the overrides in a YAML file and pass it with --configfile"
    )
CONFIG_FILES = [
    *(
        ["config/config.yaml"]
        if Path("config/config.yaml").exists()
        and not workflow.config_settings.replace_workflow_config
        else []
    ),
    *map(str, workflow.config_settings.configfiles),
]
shell.prefix(
    f'set -euo pipefail; export PATH="{Path(sys.executable).parent}:$PATH"; '
    f'export STRINGCAST_CONFIG="{os.pathsep.join(map(os.path.abspath, CONFIG_FILES))}"; '
)
CLI = "stringcast"


try:
    SETTINGS = settings_from_config(config)
except ConfigError as exc:
    raise WorkflowError(f"stringcast: {exc}") from exc


def stage_settings(command):
    """The settings of the config sections that `stringcast <command>`'s stage reads (its
    entry point's settings parameters, stringcast.cli.stage_sections), as plain data: a
    rule's params, so that a changed setting reruns exactly the stages that read it."""
    return {s: getattr(SETTINGS, s).as_dict() for s in stage_sections(command)}


def campaign_lab_entries(wildcards):
    """The config's entries this campaign resolves to (its arm, set-up, camera, string and
    target; inline entries as written; stringcast.core.campaign_entries): a rule's params, so
    that editing one of them reruns that campaign's stages and no other campaign's."""
    return _lab_entries(wildcards.campaign)


@functools.cache
def _lab_entries(campaign):
    """campaign_lab_entries, read once per campaign (every rule of every trial asks)."""
    path = Path("data", campaign, "campaign.yaml")
    try:
        e = campaign_entries(load_yaml(path) or {}, config, path)
    except (ConfigError, KeyError) as exc:
        raise WorkflowError(f"stringcast: {path}: {exc}") from exc
    return {k: (v[1] if isinstance(v, tuple) else v) for k, v in e.items()}


VIDEO_NAMES = ("video.mkv", "video.avi", "video.mp4", "video.cihx", "video")


def campaigns():
    """Campaign names: folders data/<campaign>/ holding a campaign.yaml."""
    return sorted(p.parent.name for p in Path("data").glob("*/campaign.yaml"))


def trials(campaign):
    """Trial indices present under data/<campaign>/ (those with a joints.csv), each
    joints.csv's header checked against the campaign's arm (check_joint_logs)."""
    ks = []
    for p in Path("data", campaign).glob("trial_*/joints.csv"):
        suffix = p.parent.name.split("_", 1)[1]
        if suffix.isdigit():
            ks.append(int(suffix))
    check_joint_logs(campaign, sorted(ks))
    return sorted(ks)


_CHECKED_JOINT_LOGS = set()


def check_joint_logs(campaign, ks):
    """Refuse, before any job runs, a trial whose joints.csv lacks one of the campaign's
    arm's joint columns (or has more): each header's first line only, once per file."""
    todo = [
        Path("data", campaign, f"trial_{k}", "joints.csv")
        for k in ks
        if (campaign, k) not in _CHECKED_JOINT_LOGS
    ]
    if not todo:
        return
    try:
        arm = load_campaign(Path("data", campaign, "campaign.yaml"), config).arm
        for path in todo:
            check_joint_header(path, arm.n_joints, arm.name)
    except (ConfigError, DataError) as exc:
        raise WorkflowError(f"stringcast: {exc}") from exc
    _CHECKED_JOINT_LOGS.update((campaign, k) for k in ks)


def trial_video(wildcards):
    """The trial's video: a container file, a frame folder, or a Photron .cihx."""
    d = Path("data", wildcards.campaign, f"trial_{wildcards.trial}")
    for name in VIDEO_NAMES:
        if (d / name).exists():
            return str(d / name)
    return str(d / "video.mkv")


def calib_input(wildcards):
    """The campaign's board views and their intrinsics (rule calib_views), if it has calib/."""
    d = Path("data", wildcards.campaign, "calib")
    r = f"results/{wildcards.campaign}"
    return [f"{r}/calib_views.npz", f"{r}/intrinsics.json"] if d.is_dir() else []


def calib_arg(wildcards, input):
    if not input.calib:
        return ""
    return f'--calib-views "{input.calib[0]}" --intrinsics "{input.calib[1]}"'


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


def earlier_trials(wildcards):
    """The earlier trials fitted together with this one (estimation.joint_trials; 1: none)."""
    k = int(wildcards.trial)
    n = SETTINGS.estimation.joint_trials
    first = 1 if n == 0 else max(1, k - n + 1)
    return {
        "earlier_tracks": [
            f"results/{wildcards.campaign}/trial_{j}/tracks.parquet"
            for j in range(first, k)
        ],
        "earlier_joints": [
            f"data/{wildcards.campaign}/trial_{j}/joints.csv" for j in range(first, k)
        ],
    }


def earlier_arg(wildcards, input):
    if not input.earlier_tracks:
        return ""
    tracks = " ".join(f'"{p}"' for p in input.earlier_tracks)
    joints = " ".join(f'"{p}"' for p in input.earlier_joints)
    return f"--earlier-tracks {tracks} --earlier-joints {joints}"


def prev_arg(wildcards, input):
    return f'--prev "{input.prev[0]}"' if input.prev else ""


def trial_reports(wildcards):
    return [
        f"results/{wildcards.campaign}/trial_{k}/report.html"
        for k in trials(wildcards.campaign)
    ]


def all_targets():
    """Every stage's product of every trial, so a deleted one is made again and what
    depends on it reruns (Snakemake does not remake a missing file that no requested
    output needs)."""
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
        out.append(f"results/{c}/first_motion/motion.csv")
        ks = trials(c)
        out += [f"results/{c}/trial_{k}/{name}" for k in ks for name in stages]
        out += [f"results/{c}/trial_{k}/prediction.json" for k in ks if k > 1]
        if ks:
            out.append(f"results/{c}/report.html")
    return out
