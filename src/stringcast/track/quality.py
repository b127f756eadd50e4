"""Tracking that says when it is poor: ``tracking.json``, beside ``tracks.parquet``.

Tracking has no ground truth to compare with, but a string has properties the tracker does
not impose, and their violation measures its error (:func:`tracking_quality`):

* **Valid share**: the share of the string's points 1..n tracked in the moving frames (the
  motion's window). The points lost are the fast, blurred ones the fit is judged by.
* **Length mismatch** D = L - the centreline's length from the grasp to a trusted free end
  (the tip), in the frames where the string is seen from the fingers to its end
  (:class:`~stringcast.track.frame_tracker.FrameTrack`). The tracker shares D among the head,
  the arc and the end, so it is not in the points' spacing; it is the error of the measured
  length itself: its median, a bias (the image scale, or L, or a tip lost against the wall),
  and its spread (p95 of |D - median|). Both are reported, not judged: a drawn setup whose
  points were within 0.43 mm median / 0.85 mm p95 of the truth measured its string 21 mm
  short at the median frame (a clay weight half-way, string type 3), and the free end's
  extension varies by several mm on tracks whose points are within 3 mm.
* **Segment excess**: a chord between consecutive points cannot be longer than the arc
  between them (L / n) by more than the string stretches; the p95 over the moving frames of
  max(0, chord - L / n), mm.
* **Rest jitter**: the string hangs still before the motion; the p95 over the points of each
  point's standard deviation over those frames, mm: the tracker's noise where the truth is
  constant.

The verdict (:class:`~stringcast.core.TrackingSettings`, ``verdict_*``) compares them with the
error the rest of the pipeline can bear (the tracking goals: median 1 mm, p95 3 mm), in mm of
the string and shares of its points, not with any camera: warn when the valid share is under
``verdict_min_valid_share``, or the segment excess or the rest jitter exceed their limits;
each reason names the likely cause. ``fail`` is left to the fit (:mod:`stringcast.estimate`),
which sees whether the tracked path can be explained at all.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from stringcast.core import TrackingSettings, Verdict


def _p95(a: np.ndarray) -> float | None:
    a = np.asarray(a, float)
    a = a[np.isfinite(a)]
    return float(np.percentile(a, 95)) if a.size else None


def tracking_quality(tracks: pd.DataFrame, mismatch_m: np.ndarray, L: float, n: int, moving: np.ndarray,
                     rest: np.ndarray, st: TrackingSettings) -> dict:
    """The tracking's self-measures and verdict, for ``tracking.json``.

    Args:
        tracks: ``tracks.parquet``'s table (``frame, point, x_m, y_m, valid``; points 0..n).
        mismatch_m: (F,) per frame L minus the measured length to a trusted free end, m (NaN
            where none; :attr:`FrameTrack.length_mismatch_m`).
        L: the string's length, m. n: its mass points.
        moving: (F,) bool, the frames of the motion's window (judged).
        rest: (F,) bool, the still frames before the motion (rest jitter).
        st: :class:`~stringcast.core.TrackingSettings` (the ``verdict_*`` limits).

    Returns:
        ``{"valid_share", "moving_frames", "length_mismatch_mm": {"frames", "median",
        "spread_p95", "abs_p95"}, "segment_excess_p95_mm", "rest_jitter_p95_mm", "verdict"}``
        (a figure without data is None).

    Raises:
        ValueError: the table does not hold (n + 1) points for every frame, or mismatched lengths.
    """
    F = len(moving)
    if len(tracks) != F * (n + 1) or len(mismatch_m) != F or len(rest) != F:
        raise ValueError(f"tracking_quality: {len(tracks)} rows for {F} frames x {n + 1} points, "
                         f"{len(mismatch_m)} mismatches, {len(rest)} rest flags")
    t = tracks.sort_values(["frame", "point"])
    xy = t[["x_m", "y_m"]].to_numpy(float).reshape(F, n + 1, 2)
    ok = t["valid"].to_numpy(bool).reshape(F, n + 1)
    mov = np.asarray(moving, bool)
    share = float(ok[mov, 1:].mean()) if mov.any() else None
    D = np.asarray(mismatch_m, float)[mov] * 1000
    D = D[np.isfinite(D)]
    med = float(np.median(D)) if D.size else None
    chord = np.linalg.norm(np.diff(xy[mov], axis=1), axis=2) * 1000
    both = ok[mov, 1:] & ok[mov, :-1]
    excess = np.maximum(chord[both] - L / n * 1000, 0.0)
    still = np.asarray(rest, bool)
    jitter = None
    if still.sum() >= 5:
        xs, oks = xy[still, 1:], ok[still, 1:]
        seen = oks.sum(axis=0) >= 5                      # points seen in at least 5 still frames
        if seen.any():
            at_rest = np.where(oks[:, seen, None], xs[:, seen], np.nan)
            jitter = _p95(np.sqrt(np.nanvar(at_rest, axis=0).sum(axis=1)) * 1000)
    doc = {"valid_share": share, "moving_frames": int(mov.sum()),
           "length_mismatch_mm": {"frames": int(D.size), "median": med,
                                  "spread_p95": _p95(np.abs(D - med)) if D.size else None, "abs_p95": _p95(np.abs(D))},
           "segment_excess_p95_mm": _p95(excess) if excess.size else None, "rest_jitter_p95_mm": jitter}
    doc["verdict"] = tracking_verdict(doc, st).as_dict()
    return doc


def tracking_verdict(doc: dict, st: TrackingSettings) -> Verdict:
    """Warn, naming the likely cause, where :func:`tracking_quality`'s figures pass their limits."""
    v = Verdict()
    share = doc["valid_share"]
    if share is None:
        return v.add("warn", "tracking: no moving frames to judge (the motion's window holds no frames)")
    if share < st.verdict_min_valid_share:
        v = v.add("warn", f"tracking: only {share:.0%} of the string's points were tracked in the moving frames "
                          f"(< {st.verdict_min_valid_share:.0%}): the string is lost against the background, "
                          "in blur or behind the arm; more light, a shorter exposure or a plainer wall helps")
    ex = doc["segment_excess_p95_mm"]
    if ex is not None and ex > st.verdict_segment_excess_mm:
        v = v.add("warn", f"tracking: consecutive points lie up to {ex:.1f} mm (p95) farther apart than the string "
                          f"between them (> {st.verdict_segment_excess_mm:g} mm): points are misplaced along the string")
    jit = doc["rest_jitter_p95_mm"]
    if jit is not None and jit > st.verdict_rest_jitter_mm:
        v = v.add("warn", f"tracking: the hanging string's points jitter by {jit:.1f} mm (p95 of their standard "
                          f"deviations at rest, > {st.verdict_rest_jitter_mm:g} mm): noise, flicker or codec "
                          "artefacts reach the centreline")
    return v


def frames_judged(t: np.ndarray, in_log: np.ndarray, t_start: float, t_end: float, settle_s: float = 0.1
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(moving, rest) frame masks (F,): the motion's window plus ``settle_s``, and the frames
    before the motion (by more than 20 ms) that the joint log covers or takes as still."""
    t = np.asarray(t, float)
    moving = (t >= t_start) & (t <= t_end + settle_s) & np.asarray(in_log, bool)
    rest = t < t_start - 0.02
    return moving, rest


__all__ = ["frames_judged", "tracking_quality", "tracking_verdict"]
