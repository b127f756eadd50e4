"""Residual correction of the plan (ours, not the paper's): the model's error on the played
motion, carried over to the next motion.

After an execution two tip paths of the played motion m_k are known: the tracked one,
r(t), and the model's prediction of it, s_k(t), with the new estimate, computed exactly
as the planner predicts a candidate (the commanded motion, from the hanging equilibrium).
The next motion m' is a perturbation of m_k (Section V.B), so to first order the model
is wrong about m' as it was about m_k, which is the idea of iterative learning control:

    r'(t) ~ s'(t) + delta(t),   delta(t) = r(t) - s_k(t).

The tip hits when s'(t) comes within the radius of target - delta(t): the planner aims
the model at that moving target (:func:`stringcast.model.string_model.closest_approach_batch`).
Measured on the lab (type 3, trials 1-3 of one campaign): the model alone predicted the
next motion would pass 0.4-12 mm from the target, the lab's tip passed 28-117 mm from it;
the corrected prediction said 16-97 mm.

Time: motion time t = 0 is the first sample of the commanded motion. The joint log's
clock maps onto it by the delay that best aligns the measured joints with the commanded
motion, pre-roll and servo lag together (:func:`motion_delay`); tracks.parquet's t_s is on
the joint log's clock (sync). Where the tip was not tracked, delta is interpolated between
valid frames and held beyond them; with fewer than ``min_valid_share`` of the frames in
[0, T + flight window] valid there is no correction (:func:`tip_residual` says why).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stringcast.core import DataError, tracks_arrays

ALIGN_RMS_MAX_RAD = 0.05
"""A joint log further than this (rms, rad) from the commanded motion at the best delay
is not a recording of that motion."""


@dataclass(frozen=True)
class TipResidual:
    """delta(t) = tracked tip - model tip of the played motion, per parameter set.

    Attributes:
        dt: s, sample spacing of ``delta`` from motion time 0.
        delta: (P, S, 2) m, one row per parameter set (the planner's set first, then
            its ensemble, in the order the caller gave the model paths).
        delay_s: s, the joint-log time at which motion time 0 was played (:func:`motion_delay`).
        valid_share: share of the frames in [0, horizon] with a tracked tip.
    """

    dt: float
    delta: np.ndarray
    delay_s: float
    valid_share: float

    def __post_init__(self):
        if np.ndim(self.delta) != 3 or np.shape(self.delta)[2] != 2 or np.shape(self.delta)[1] < 1:
            raise ValueError(f"TipResidual.delta: expected (P, S, 2), got {np.shape(self.delta)}")
        if not (self.dt > 0 and np.all(np.isfinite(self.delta))):
            raise ValueError("TipResidual: dt must be > 0 and delta finite")

    def targets(self, target_xy: np.ndarray) -> np.ndarray:
        """The moving targets target - delta(t): (P, S, 2) m, sampled every ``dt`` from t = 0."""
        return np.ascontiguousarray(np.asarray(target_xy, float)[None, None] - self.delta)

    def summary(self) -> dict:
        """What motion.json records: delay, valid share, |delta| (median and max over t, set 0, mm)."""
        size = np.hypot(self.delta[0, :, 0], self.delta[0, :, 1]) * 1000
        return {"delay_s": self.delay_s, "valid_share": self.valid_share, "sets": int(len(self.delta)),
                "median_mm": float(np.median(size)), "max_mm": float(size.max())}


def motion_delay(t_log: np.ndarray, q_log: np.ndarray, q_cmd: np.ndarray, rate: float,
                 source: str = "joints.csv") -> float:
    """Joint-log time at which the commanded motion's t = 0 was played (pre-roll plus servo lag).

    Least squares: the delay d minimising mean |q_log(t) - q_cmd(t - d)|^2 over the log,
    with q_cmd held at its first and last sample outside [0, T]; on a grid of one
    controller period, then refined by a parabola through the best three.

    Args:
        t_log: (K,) s; q_log: (K, J) rad, the measured joints. q_cmd: (M, J) rad, the
            motion file from t = 0 at ``rate`` Hz.

    Raises:
        DataError: (naming ``source``) when even the best delay leaves an rms residual
            above :data:`ALIGN_RMS_MAX_RAD`: the log is not a recording of this motion.
    """
    t_log, q_log, q_cmd = (np.asarray(a, float) for a in (t_log, q_log, q_cmd))
    if q_log.ndim != 2 or q_cmd.ndim != 2 or q_log.shape[1] != q_cmd.shape[1] or len(t_log) != len(q_log):
        raise DataError(f"{source}: joint log {q_log.shape} and motion {q_cmd.shape} do not match")
    t_cmd = np.arange(len(q_cmd)) / rate
    grid = np.arange(t_log[0] - t_cmd[-1], t_log[-1], 1.0 / rate)

    def cost(d: float) -> float:
        sim = np.column_stack([np.interp(t_log - d, t_cmd, q_cmd[:, j]) for j in range(q_cmd.shape[1])])
        return float(np.mean((sim - q_log) ** 2))

    costs = np.array([cost(d) for d in grid])
    i = int(np.clip(np.argmin(costs), 1, len(grid) - 2))
    c0, c1, c2 = costs[i - 1:i + 2]
    curv = c0 - 2 * c1 + c2
    shift = 0.5 * (c0 - c2) / curv if curv > 0 else 0.0
    delay = float(grid[i] + np.clip(shift, -1.0, 1.0) / rate)
    rms = np.sqrt(cost(delay) * q_cmd.shape[1])
    if not rms <= ALIGN_RMS_MAX_RAD:
        raise DataError(f"{source}: the measured joints are {rms:.3f} rad (rms) from the played motion at the best "
                        f"delay ({delay:.3f} s): not a recording of this motion.csv")
    return delay


def tip_residual(frame_t: np.ndarray, tip: np.ndarray, valid: np.ndarray, model_tip: np.ndarray,
                 horizon: float, delay_s: float, dt: float = 0.002,
                 min_valid_share: float = 0.5) -> tuple[TipResidual | None, str]:
    """delta(t) = tracked tip - model tip on a grid of ``dt`` over [0, horizon] (motion time).

    Args:
        frame_t: (F,) s, motion time of each frame (t_s - delay). tip: (F, 2) m tracked tip,
            valid: (F,) bool. model_tip: (P, F, 2) m, the model's tip at frame_t, one row
            per parameter set (NaN where a set's simulation blew up: such a set, but set 0,
            takes set 0's residual; frames where set 0 is NaN are not used).
        horizon: s, T + flight window. delay_s: recorded in the result.
        min_valid_share: fewer valid frames than this share of those in [0, horizon]: no
            correction.

    Returns:
        (TipResidual, "") or (None, why not).
    """
    frame_t, tip, valid, model_tip = (np.asarray(a) for a in (frame_t, tip, valid, model_tip))
    if model_tip.ndim != 3 or model_tip.shape[1:] != tip.shape or tip.shape != (len(frame_t), 2):
        raise ValueError(f"tip_residual: shapes frame_t (F,), tip (F, 2), model_tip (P, F, 2) expected; got "
                         f"{frame_t.shape}, {tip.shape}, {model_tip.shape}")
    window = (frame_t >= 0) & (frame_t <= horizon)
    ok = window & valid.astype(bool) & np.all(np.isfinite(tip), axis=1) & np.all(np.isfinite(model_tip[0]), axis=1)
    share = float(ok.sum() / max(1, window.sum()))
    if share < min_valid_share or ok.sum() < 2:
        return None, (f"no residual correction: the tip was tracked in {share:.0%} of the {int(window.sum())} frames "
                      f"of the played motion (need {min_valid_share:.0%})")
    grid = np.arange(0.0, horizon + 0.5 * dt, dt)
    d = tip[None, ok] - model_tip[:, ok]
    d[~np.all(np.isfinite(d), axis=(1, 2))] = d[0]      # a set that blew up on the played motion: set 0's residual
    delta = np.stack([np.column_stack([np.interp(grid, frame_t[ok], d[p, :, 0]),
                                       np.interp(grid, frame_t[ok], d[p, :, 1])]) for p in range(len(d))])
    return TipResidual(dt=float(dt), delta=delta, delay_s=float(delay_s), valid_share=share), ""


def observed_tip(tracks_df, t_log: np.ndarray, q_log: np.ndarray, q_cmd: np.ndarray, n: int, rate: float,
                 source: str = "tracks.parquet") -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The played motion's tracked tip on motion time.

    Args:
        tracks_df: tracks.parquet's long table, or its columns (:func:`~stringcast.core.read_parquet_columns`);
            t_s on the joint log's clock.
        t_log (K,) s, q_log (K, J) rad: the measured joints; q_cmd (M, J) rad: the played motion file.
        n: the string's points (the tip is point n).

    Returns:
        frame_t (F,) s (motion time), tip (F, 2) m, valid (F,) bool, delay s (:func:`motion_delay`).

    Raises:
        DataError: bad tracks (named) or a joint log that is not this motion.
    """

    delay = motion_delay(t_log, q_log, q_cmd, rate)
    _, t, xy, valid = tracks_arrays(tracks_df, n, source)
    return t - delay, xy[:, n], valid[:, n], delay


def observed_miss(frame_t: np.ndarray, tip: np.ndarray, valid: np.ndarray, target_xy: np.ndarray,
                  horizon: float) -> float:
    """The tracked tip's closest approach to the target over [0, horizon] of motion time, m
    (NaN when the tip was never tracked there). Args as :func:`tip_residual`'s; target_xy (2,) m."""
    sel = (np.asarray(frame_t) >= 0) & (np.asarray(frame_t) <= horizon) & np.asarray(valid, bool)
    sel &= np.all(np.isfinite(tip), axis=1)
    if not sel.any():
        return float("nan")
    return float(np.min(np.hypot(tip[sel, 0] - target_xy[0], tip[sel, 1] - target_xy[1])))
