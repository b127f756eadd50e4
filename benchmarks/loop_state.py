"""The loop benchmark's state mode (issue 27): the lab's true points, with the tracking's own measured
error and dropout, in place of filming, calibrating, syncing and tracking.

A state-mode campaign runs the lab with ``lab.render: false`` (physics and the camera's clock, no
video; :mod:`stringcast_lab.trial`). After each execution, and before the workflow processes it,
:func:`synthesize_trial` (this harness, never a workflow stage) writes what the skipped stages
would have written into ``results/<campaign>/trial_<k>/``:

* ``tracks.parquet`` (docs/data_contract.md): the lab's true points 1..n at the camera's frames
  (``ground_truth.parquet``), each moved by an error drawn independently per frame and point: a
  uniform direction and a log-normal length whose median and 95th percentile are the tracking's
  measured ones for that string type (``tracking.json``'s ``per_string``; its overall figures for
  a type it lacks); each point marked invalid (NaN) with probability 1 - valid_share, the
  tracking's measured share of valid points 1..n; frames outside the joint log invalid, as the
  tracker marks them. Every frame time is the true one plus one sync error per trial, drawn
  from the measured sync errors after the arm's sweep (``generalization.json``'s per setup, else
  ``sync.json``'s per case: :func:`error_model`). Point 0,
  the grasp, is the forward kinematics of the measured joints at those times, as tracking puts it.
* ``tracking.json``: the tracking's own self-measures and verdict
  (:func:`stringcast.track.quality.tracking_quality`) of those points, plus ``state_mode``.
* ``geometry.json`` and ``clock.json``: the clock's ``offset_s`` (frame 0's time as the tracks
  have it), ``fps``, ``frames``, an ``ok`` verdict whose note says that nothing was calibrated
  or synced, and ``state_mode``.

The workflow then runs with ``--allowed-rules`` :data:`STATE_RULES` (:data:`WORKFLOW_ARGS`):
Snakemake takes the files above as given (the rules that make them are not allowed, so it
neither reruns them nor asks for a video), and the *same* estimate, plan and predict rules run
on them, unchanged. No stage reads ``ground_truth.*``; only this harness does.

What is honest: the points the fit sees are the lab's physics at the camera's frame times, with
errors as large (median, p95), as often missing and as late or early as the measured tracking
and sync; the stages and settings are the workflow's own. What is not: the errors here are
independent across frames and points, while real tracking errors are correlated (a point lost
for a run of frames, a whole string offset by a calibration error, the tip lost in blur when it
is fastest); the drawn errors do not depend on the string's speed or on the camera; the
figures were measured on the MuJoCo lab's footage (the default camera) and are applied to every
physics. Each run's ``state_mode`` record and loop.json say so; the video mode's campaigns
(``video_check``) show how far the state mode's figures hold.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd

STATE_RULES = ("plan_first", "estimate", "plan", "predict")
"""The workflow rules a state-mode campaign runs; every other stage's output is synthesized."""
WORKFLOW_ARGS = ("--allowed-rules", *STATE_RULES)
"""Snakemake's arguments for a state-mode campaign (``run_campaign(workflow_args=...)``)."""
P95_Z = 1.6448536269514722
"""The standard normal's 95th percentile: log-normal p95 = median exp(P95_Z sigma)."""
NOTE = ("state mode (benchmarks/loop_state.py): no video was filmed; this trial was not calibrated, synced or "
        "tracked: its tracks.parquet is the virtual lab's true points with the tracking's measured error")


