"""The check of a whole campaign folder, and of one trial: which folders are trials, and each file's
checks in turn (:mod:`.campaign_file`, :mod:`.calib_files`, :mod:`.video_files`, :mod:`.joint_files`).
"""
from __future__ import annotations

from pathlib import Path
from collections.abc import Mapping

from stringcast.core import ArmSpec, Campaign, SyncSettings, settings_from_config
from .calib_files import calib_findings
from .campaign_file import check_campaign_yaml
from .joint_files import joints_findings, motion_findings
from .problem import Problem, guarded, guarded_with, problem
from .video_files import video_findings


def _has_trial_files(d: Path) -> bool:
    return ((d / "joints.csv").is_file() or (d / "joints.partial.csv").is_file()
            or any(p.name != "video.yaml" for p in d.glob("video*")))


def trial_dirs(campaign_dir: str | Path) -> tuple[list[Problem], list[Path]]:
    """The campaign's trials: folders ``trial_<k>`` holding a ``joints.csv`` (or a stopped trial's
    ``joints.partial.csv``) or a video, in the order of k.

    Returns:
        (problems with the folders, the trial folders). Problems: a trial folder under a name the
        workflow does not read (``trial_01``, ``trial_1b``), trial numbers from 0 or with a gap
        (trial k starts from trial k - 1's estimate, eq. 3: the workflow cannot build it); a
        ``trial_*`` folder with neither joint log nor video is warned about.
    """
    d = Path(campaign_dir)
    out, trials = [], []
    for p in sorted(d.glob("trial_*")):
        if not p.is_dir():
            continue
        suffix = p.name[len("trial_"):]
        if not _has_trial_files(p):
            out.append(problem(p, "neither joints.csv nor a video: not a trial (yet)", severity="warn"))
        elif not (suffix.isdigit() and suffix == str(int(suffix))):
            out.append(problem(p, "a trial folder is named trial_<k>, k = 1, 2, ... with no leading zero: the workflow "
                                  "never reads this one's files"))
        else:
            trials.append((int(suffix), p))
    trials.sort()
    logged = {k for k, p in trials if (p / "joints.csv").is_file()}
    for k, p in trials:
        if k == 0:
            out.append(problem(p, "trials are numbered from 1 (trial_1 is the first motion's)"))
        elif k > 1 and k in logged and k - 1 not in logged:
            out.append(problem(p, f"no trial_{k - 1}/joints.csv before it: trial {k}'s estimate starts from trial "
                                  f"{k - 1}'s (eq. 3), so the workflow cannot build it; renumber the trials?"))
    return out, [p for _, p in trials]


def _sync(config: Mapping) -> SyncSettings:
    try:
        return settings_from_config(config).sync
    except Exception:  # noqa: BLE001 -- a config the stages refuse is theirs to name; the check uses defaults
        return SyncSettings()


def trial_findings(trial_dir: Path, arm: ArmSpec | None, sync: SyncSettings, video: bool = True) -> list[Problem]:
    """One trial's files against the campaign's ``arm`` (None: the checks that need none); its video and
    ``video.yaml`` too unless ``video`` is False."""
    out = []
    joints = trial_dir / "joints.csv"
    if not joints.is_file():
        partial = trial_dir / "joints.partial.csv"
        if partial.is_file():
            return [problem(partial, "a stopped trial: the workflow never processes it (play the motion again into "
                                     "this folder, or move the folder out)", severity="warn")]
        out.append(problem(joints, "file not found: the workflow picks up trials by their joints.csv, so it skips "
                                   "this one (copy the joint log in)", severity="warn"))
    meta = None
    if video:
        found, meta = guarded_with(trial_dir, video_findings, trial_dir)
        out += found
    if joints.is_file():
        out += guarded(joints, joints_findings, joints, arm, meta, sync)
    out += guarded(trial_dir, motion_findings, trial_dir, arm)
    return out


