"""The executor: play a motion file on an arm and record the trial's raw files.

It touches hardware and is run by a person (or the campaign loop on the virtual
lab), never by Snakemake. Before anything moves it checks the motion file: t
starts at 0 and steps by the controller period, and the trajectory stays within
the arm's position, speed, acceleration and floor limits
(:func:`stringcast.core.arm.assert_within_limits`). The command sent is: hold q0 for
``executor.pre_roll_s`` (filmed at rest: the estimation's initial state), the
motion, then hold the end posture for ``executor.post_roll_s`` (covers the
flight window).

Backends:

* ``virtual``: :func:`stringcast_lab.run_trial` (MuJoCo or PyElastica string, simulated arm
  and camera) writes video.mkv, video.yaml, joints.csv and the ground truth. The virtual lab
  is an extra (``pip install 'stringcast[lab]'``), imported only when this backend plays.
* ``ur-rtde``: a Universal Robots arm through ``ur_rtde`` servoJ
  (:func:`stringcast.execute.ur_rtde.play_ur`): checks the arm's current posture
  against the start, writes joints.csv and executor.json (a stopped trial:
  joints.partial.csv, ``partial: true``). The video comes from the lab's camera.
"""
from __future__ import annotations

import shutil
from pathlib import Path
from collections.abc import Mapping

import numpy as np

from stringcast.core import (Campaign, ConfigError, DataError, ExecutorSettings, assert_within_limits, atomic_path,
                             check_motion_timing, load_campaign, read_joint_table)
from .ur_rtde import UR_JOINTS, URSettings, play_ur

BACKENDS = ("virtual", "ur-rtde")


def lab_module(name: str = "stringcast_lab", needed_by: str = "this command"):
    """The virtual lab's module ``name``, imported on demand: the pipeline, the ``ur-rtde`` backend and
    every command but the lab's own run without the lab's simulators. ``needed_by`` names who needs it
    in the error.

    Raises:
        ConfigError: the virtual lab (the ``lab`` extra: MuJoCo, PyElastica, PyAV) is not installed.
    """
    import importlib

    try:
        return importlib.import_module(name)
    except ImportError as e:
        raise ConfigError(f"{needed_by} needs the virtual lab, which is not installed ({e}): "
                          "pip install 'stringcast[lab]'") from e


def virtual_lab_trial():
    """The ``virtual`` backend's player, :func:`stringcast_lab.run_trial` (:func:`lab_module`).

    Raises:
        ConfigError: the virtual lab is not installed.
    """
    return lab_module(needed_by="executor: the virtual backend").run_trial


def _copy(src: Path, dst: Path) -> None:
    with atomic_path(dst) as tmp:
        shutil.copyfile(src, tmp)