@dataclass(frozen=True)
class ErrorModel:
    """The tracking's and the sync's measured error, as the state mode draws it.

    Attributes:
        median_mm, p95_mm: the tracked points' distance to the truth, mm (median, 95th percentile).
        valid_share: the share of points 1..n the tracking marks valid.
        sync_errors_ms: the measured sync errors (estimated minus true offset), ms; one is drawn per trial.
        source: where the figures come from: files, their commits and dates, the keys read.
    """

    median_mm: float
    p95_mm: float
    valid_share: float
    sync_errors_ms: tuple[float, ...]
    source: dict

    def __post_init__(self):
        if not (0 < self.median_mm <= self.p95_mm and 0 < self.valid_share <= 1 and len(self.sync_errors_ms)):
            raise ValueError(f"ErrorModel: need 0 < median <= p95, valid share in (0, 1] and sync errors; got {self}")

    @property
    def sigma_log(self) -> float:
        """The log-normal's sigma: p95 = median exp(P95_Z sigma)."""
        return float(np.log(self.p95_mm / self.median_mm) / P95_Z)

    def as_dict(self) -> dict:
        """What a run's JSON records: the figures, the distribution drawn and its source."""
        return {**asdict(self), "sync_errors_ms": list(self.sync_errors_ms), "sigma_log": self.sigma_log,
                "point_error": "uniform direction, log-normal length (median, p95 as measured), independent per "
                               "frame and point",
                "dropout": "each point 1..n invalid with probability 1 - valid_share, independently per frame",
                "sync_error": "one of sync_errors_ms per trial (uniform draw), added to every frame time"}


def error_model(string_type: int, source_dir: Path) -> ErrorModel:
    """The measured error for ``string_type`` from ``source_dir``'s ``tracking.json`` (per-type median,
    p95, valid share; the overall ones for a type it lacks) and the measured sync errors after the
    arm's sweep: ``generalization.json``'s per setup (the setup family), or, where there is none,
    ``sync.json``'s per case (the default camera, the trigger withheld). ``source`` says which.

    Raises:
        DataError: a file missing (named, with how to make it) or lacking those keys.
    """
    from stringcast.core import DataError, read_json

    tp = Path(source_dir) / "tracking.json"
    if not tp.exists():
        raise DataError(f"{tp}: the state mode's error model needs it (python -m benchmarks.tracking, or "
                        "--state-source DIR)")
    gp = next((p for p in (Path(source_dir) / "generalization.json", Path(source_dir) / "sync.json") if p.exists()),
              None)
    if gp is None:
        raise DataError(f"{Path(source_dir) / 'generalization.json'} (or sync.json): the state mode's sync errors "
                        "need one (python -m benchmarks.generalization or benchmarks.sync, or --state-source DIR)")
    tr, gen = read_json(tp), read_json(gp)
    per = (tr.get("per_string") or {}).get(str(string_type))
    fig = per if per else tr
    try:
        if gp.name == "generalization.json":
            rows, key, what = gen["per_setup"], "sync_error_ms", "per_setup[].sync_error_ms"
        else:
            rows, key, what = list(gen["cases"].values()), "swept_offset_error_ms", "cases.*.swept_offset_error_ms"
        sync = tuple(float(r[key]) for r in rows if r.get(key) is not None)
        model = ErrorModel(float(fig["median_mm"]), float(fig["p95_mm"]), float(fig["valid_share"]), sync, {
            "tracking": {"file": str(tp), "git_commit": tr.get("git_commit"), "created": tr.get("created"),
                         "figures": f"per_string.{string_type}" if per else "overall"},
            "sync": {"file": str(gp), "git_commit": gen.get("git_commit"), "created": gen.get("created"),
                     "figures": what, "count": len(sync)}})
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise DataError(f"{tp} / {gp}: no usable median_mm, p95_mm, valid_share or {key}: {exc}") from exc
    return model


def draw_tracks(truth: pd.DataFrame, t_j: np.ndarray, q_j: np.ndarray, arm, n: int, model: ErrorModel,
                rng: np.random.Generator) -> tuple[pd.DataFrame, float]:
    """tracks.parquet's table from the lab's truth (module doc).

    Args:
        truth: ground_truth.parquet's ``frame, t_s, point, x_m, y_m`` (points 0..n, true times).
        t_j (K,) s, q_j (K, J) rad: the measured joint log (point 0 and the frames inside the log).
        arm: the campaign's arm. n: the string's points. model: the error drawn. rng: the draw.

    Returns:
        (``frame, t_s, point, x_m, y_m, valid``, (n + 1) rows per frame; the sync error drawn, s).

    Raises:
        DataError: a truth table without all points 0..n in every frame.
    """
    from stringcast.core import forward_kinematics, joints_at, tracks_arrays

    frames, t_true, xy, _ = tracks_arrays(truth.assign(valid=True), n, "ground_truth.parquet")
    f = len(frames)
    sync_s = float(rng.choice(model.sync_errors_ms)) / 1000
    t = t_true + sync_s
    r = model.median_mm / 1000 * np.exp(model.sigma_log * rng.standard_normal((f, n)))
    a = rng.uniform(0, 2 * np.pi, (f, n))
    xy[:, 1:] += np.stack([r * np.cos(a), r * np.sin(a)], axis=-1)
    in_log = (t >= t_j[0]) & (t <= t_j[-1])
    valid = np.zeros((f, n + 1), bool)
    valid[:, 1:] = (rng.random((f, n)) < model.valid_share) & in_log[:, None]
    valid[:, 0] = in_log
    xy[:, 0] = forward_kinematics(arm, joints_at(t, t_j, q_j))[:, -1]
    xy[~valid] = np.nan
    df = pd.DataFrame({"frame": np.repeat(frames, n + 1).astype(np.int64), "t_s": np.repeat(t, n + 1),
                       "point": np.tile(np.arange(n + 1), f).astype(np.int64), "x_m": xy[..., 0].ravel(),
                       "y_m": xy[..., 1].ravel(), "valid": valid.ravel()})
    return df, sync_s


