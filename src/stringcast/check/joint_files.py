"""A trial's joint files: ``joints.csv`` (the measured log) and ``motion.csv`` + ``motion.json`` (the
motion as played), read by the stages' own readers and checked against the campaign's arm.

``joints.csv``: :func:`~stringcast.core.read_joint_table` (columns, cells, NaN, increasing ``t_s``),
then its rate against the arm's ``controller_rate_hz``, every value inside the arm's position limits
("degrees?" where the values read as degrees would fit them), and the log's cover of the video as far
as ``video.yaml``'s trigger time tells it (:func:`~stringcast.core.check_joint_coverage`, with the
sync's search window as slack). ``motion.csv``: the reader, the executor's timing check
(:func:`~stringcast.core.check_motion_timing`) and limits (:func:`~stringcast.core.assert_within_limits`).
``motion.json``: :func:`~stringcast.core.read_motion_sidecar`, what the plan rule reads.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from stringcast.core import (ArmSpec, DataError, JointLimitError, SyncSettings, assert_within_limits,
                             check_joint_coverage, check_motion_timing, read_joint_table, read_json,
                             read_motion_sidecar)
from .problem import Problem, from_error, problem

LIMIT_SLACK_DEG = 0.5
"""A measured joint may read this far past its position limit before the check calls it beyond:
far above an encoder's noise (a UR's: about 0.01 deg), far below a wrong unit or offset."""
RATE_TOLERANCE = 0.1
"""A joint log's rate (1 / its median period) may differ from the arm's ``controller_rate_hz``
by this share before the check warns."""
GAP_PERIODS = 10.0
"""A step of ``t_s`` longer than this many median periods is a gap in the log (warned)."""


def _read(path: Path, arm: ArmSpec | None, kind: str) -> tuple[list[Problem], np.ndarray | None, np.ndarray | None]:
    try:
        t, q = read_joint_table(path, kind, n_joints=None if arm is None else arm.n_joints,
                                arm_name=None if arm is None else arm.name)
    except DataError as exc:
        return [from_error(exc, path, hint=_separator_hint(path))], None, None
    return [], t, q


def _separator_hint(path: Path) -> str:
    """"separated by ';'?" where a CSV file's first line holds no comma but another separator."""
    try:
        with open(path, encoding="utf-8-sig", errors="replace") as f:
            head = f.readline()
    except OSError:
        return ""
    sep = next((name for c, name in ((";", "';'"), ("\t", "tabs"), (" ", "spaces")) if c in head.strip()), None)
    return f"separated by {sep}? the data contract's CSV files use ','" if sep and "," not in head and "t_s" in head \
        else ""


def rate_findings(path: Path, t: np.ndarray, arm: ArmSpec) -> list[Problem]:
    """The log's rate against the arm's controller rate (``t_s`` in ms or us named), and gaps."""
    dt = np.diff(t)
    period = float(np.median(dt))
    rate, want = 1.0 / period, arm.controller_rate
    out = []
    unit = next((u for u, r in (("milliseconds", 1e-3), ("microseconds", 1e-6)) if abs(rate / want / r - 1) < 0.1),
                None)
    if unit:
        out.append(problem(path, f"one row per {period:g} s ({rate:.3g} Hz), the arm {arm.name}'s controller runs at "
                                 f"{want:g} Hz: t_s in {unit}? the data contract asks seconds", "t_s"))
    elif abs(rate / want - 1) > RATE_TOLERANCE:
        out.append(problem(path, f"one row per {period * 1000:.4g} ms ({rate:.4g} Hz), the arm {arm.name}'s "
                                 f"controller_rate_hz is {want:g}: another arm's log, or one decimated? (one row per "
                                 "controller cycle)", "t_s", severity="warn"))
    gaps = np.flatnonzero(dt > GAP_PERIODS * period)
    if gaps.size and not unit:
        i = int(gaps[0])
        out.append(problem(path, f"{gaps.size} gap(s) in the log, the first {dt[i]:.4g} s long after row {i + 2} "
                                 f"(the median step is {period:.4g} s): samples lost?", "t_s", f"{t[i]:.6g}",
                           "warn"))
    return out


def looks_like_degrees(q: np.ndarray, arm: ArmSpec) -> bool:
    """Joint values (K, J) that exceed 2 pi where the arm's limits lie within +-2 pi, and fit the limits
    once read as degrees."""
    slack = math.radians(LIMIT_SLACK_DEG)
    lo, hi = arm.q_min, arm.q_max
    turn = 2 * math.pi
    if not (np.max(np.abs(q)) > turn and np.all(np.abs(lo) <= turn) and np.all(np.abs(hi) <= turn)):
        return False
    qr = np.radians(q)
    return bool(np.all((qr >= lo - slack) & (qr <= hi + slack)))


