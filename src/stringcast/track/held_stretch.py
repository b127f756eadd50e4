"""A stretching string's points where its end is not seen: spread by the stretch seen just before and
after (step 5 of :mod:`stringcast.track.tracking`).

A frame that sees the string from the grasp to a trusted free end with no ambiguity between measures
its stretch, the seen length over L (:attr:`~stringcast.track.frame_tracker.FrameTrack.seen_ratio`; also
where the length agrees with L within the anchor's tolerance: an elastic cord hanging at rest is 1-2 %
longer than L, within it). A frame that does not (the end behind the arm, past an ambiguity, blurred)
places its points from the grasp at s_i = i L / n (and those beyond the arm, where the string comes out
from behind a link, L - s_i back from its tip): on an elastic cord, short of their place by up to the
stretch (tens of mm at the tip in a cast). The stretch changes with the string's tension, on the time
scale of the swing, not from one frame to the next. Such a frame takes the stretch of the frames that
measured one within ``tracking.stretch_hold_ms`` of it (:func:`held_stretch`: each measure the median of
those within :data:`MEDIAN_HALF_S`, then interpolated between the one before and the one after, else the
nearest), and its points at s_i = i L / n times that stretch (uniform strain, as where the stretch is
seen), those beyond the arm that stretch times L - s_i back from the tip. Elsewhere it keeps
s_i = i L / n. On a string that does not stretch the measured stretch is 1 (within twice the scale's
uncertainty) and nothing changes.
"""
from __future__ import annotations

import numpy as np

from .centreline import resample_by_arc


MEDIAN_HALF_S = 0.05
"""The measures are first replaced by their median over the measuring frames within this many s of each, so
one frame that misjudged its end (a lump, the last millimetres of a stretched string hidden) is not carried
to every frame about it. 50 ms is a fifteenth of the family's shortest swing period (0.76 s,
``benchmarks.inertia``); a median over a window keeps a stretch that rises or falls steadily across it."""

MIN_SUPPORT = 3
"""A measure counts only with at least this many measuring frames (itself included) within
:data:`MEDIAN_HALF_S`: a lone frame that saw a free end near L may have seen a stretched string with its last
millimetres hidden (ours' MuJoCo elastic cord, trial 1: one such frame measured 0.995 where the cord was
1.012; held in the frames about it, it raised the trial's true p95 from 3.40 to 3.98 mm)."""

UNIT_SIGMAS = 2.0
"""A median measure within this many ``tracking.scale_sigma`` of 1 counts as 1: a stretch that small cannot
be told from the pixel scale's uncertainty along the string (an inextensible bead chain measures 1.002-1.003)."""


def _running_median(t: np.ndarray, m: np.ndarray, have: np.ndarray, half_s: float) -> np.ndarray:
    """``m`` (F,) with each measured entry (indices ``have``) replaced by the median of the measured entries
    within ``half_s`` s of it; NaN elsewhere as in ``m``."""
    out = m.copy()
    th = t[have]
    lo, hi = np.searchsorted(th, th - half_s, "left"), np.searchsorted(th, th + half_s, "right")
    out[have] = [np.median(m[have[a:b]]) if b - a >= MIN_SUPPORT else np.nan for a, b in zip(lo, hi)]
    return out


def held_stretch(t_s: np.ndarray, measured: np.ndarray, hold_s: float, scale_sigma: float = 0.0) -> np.ndarray:
    """Each frame's stretch from the frames that measured one.

    Parameters
    ----------
    t_s : ndarray, (F,)
        The frames' times, s, increasing.
    measured : ndarray, (F,)
        The stretch each frame measured (seen length over L), NaN where it measured none.
    hold_s : float
        How far in time a measured stretch is carried, s (0: not at all).
    scale_sigma : float
        The pixel scale's relative uncertainty along the string (``tracking.scale_sigma``): a median measure
        within :data:`UNIT_SIGMAS` of it from 1 is 1.

    Returns
    -------
    ndarray, (F,)
        The measured stretch (its median over the measuring frames within :data:`MEDIAN_HALF_S`, where
        :data:`MIN_SUPPORT` of them lie there, else none) where there is one; else the linear interpolation in time between the
        nearest measuring frames before and after where both lie within ``hold_s``; else the nearest
        measuring frame's where it lies within ``hold_s`` (the motion's first or last measured frames,
        or a gap of one side); else NaN.
    """
    t = np.asarray(t_s, float)
    m = np.asarray(measured, float)
    have = np.flatnonzero(np.isfinite(m))
    if not len(have) or hold_s <= 0:
        return m.copy()
    m = _running_median(t, m, have, MEDIAN_HALF_S)
    m[np.abs(m - 1.0) <= UNIT_SIGMAS * scale_sigma] = 1.0
    have = np.flatnonzero(np.isfinite(m))
    out = m.copy()
    if not len(have):
        return out
    todo = np.flatnonzero(~np.isfinite(m))
    nxt = np.searchsorted(have, todo)   # the first measuring frame after each frame to fill
    a, b = have[np.maximum(nxt - 1, 0)], have[np.minimum(nxt, len(have) - 1)]
    da = np.where(nxt > 0, t[todo] - t[a], np.inf)            # to the one before, s
    db = np.where(nxt < len(have), t[b] - t[todo], np.inf)    # to the one after, s
    w = np.divide(da, da + db, out=np.zeros(len(todo)), where=np.isfinite(da + db) & (da + db > 0))
    fill = np.where((da <= hold_s) & (db <= hold_s), (1 - w) * m[a] + w * m[b],
                    np.where(np.minimum(da, db) <= hold_s, np.where(da <= db, m[a], m[b]), np.nan))
    out[todo] = fill
    return out


