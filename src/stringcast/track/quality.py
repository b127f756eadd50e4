"""Tracking that says when it is poor: ``tracking.json``, beside ``tracks.parquet``.

Tracking has no ground truth to compare with, but a string has properties the tracker does
not impose, and their violation measures its error (:func:`tracking_quality`):

* **Valid share**: the share of the string's points 1..n tracked in the frames judged: every
  frame a later stage compares, from the motion's start to the joint log's end (the fit, eqs.
  4-6, and the next trial's prediction compare every frame the log covers; the planner's
  residual the tip up to the flight window after the arm stops). The points lost are the fast,
  blurred ones the fit is judged by, and the ones that leave the image after the motion (a
  point outside the image is never valid).
* **Length mismatch** D = L - the centreline's length from the grasp to a trusted free end
  (the tip), in the frames where the string is seen from the fingers to its end
  (:class:`~stringcast.track.frame_tracker.FrameTrack`). The tracker shares D among the head,
  the arc and the end, so it is not in the points' spacing; it is the error of the measured
  length itself: its median, a bias (the image scale, or L, or a tip lost against the wall),
  and its spread (p95 of |D - median|), with the tails on each side (``longer_p95``: how much
  longer than at its median the string is seen in the 5 % of frames where it is seen longest;
  ``shorter_p95`` likewise shorter). A median beyond ``verdict_length_share`` of L is judged
  as a string of another length than the campaign's (a 5000 mm string configured for a 300 mm
  one) and then no point is trusted; a smaller median is not (a drawn setup whose points were
  within 0.43 mm median / 0.85 mm p95 of the truth measured its string 21 mm short at the
  median frame: a clay weight half-way, string type 3). The spread and its tails are taken over
  the frames that placed points (``placed_frames``): a spread beyond ``verdict_length_spread_mm``
  is judged, as in those frames the tracker placed points by an end whose length disagrees with
  the rest of the cast, so they may lie off along the string by up to about the spread (an
  elastic cord placed from the grasp where its end is not seen; a whipping thread whose blurred
  tip is seen short, every point shifted back by the missing length).
* **Past the region of interest**: the share of the frames judged whose walk from the grasp
  runs to the edge of the region tracked (L + ``roi_margin_mm`` around the grasp) inside the
  image: string seen farther from the grasp than the campaign's string reaches.
* **Segment excess**: a chord between consecutive points cannot be longer than the arc
  between them: L / n, or in a frame where the tracker spread the points over a stretched
  string's seen length (:attr:`~stringcast.track.frame_tracker.FrameTrack.stretch`) that length / n;
  the p95 over the frames judged of max(0, chord - that arc), mm.
* **Rest jitter**: the string hangs still before the motion; the p95 over the points of each
  point's standard deviation over those frames, mm: the tracker's noise where the truth is
  constant.

The verdict (:class:`~stringcast.core.TrackingSettings`, ``verdict_*``) compares them with the
error the rest of the pipeline can bear (the tracking goals: median 1 mm, p95 3 mm), in mm of
the string and shares of its points, not with any camera: warn when the valid share is under
``verdict_min_valid_share``, the seen length or the region's edge says the string is not the
campaign's, or the segment excess or the rest jitter exceed their limits; each reason names the
likely cause (and the setting, where one is). ``fail`` is left to the fit (:mod:`stringcast.estimate`),
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


def tracking_quality(tracks: pd.DataFrame, mismatch_m: np.ndarray, L: float, n: int, judged: np.ndarray,
                     rest: np.ndarray, st: TrackingSettings, past_roi: np.ndarray | None = None,
                     off_image: np.ndarray | None = None, string_setting=None, scale_note: str | None = None,
                     stretch: np.ndarray | None = None, unplaced: np.ndarray | None = None,
                     stretch_frames: dict | None = None) -> dict:
    """The tracking's self-measures and verdict, for ``tracking.json``.

    Args:
        tracks: ``tracks.parquet``'s table (``frame, point, x_m, y_m, valid``; points 0..n).
        mismatch_m: (F,) per frame L minus the measured length to a trusted free end, m (NaN
            where none; :attr:`FrameTrack.length_mismatch_m`).
        L: the string's length, m. n: its mass points.
        judged: (F,) bool, the frames a later stage compares (:func:`frames_judged`).
        rest: (F,) bool, the still frames before the motion (rest jitter).
        st: :class:`~stringcast.core.TrackingSettings` (the ``verdict_*`` limits).
        past_roi, off_image: (F,) bool or None: the frame's walk from the grasp ran to the edge of
            the region tracked inside the image (:attr:`FrameTrack.past_roi`), or to the image's edge.
        string_setting: ``key -> str``, where the string's ``key`` is set
            (:meth:`~stringcast.core.specs.Campaign.string_setting`), for the reasons; None: the key.
        scale_note: where the calibration found the image scale off (the still arm seen at a scale,
            :func:`~stringcast.calibrate.scale_check.arm_scale`), what it said: a string seen at another
            length is then put down to the scale, not to the string.
        stretch: (F,) the factor each frame's points were spread by over a stretched string
            (:attr:`FrameTrack.stretch`; None: 1, none stretched): the segment excess is measured
            against stretch L / n.
        unplaced: (F,) str, why each frame placed no point (:attr:`FrameTrack.unplaced`; None: not known):
            the points lost in the frames judged are shared among those causes (``lost_points``).
        stretch_frames: ``tracking.json``'s ``stretch`` (the frames judged that measured the stretch, and
            those that did not see the end, spread by it or not: :mod:`stringcast.track.held_stretch`), kept
            and named in a seen-longer reason; None: not known.

    Returns:
        ``{"valid_share", "judged_frames", "length_mismatch_mm": {"frames", "median", "abs_p95",
        "placed_frames", "spread_p95", "longer_p95", "shorter_p95"}, "lost_points", "past_roi_share",
        "off_image_share", "segment_excess_p95_mm", "rest_jitter_p95_mm", "stretch", "verdict", "error_scale_mm"}``
        (a figure without data is None; :func:`lost_points`, :func:`error_scale_mm`).

    Raises:
        ValueError: the table does not hold (n + 1) points for every frame, or mismatched lengths.
    """
    F = len(judged)
    flags = [np.zeros(F, bool) if f is None else np.asarray(f, bool) for f in (past_roi, off_image)]
    stretch = np.ones(F) if stretch is None else np.asarray(stretch, float)
    if len(tracks) != F * (n + 1) or len(mismatch_m) != F or len(rest) != F or any(len(f) != F for f in flags) \
            or len(stretch) != F or (unplaced is not None and len(unplaced) != F):
        raise ValueError(f"tracking_quality: {len(tracks)} rows for {F} frames x {n + 1} points, "
                         f"{len(mismatch_m)} mismatches, {len(rest)} rest flags, {len(stretch)} stretches")
    t = tracks.sort_values(["frame", "point"])
    xy = t[["x_m", "y_m"]].to_numpy(float).reshape(F, n + 1, 2)
    ok = t["valid"].to_numpy(bool).reshape(F, n + 1)
    use = np.asarray(judged, bool)
    share = float(ok[use, 1:].mean()) if use.any() else None
    D_all = np.asarray(mismatch_m, float)[use] * 1000
    D = D_all[np.isfinite(D_all)]
    med = float(np.median(D)) if D.size else None
    dev = (D_all - med)[np.isfinite(D_all) & ok[use, 1:].any(axis=1)] if D.size else D   # frames that placed points
    chord = np.linalg.norm(np.diff(xy[use], axis=1), axis=2) * 1000
    both = ok[use, 1:] & ok[use, :-1]
    excess = np.maximum(chord - (L / n * 1000 * stretch[use])[:, None], 0.0)[both]   # a stretched string: its own
    still = np.asarray(rest, bool)
    jitter = None
    if still.sum() >= 5:
        xs, oks = xy[still, 1:], ok[still, 1:]
        seen = oks.sum(axis=0) >= 5                      # points seen in at least 5 still frames
        if seen.any():
            at_rest = np.where(oks[:, seen, None], xs[:, seen], np.nan)
            jitter = _p95(np.sqrt(np.nanvar(at_rest, axis=0).sum(axis=1)) * 1000)
    tails = (max(0.0, -float(np.percentile(dev, 5))), max(0.0, float(np.percentile(dev, 95)))) if dev.size \
        else (None, None)
    doc = {"valid_share": share, "judged_frames": int(use.sum()),
           "length_mismatch_mm": {"frames": int(D.size), "median": med,
                                  "abs_p95": _p95(np.abs(D)), "placed_frames": int(dev.size),
                                  "spread_p95": _p95(np.abs(dev)), "longer_p95": tails[0], "shorter_p95": tails[1]},
           "past_roi_share": float(flags[0][use].mean()) if use.any() else None,
           "off_image_share": float(flags[1][use].mean()) if use.any() else None,
           "segment_excess_p95_mm": _p95(excess) if excess.size else None, "rest_jitter_p95_mm": jitter,
           "lost_points": lost_points(ok[use, 1:], None if unplaced is None else np.asarray(unplaced, object)[use]),
           "stretch": stretch_frames}
    doc["verdict"] = tracking_verdict(doc, st, L, n, string_setting, scale_note).as_dict()
    doc["error_scale_mm"] = error_scale_mm(doc, st, L)
    return doc


UNPLACED = ("no_view", "no_string", "behind_arm", "no_anchor")
"""Why a frame placed no point (:attr:`~stringcast.track.frame_tracker.FrameTrack.unplaced`): the grasp maps to
no place in the image (or its region is cut to nothing); no walk from the grasp (the string not seen there);
the walk from the grasp ends by the arm and no free stretch comes out beyond it; a walk, but neither its start
at the grasp nor a free end anchors points on it (the start hidden by the fingers, an ambiguity before a free
end, or a length far from L)."""


def lost_points(ok: np.ndarray, unplaced: np.ndarray | None) -> dict[str, float] | None:
    """The share of the judged frames' points 1..n (``ok`` (F, n) bool: tracked) lost, by why: each of
    :data:`UNPLACED` (the frame placed no point: ``unplaced`` (F,) str) and ``placed`` (the frame placed
    points, and these fell past an ambiguity, the end seen or the image's edge). None without ``unplaced``
    or frames."""
    if unplaced is None or not ok.size:
        return None
    lost = (~ok).sum(axis=1) / ok.size
    return {why: float(lost[unplaced == key].sum()) for why, key in (*((u, u) for u in UNPLACED), ("placed", ""))}


LOST_CAUSES = {
    "no_view": "are in frames where the grasp maps to no place in the image (the calibration degenerates there)",
    "no_string": "are in frames where the string is not found from the grasp (lost against the background, in blur "
                 "or behind the arm); more light, a shorter exposure or a plainer wall helps",
    "behind_arm": "are in frames where the string runs on behind the arm from the grasp and no free stretch of it "
                  "comes out beyond (a point the arm hides is not tracked); a view in which the arm does not pass "
                  "in front of the string helps",
    "no_anchor": "are in frames where the string is seen but neither its start at the grasp nor a free end anchors "
                 "points on it (the start hidden by the fingers, a crossing, fold or gap before a free end, or a "
                 "length far from L)",
    "placed": "lie past a crossing, fold or gap of a string tracked from the grasp, or past the end seen (points are "
              "placed only up to the first ambiguity)",
}
"""What each of :func:`lost_points`' causes says in the tracking verdict."""


def _lost_why(doc: dict) -> str:
    """The tracking verdict's cause of a low valid share, from ``lost_points``: the cause that lost the most
    points, with its share of them; the causes together where ``lost_points`` is not known."""
    lost = doc.get("lost_points")
    if not lost or sum(lost.values()) <= 0:
        return ("the string is lost against the background, in blur or behind the arm; more light, a shorter "
                "exposure or a plainer wall helps")
    why = max(lost, key=lost.get)
    return f"{lost[why] / sum(lost.values()):.0%} of the points lost {LOST_CAUSES[why]}"


def error_scale_mm(doc: dict, st: TrackingSettings, L: float | None) -> float | None:
    """The size of the tracked points' errors that tracking's own figures show, mm, for a later stage to
    weigh its errors against (the fit's verdict: a tracking error at most a quarter of the fit's cannot be
    its cause): the largest of the seen length's p95 disagreement with L, the p95 excess of consecutive
    points' spacing over the string's, and the p95 jitter at rest. None where a figure that says the points
    may lie anywhere passes its limit (too few points tracked, the string running past the region tracked,
    a string of another length, a limit of ``st``) or no mm figure was measured: no scale is then stated."""
    share, D = doc["valid_share"], doc["length_mismatch_mm"]
    if share is None or share < st.verdict_min_valid_share or _past_roi(doc, st):
        return None
    if L is not None and _length_off(doc, st, L, 1):        # any frame seen at another length: no scale
        return None
    figures = [D["abs_p95"], doc["segment_excess_p95_mm"], doc["rest_jitter_p95_mm"]]
    figures = [f for f in figures if f is not None and np.isfinite(f)]
    return float(max(figures)) if figures else None


MIN_LENGTH_FRAMES = 5
"""Frames with a trusted free end the seen length's verdict needs."""


def _length_off(doc: dict, st: TrackingSettings, L: float, min_frames: int) -> bool:
    """The string is seen at another length than L (m), over at least ``min_frames`` frames."""
    D = doc["length_mismatch_mm"]
    return D["frames"] >= max(1, min_frames) and abs(D["median"]) > st.verdict_length_share * L * 1000


def _past_roi(doc: dict, st: TrackingSettings) -> bool:
    """The string runs past the region tracked in more of the frames judged than the limit allows."""
    roi = doc["past_roi_share"]
    return roi is not None and roi > st.verdict_past_roi_share


def _not_this_string(doc: dict, st: TrackingSettings, L: float, n: int, setting, scale_note=None) -> list[str]:
    """The reasons, if any, why the string filmed is not the campaign's: its length seen from the
    grasp to its free end, or the string running past the region tracked (put down to the image
    scale where the calibration found it off: ``scale_note``)."""
    out = []
    D = doc["length_mismatch_mm"]
    L_mm = L * 1000
    names = f"{setting('length_mm')} and {setting('n_points')}"
    if scale_note:
        check, verdict = scale_note, "the image scale is off"
    else:
        check = f"check {names} (or the image scale, if the calibration's verdict names it)"
        verdict = "the string filmed is not the one configured"
    if _length_off(doc, st, L, MIN_LENGTH_FRAMES):
        seen = L_mm - D["median"]
        out.append(f"tracking: the string is seen {seen:.0f} mm long from the grasp to its free end (median of "
                   f"{D['frames']} frames), but the campaign's string is {L_mm:.0f} mm with {n} points ({seen / L_mm:.2f} "
                   f"times; > tracking.verdict_length_share {st.verdict_length_share:g} off): {verdict}, and no point "
                   f"is trusted where the lengths disagree; {check}")
    roi = doc["past_roi_share"]
    if _past_roi(doc, st):
        out.append(f"tracking: in {roi:.0%} of the frames judged the string runs on past "
                   f"{L_mm + st.roi_margin_mm:.0f} mm from the grasp (the campaign's {L_mm:.0f} mm string + "
                   f"tracking.roi_margin_mm), out of the region tracked: "
                   f"{verdict if scale_note else 'the string filmed is longer than the one configured'}; {check}")
    return out


def _length_spread(doc: dict, st: TrackingSettings) -> str | None:
    """The reason, if any, to distrust points placed along the string: in the frames that placed points by a
    trusted free end (at least :data:`MIN_LENGTH_FRAMES`), the length seen from the grasp to it varies about
    its median by more than ``verdict_length_spread_mm`` (p95), named by the side its tail lies on (both,
    where the smaller tail is at least half the larger)."""
    D = doc["length_mismatch_mm"]
    spread, frames = D["spread_p95"], D["placed_frames"]
    if frames < MIN_LENGTH_FRAMES or spread <= st.verdict_length_spread_mm:
        return None
    longer, shorter = D["longer_p95"], D["shorter_p95"]
    why = []
    if longer >= 0.5 * shorter:
        held = doc.get("stretch") or {}
        where = (f"spread by the stretch seen within tracking.stretch_hold_ms in {held['held_frames']} frames, and "
                 f"short of their place by up to that in the {held['unheld_frames']} with none seen so near"
                 if held else "short of their place by up to that")
        why.append(f"seen up to {longer:.0f} mm longer than at its median length: a string that stretches in the "
                   "cast (an elastic cord; its points are spread evenly over the length seen, right where it "
                   f"stretches evenly, and placed from the grasp where its end is not seen: {where}), or a walk "
                   "that ran on past the tip (a shadow, a crossing)")
    if shorter >= 0.5 * longer:
        why.append(f"seen up to {shorter:.0f} mm shorter than at its median length, its points placed back from "
                   "the free end: right where the length missing hides by the grasp (a loop under the fingers or "
                   "the arm), shifted along the string by it where the end was lost instead (a fast tip blurred, "
                   "or the end behind the arm or out of the light)")
    return (f"tracking: the string's length from the grasp to its free end varies by {spread:.1f} mm about its "
            f"median (p95 over the {frames} frames that placed points by it, > tracking.verdict_length_spread_mm "
            f"{st.verdict_length_spread_mm:g}): {'; and '.join(why)}; points may lie up to that far off along "
            "the string there")


def tracking_verdict(doc: dict, st: TrackingSettings, L: float | None = None, n: int | None = None,
                     string_setting=None, scale_note: str | None = None) -> Verdict:
    """Warn, naming the likely cause (and the setting, where one is: ``string_setting(key)``, as
    :func:`tracking_quality`), where :func:`tracking_quality`'s figures pass their limits; ``L`` (m)
    and ``n``: the campaign's string (None: its length is not judged)."""
    setting = string_setting or (lambda key: f"the string's {key}")
    v = Verdict()
    share = doc["valid_share"]
    if share is None:
        return v.add("warn", "tracking: no frames to judge (no frame lies between the motion's start and the joint "
                             "log's end)")
    other = [] if L is None else _not_this_string(doc, st, L, n, setting, scale_note)
    for reason in other:
        v = v.add("warn", reason)
    if share < st.verdict_min_valid_share:
        off = doc.get("off_image_share") or 0.0
        why = ("the image scale is off (above)" if other and scale_note else
               "the string filmed is not the campaign's (above)" if other else
               f"the string runs out of the image in {off:.0%} of them (a point outside the image is never valid); "
               "frame the whole swing and the string after it" if off >= 0.2 else _lost_why(doc))
        v = v.add("warn", f"tracking: only {share:.0%} of the string's points were tracked in the "
                          f"{doc.get('judged_frames', 0)} frames judged (the motion's start to the joint log's end, "
                          f"which the fit compares; < {st.verdict_min_valid_share:.0%}): {why}")
    spread = _length_spread(doc, st)
    if spread and not other:
        v = v.add("warn", spread)
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


def frames_judged(t: np.ndarray, in_log: np.ndarray, t_start: float, t_last: float) -> tuple[np.ndarray, np.ndarray]:
    """(judged, rest) frame masks (F,) of frame times t (F,) s: judged, the frames a later stage compares,
    from the motion's start ``t_start`` to ``t_last`` (the joint log's last sample: the fit and the
    prediction compare every frame up to it, the planner's residual the tip up to the flight window
    after the motion) that the joint log covers (``in_log``, tracked); rest, the frames before the
    motion (by more than 20 ms), whose jitter is judged and whose points give the fit's rest state."""
    t = np.asarray(t, float)
    judged = (t >= t_start) & (t <= t_last) & np.asarray(in_log, bool)
    rest = t < t_start - 0.02
    return judged, rest


__all__ = ["frames_judged", "tracking_quality", "tracking_verdict"]