def limit_findings(path: Path, q: np.ndarray, arm: ArmSpec) -> list[Problem]:
    """Every joint's values inside the arm's position limits (:data:`LIMIT_SLACK_DEG` of slack): one
    problem per joint beyond them, or one for the file where the values look like degrees."""
    slack = math.radians(LIMIT_SLACK_DEG)
    lo, hi = arm.q_min, arm.q_max
    beyond = (q < lo - slack) | (q > hi + slack)
    if not beyond.any():
        return []
    cols = f"q1_rad..q{arm.n_joints}_rad"
    if looks_like_degrees(q, arm):
        big = float(q.flat[np.argmax(np.abs(q))])
        return [problem(path, f"values up to {big:.4g} exceed 2 pi and the limits of arm {arm.name}; read as "
                              "degrees they all fit them: degrees? the data contract asks radians", cols, f"{big:.6g}")]
    out = []
    for j in np.flatnonzero(beyond.any(axis=0)):
        rows = np.flatnonzero(beyond[:, j])
        excess = np.maximum(lo[j] - q[rows, j], q[rows, j] - hi[j])
        worst = float(q[rows[np.argmax(excess)], j])
        out.append(problem(path, f"{rows.size} rows beyond arm {arm.name}'s limits {math.degrees(lo[j]):g}.."
                                 f"{math.degrees(hi[j]):g} deg ({lo[j]:.4f}..{hi[j]:.4f} rad), the first at row "
                                 f"{rows[0] + 2}: another arm's log, another joint order, or another zero?",
                           f"q{j + 1}_rad", f"{worst:.6g}"))
    return out


def coverage_findings(path: Path, t: np.ndarray, q: np.ndarray, arm: ArmSpec, meta: dict,
                      sync: SyncSettings) -> list[Problem]:
    """The log against the video's span on the controller clock as ``video.yaml`` puts it
    (``trigger_time_s`` + frame / ``fps``): :func:`~stringcast.core.check_joint_coverage`, with
    one log period and, where sync searches around the trigger (``sync.method: video``),
    ``sync.search_ms`` of slack. Without a trigger time there is nothing to tell before sync."""
    trigger = meta.get("trigger_time_s")
    if trigger is None:
        return []
    span = np.array([float(trigger), float(trigger) + (int(meta["frames"]) - 1) / float(meta["fps"])])
    slack = float(np.median(np.diff(t))) + (sync.search_ms / 1000 if sync.method == "video" else 0.0)
    try:
        check_joint_coverage(t, span, path, tol_s=slack, q_joints=q, qd_max=arm.qd_max,
                             still_share=sync.still_speed_share, still_window_s=sync.still_window_s)
    except DataError as exc:
        return [from_error(exc, path, "t_s", hint="(from video.yaml's trigger_time_s, fps and frames) a log cut "
                                                  "short, or a trigger time on another clock?")]
    return []


def joints_findings(path: Path, arm: ArmSpec | None, meta: dict | None, sync: SyncSettings) -> list[Problem]:
    """``joints.csv`` (see the module docstring). ``meta``: ``video.yaml``'s mapping, or None where it
    has an error (the cover of the video is then not checked); ``arm`` None: the read alone."""
    out, t, q = _read(path, arm, "joints.csv")
    if t is None or arm is None:
        return out
    rate = rate_findings(path, t, arm)
    out += rate + limit_findings(path, q, arm)
    # a log in other units than the contract's would only add a misleading coverage problem
    if meta is not None and not looks_like_degrees(q, arm) and not any(p.is_error for p in rate):
        out += coverage_findings(path, t, q, arm, meta, sync)
    return out


def motion_findings(trial_dir: Path, arm: ArmSpec | None) -> list[Problem]:
    """``motion.csv`` and ``motion.json``: both there, each readable, the motion within the arm's
    limits and on its controller clock (see the module docstring)."""
    csv, sidecar = trial_dir / "motion.csv", trial_dir / "motion.json"
    out = []
    if not csv.is_file():
        out.append(problem(csv, "file not found: the motion as played (the executor copies it into the trial with "
                                "its motion.json)"))
    else:
        found, t, q = _read(csv, arm, "motion.csv")
        out += found
        if t is not None and arm is not None:
            try:
                check_motion_timing(t, arm.controller_rate, csv)
            except DataError as exc:
                out.append(from_error(exc, csv, "t_s"))
            limits = limit_findings(csv, q, arm)
            out += limits
            if not limits:
                try:
                    assert_within_limits(arm, q, 1.0 / arm.controller_rate, source=str(csv))
                except JointLimitError as exc:
                    out.append(from_error(exc, csv))
    if not sidecar.is_file():
        out.append(problem(sidecar, "file not found: the plan rule rebuilds the played motion from it (the "
                                    "executor copies it beside motion.csv; copy in the motion.json planned with it)"))
        return out
    try:
        doc = read_json(sidecar)
        if arm is not None:
            read_motion_sidecar(sidecar, arm.n_joints)
    except DataError as exc:
        return out + [from_error(exc, sidecar)]
    if arm is not None and isinstance(doc, dict):
        rate = doc.get("controller_rate_hz")
        if isinstance(rate, (int, float)) and abs(float(rate) - arm.controller_rate) > 1e-6 * arm.controller_rate:
            out.append(problem(sidecar, f"planned at {rate:g} Hz, the arm {arm.name}'s controller_rate_hz is "
                                        f"{arm.controller_rate:g}", "controller_rate_hz", rate, "warn"))
    return out