def respread(grasp_arc: tuple | None, s_targets: np.ndarray, stretch: float,
             tip_arc: tuple | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A frame's points placed on a string stretched by ``stretch``: from the grasp, and beyond the arm from
    the tip.

    ``grasp_arc``: :attr:`~stringcast.track.frame_tracker.FrameTrack.grasp_arc`, the frame's polyline
    (K, 2) m from the grasp, its observed segments (K - 1,) and the arc length, m, past which no point is
    trusted (the first ambiguity), or None; point i lies ``stretch`` s_i along it. ``tip_arc``:
    :attr:`~stringcast.track.frame_tracker.FrameTrack.tip_arc`, the stretch beyond the arm (its polyline
    (K', 2) m from the arm's rim to the tip, observed segments, the arc length before which no point is
    trusted, the string's length from the rim to its tip and the tip's tolerance, m), or None; point i
    lies ``stretch`` (L - s_i) back from the tip, where a point from the grasp is not. ``s_targets`` (n,) m:
    i L / n. Returns positions (n, 2) m (NaN where invalid) and valid (n,), as
    :func:`~stringcast.track.centreline.resample_by_arc`.
    """
    s_targets = np.asarray(s_targets, float)
    pos, valid = np.full((len(s_targets), 2), np.nan), np.zeros(len(s_targets), bool)
    if grasp_arc is not None:
        xy, obs, hi = grasp_arc
        s_t = s_targets * stretch
        pos, valid = resample_by_arc(xy, obs, s_t)
        valid &= s_t <= hi
    if tip_arc is not None:
        far, obs, lo, reach, end_tol = tip_arc
        s_t = reach - stretch * (s_targets[-1] - s_targets)      # s_targets[-1] = L
        beyond, ok = resample_by_arc(far, obs, s_t, end_tol)
        ok &= (s_t >= lo) & ~valid
        pos, valid = np.where(ok[:, None], beyond, pos), valid | ok
    pos[~valid] = np.nan
    return pos, valid


def respread_frames(held: np.ndarray, arcs: dict, s_targets: np.ndarray) -> dict[int, tuple[np.ndarray, np.ndarray, float]]:
    """The points of the frames anchored at the grasp or, beyond the arm, at the tip, spread by the stretch
    held from the frames that measured one (the module doc).

    Parameters
    ----------
    held : ndarray, (F,)
        Each frame's stretch, NaN where not known (:func:`held_stretch` of the stretch the frames measured,
        :attr:`FrameTrack.seen_ratio` where :attr:`FrameTrack.stretch_seen`, over ``tracking.stretch_hold_ms``).
    arcs : dict
        {frame: (:attr:`FrameTrack.grasp_arc`, :attr:`FrameTrack.tip_arc`)} of the frames so anchored (either
        may be None).
    s_targets : ndarray, (n,)
        The points' arc lengths on the unstretched string, i L / n, m.

    Returns
    -------
    dict
        {frame: (positions (n, 2) m, NaN where invalid; valid (n,); the stretch)} for each frame of ``arcs``
        whose held stretch is known and not 1 (the others keep their points).
    """
    return {k: (*respread(grasp, s_targets, float(held[k]), tip), float(held[k]))
            for k, (grasp, tip) in arcs.items() if np.isfinite(held[k]) and held[k] != 1.0}