def synthesize_trial(k: int, trial_dir: Path, results_dir: Path, campaign, model: ErrorModel, seed: int,
                     tracking) -> dict:
    """Write trial k's tracks.parquet, tracking.json, geometry.json and clock.json (module doc) from
    ``trial_dir``'s ground truth and joint log, drawn with ``seed`` and ``k``; a trial that already
    has them (a resumed campaign) is left as it is, so its results stay up to date.

    Args:
        tracking: :class:`~stringcast.core.TrackingSettings` (the verdict's limits, rest frames).

    Returns:
        This trial's record: trial, sync_error_ms drawn, the drawn points' median and p95 error (mm)
        and valid share against the truth; ``reused`` when the files were there.

    Raises:
        DataError: a missing or malformed ground truth or joint log (named).
    """
    from stringcast_lab.campaign import tracking_errors
    from stringcast.core import motion_window, read_joint_table, read_json, read_parquet, write_json, write_parquet
    from stringcast.track.quality import frames_judged, tracking_quality

    results_dir = Path(results_dir)
    record_path = results_dir.parents[2] / "state_mode" / f"trial_{k}.json"   # the run's root, beside results/
    if (results_dir / "tracks.parquet").exists() and record_path.exists():
        return read_json(record_path) | {"reused": True}
    truth = read_parquet(Path(trial_dir) / "ground_truth.parquet", ["frame", "t_s", "point", "x_m", "y_m"])
    t_j, q_j = read_joint_table(Path(trial_dir) / "joints.csv", n_joints=campaign.arm.n_joints,
                                 arm_name=campaign.arm.name)
    n = campaign.string.n_points
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(k), 27]))
    df, sync_s = draw_tracks(truth, t_j, q_j, campaign.arm, n, model, rng)
    t = df["t_s"].to_numpy()[::n + 1]
    in_log = (t >= t_j[0]) & (t <= t_j[-1])
    moving, rest = frames_judged(t, in_log, *motion_window(t_j, q_j))
    stamp = {"mode": "state", "note": NOTE, "error_model": model.as_dict()}
    quality = tracking_quality(df, np.full(len(t), np.nan), campaign.string.length, n, moving, rest, tracking)
    verdict = {"status": "ok", "reasons": [NOTE]}
    meta = read_json(Path(trial_dir) / "ground_truth.json")
    results_dir.mkdir(parents=True, exist_ok=True)
    write_json(results_dir / "geometry.json", {"state_mode": stamp, "verdict": verdict})
    write_json(results_dir / "clock.json", {"offset_s": float(t[0]), "fps": float(meta["fps"]), "frames": len(t),
                                            "state_mode": stamp, "verdict": verdict})
    write_json(results_dir / "tracking.json", quality | {"state_mode": stamp})
    write_parquet(results_dir / "tracks.parquet", df)   # last: its presence says the trial is done
    e, share = tracking_errors(df, truth)
    rec = {"trial": int(k), "sync_error_ms": sync_s * 1000, "error_median_mm": float(np.median(e)),
           "error_p95_mm": float(np.percentile(e, 95)), "valid_share": share,
           "tracking_verdict": quality["verdict"]["status"], "reused": False}
    write_json(record_path, rec)
    return rec