def check_trial(trial_dir: str | Path, campaign: Campaign | None, config: Mapping) -> list[Problem]:
    """Check one trial's raw files before any decode (what :func:`check_campaign` checks in each).

    Args:
        trial_dir: ``data/<campaign>/trial_<k>``.
        campaign: the resolved campaign (its arm: joint count, limits, controller rate), or None
            where ``campaign.yaml`` does not resolve: then the checks that need no arm.
        config: the merged config (its ``sync`` settings: the slack of the joint log's cover).

    Returns:
        Every problem found (:class:`~stringcast.check.Problem`). Raises nothing; reads only.
    """
    trial_dir = Path(trial_dir)
    if not trial_dir.is_dir():
        return [problem(trial_dir, "not a folder")]
    return guarded(trial_dir, trial_findings, trial_dir, None if campaign is None else campaign.arm, _sync(config))


def check_campaign(campaign_dir: str | Path, config: Mapping, video: bool = True) -> list[Problem]:
    """Check every raw file of a campaign before any decode, by the stages' own readers where they
    have one. Reads headers only (a video's header and first frame; joint logs, YAML and JSON whole;
    ``calib/``'s images whole): seconds for a campaign of ten trials with 1 GB videos. Writes nothing,
    raises nothing, imports neither the virtual lab nor a physics engine.

    What it checks (docs/data_contract.md, "Checking a campaign"):

    * ``campaign.yaml``: YAML, schema (unknown keys with their likely spelling), the config ids it
      names (string, target, arm, setup, the set-up's camera), inline entries against the config's
      schema, the string's points 30-34 mm apart (the n_points that would fit), weights and stiff
      sections on the string, the target beyond the grasp's reach + 50 mm (unless
      ``allow_reachable``), a ChArUco board that can exist (marker < square, a dictionary OpenCV
      knows with a marker for every other square).
    * ``calib/`` (optional): every image readable and of one size, or one video readable.
    * which folders are trials (``trial_<k>`` with a joint log or a video; names the workflow reads;
      numbered from 1 without gaps); in each trial:
    * one video (two: the one the workflow reads named), opened by its header; ``video.yaml``: YAML,
      schema, fps > 0 and finite, ``frames``, ``width_px``, ``height_px`` against the video, ``fps``
      against the video's own rate unless ``fps_note`` says why, ``bit_depth``;
    * ``joints.csv``: the arm's columns, numbers, no NaN, ``t_s`` increasing, its rate against the
      arm's controller rate (``t_s`` in ms named), values inside the arm's position limits
      ("degrees?" where they read as degrees), the log covering the video as ``trigger_time_s``,
      ``fps`` and ``frames`` place it (where a trigger time is given);
    * ``motion.csv`` (read, on the controller clock, within the arm's limits) and ``motion.json``
      (the keys the plan rule reads), both present.

    Args:
        campaign_dir: ``data/<campaign>`` (or its ``campaign.yaml``).
        config: the merged config (:func:`~stringcast.core.load_config`).
        video: also check what only the video stages read (each trial's video and ``video.yaml``,
            ``calib/``); False for a run whose rules read none of them (the workflow run with
            ``--allowed-rules`` that leave out decode ... track, as the loop benchmark's state mode).

    Returns:
        Every problem found, in the order campaign.yaml, calib/, the folders, each trial's
        (:class:`~stringcast.check.Problem`; ``severity`` "error" where a stage would fail or be
        misled, "warn" else).
    """
    d = Path(campaign_dir)
    if d.name == "campaign.yaml" and d.is_file():
        d = d.parent
    if not d.is_dir():
        return [problem(d, "not a folder: a campaign is data/<campaign>/ with campaign.yaml and trial_<k>/ folders")]
    out, campaign, arm = check_campaign_yaml(d / "campaign.yaml", config, d.name)
    if video:
        out += guarded(d / "calib", calib_findings, d / "calib")
    found, trials = guarded_with(d, trial_dirs, d, default=[])
    out += found
    sync = _sync(config)
    for t in trials:
        out += guarded(t, trial_findings, t, arm, sync, video)
    return out