def build_command(q: np.ndarray, rate: float, pre_roll_s: float, post_roll_s: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The command stream: q0 held for the pre-roll, the motion, the end held for the post-roll.

    Args:
        q: (K, J) rad, the motion at the controller rate.

    Returns:
        t_cmd (K',) s from 0, q_cmd (K', J) rad, and the time the motion starts (s).
    """
    pre = int(round(pre_roll_s * rate))
    post = int(round(post_roll_s * rate))
    q_cmd = np.concatenate([np.repeat(q[:1], pre, axis=0), q, np.repeat(q[-1:], post, axis=0)])
    return np.arange(len(q_cmd)) / rate, q_cmd, pre / rate


def execute(motion_csv: Path, backend: str, out_dir: Path, campaign_yaml: Path | Campaign,
            executor: ExecutorSettings, config: Mapping, seed: int = 0, dry_run: bool = False,
            robot_ip: str | None = None, move_to_start: bool = False, interfaces=None) -> dict:
    """Check a motion file, play it on ``backend`` and record the trial into ``out_dir``.

    Parameters
    ----------
    motion_csv : Path
        ``t_s, q1_rad..qJ_rad`` (s, rad) from t = 0 at the controller rate
        (its ``motion.json``, which must be beside it, is copied along).
    backend : str
        ``"virtual"`` or ``"ur-rtde"``.
    out_dir : Path
        The trial folder to create (``data/<campaign>/trial_<k>``).
    campaign_yaml : Path or Campaign
        ``campaign.yaml`` (or an already resolved :class:`Campaign`).
    executor : ExecutorSettings
        Pre- and post-roll (s), the UR backend's settings (:class:`~stringcast.core.ExecutorSettings`).
    config : mapping
        The merged config: its lab tables resolve ``campaign.yaml``, and the virtual
        lab reads its world (``lab``) from it.
    seed : int
        The virtual lab's seed (:func:`stringcast_lab.run_trial`; ``virtual`` only).
    dry_run : bool
        Check and describe the command, move nothing, write nothing.
    robot_ip : str, optional
        ``ur-rtde`` only: the arm's address (see :func:`stringcast.execute.ur_rtde.play_ur`).
    move_to_start : bool
        ``ur-rtde`` only (see :func:`stringcast.execute.ur_rtde.play_ur`).
    interfaces : optional
        ``ur-rtde`` only: replaces ur_rtde in tests (see :func:`stringcast.execute.ur_rtde.play_ur`).

    Returns
    -------
    dict
        backend, motion, samples, duration_s (s), motion_start_s (s), dry_run, plus what the backend returned.

    Raises
    ------
    JointLimitError
        The motion breaks a limit (before anything moves); for ``ur-rtde``
        also :class:`~stringcast.execute.ur_rtde.StartPostureError` (arm not at the start).
    DataError
        Unreadable motion file, bad timing, no ``motion.json`` beside it, or ``out_dir``
        already holds a joints.csv.
    ConfigError
        Unknown backend; ``ur-rtde`` without robot_ip, without ur_rtde, or bad ``executor.ur``.
    """
    motion_csv, out_dir = Path(motion_csv), Path(out_dir)
    if backend not in BACKENDS:
        raise ConfigError(f"executor: unknown backend {backend!r} (known: {', '.join(BACKENDS)})")
    campaign = campaign_yaml if isinstance(campaign_yaml, Campaign) else load_campaign(campaign_yaml, config)
    arm = campaign.arm
    t, q = read_joint_table(motion_csv, "motion.csv", n_joints=arm.n_joints, arm_name=arm.name)
    check_motion_timing(t, arm.controller_rate, motion_csv)
    assert_within_limits(arm, q, 1.0 / arm.controller_rate, source=str(motion_csv))
    if (out_dir / "joints.csv").exists():
        raise DataError(f"{out_dir}: already holds a joints.csv; refusing to overwrite a recorded trial")
    sidecar = motion_csv.with_suffix(".json")
    if not sidecar.is_file():
        raise DataError(f"{sidecar}: missing: the motion's description (written beside motion.csv by the planner) "
                        "goes into the trial with it, and planning the next motion reads it; play a motion.csv "
                        "the workflow planned, with its motion.json")
    t_cmd, q_cmd, t_move = build_command(q, arm.controller_rate, executor.pre_roll_s, executor.post_roll_s)
    where = ""
    if backend == "ur-rtde":
        ur = URSettings.from_settings(executor, arm)  # bad settings fail before anything connects
        m = ur.mapping
        if not robot_ip and not dry_run:
            raise ConfigError("executor: the ur-rtde backend needs the arm's address (--robot-ip)")
        q0 = m.to_ur(q[0], np.zeros(6))
        where = f" at {robot_ip or '(no --robot-ip)'}, start " + ", ".join(
            f"{UR_JOINTS[i]} {np.degrees(q0[i]):.1f} deg" for i in m.joint_map) + " (others held)"
    info = {"backend": backend, "motion": str(motion_csv), "samples": len(t_cmd), "duration_s": float(t_cmd[-1]),
            "motion_start_s": t_move, "dry_run": bool(dry_run)}
    if dry_run:
        print(f"executor (dry run): {motion_csv} is within the limits of arm {arm.name}; would play "
              f"{len(t_cmd)} samples ({t_cmd[-1]:.3f} s, motion from {t_move:.3f} s) on {backend}{where} into {out_dir}")
        return info
    if backend == "ur-rtde":
        result = play_ur(t_cmd, q_cmd, arm, ur, out_dir, robot_ip, move_to_start, interfaces)
    else:
        run_trial = virtual_lab_trial()
        out_dir.mkdir(parents=True, exist_ok=True)
        result = run_trial(t_cmd, q_cmd, campaign, config, out_dir, seed, t_move)
    _copy(motion_csv, out_dir / "motion.csv")
    _copy(sidecar, out_dir / "motion.json")
    info.update(result or {})
    return info
