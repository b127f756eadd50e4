"""A stretching string's points where its end is not seen: spread by the stretch seen just before and
after (step 5 of :mod:`stringcast.track.tracking`).

A frame that sees the string from the grasp to a trusted free end with no ambiguity between measures
its stretch, the seen length over L (:attr:`~stringcast.track.frame_tracker.FrameTrack.stretch`; 1 where
the length agrees with L). A frame that does not (the end behind the arm, past an ambiguity, blurred)
places its points from the grasp at s_i = i L / n: on an elastic cord under a cast, short of their place
by up to the stretch (tens of mm at the tip). The stretch changes with the string's tension, on the
time scale of the swing, not from one frame to the next. Such a frame, anchored at the grasp, takes
the stretch of the frames that measured one within ``tracking.stretch_hold_ms`` of it (:func:`held_stretch`:
interpolated between the one before and the one after, else the nearest), and its points at
s_i = i L / n times that stretch (uniform strain, as where the stretch is seen). Elsewhere it keeps
s_i = i L / n. On a string that does not stretch the measured stretch is 1 and nothing changes.
"""
from __future__ import annotations

import numpy as np

from .centreline import resample_by_arc


def held_stretch(t_s: np.ndarray, measured: np.ndarray, hold_s: float) -> np.ndarray:
    """Each frame's stretch from the frames that measured one.

    Parameters
    ----------
    t_s : ndarray, (F,)
        The frames' times, s, increasing.
    measured : ndarray, (F,)
        The stretch each frame measured (seen length over L), NaN where it measured none.
    hold_s : float
        How far in time a measured stretch is carried, s (0: not at all).

    Returns
    -------
    ndarray, (F,)
        The measured stretch where there is one; else the linear interpolation in time between the
        nearest measuring frames before and after where both lie within ``hold_s``; else the nearest
        measuring frame's where it lies within ``hold_s`` (the motion's first or last measured frames,
        or a gap of one side); else NaN.
    """
    t = np.asarray(t_s, float)
    m = np.asarray(measured, float)
    have = np.flatnonzero(np.isfinite(m))
    out = m.copy()
    if not len(have) or hold_s <= 0:
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


def respread(grasp_arc: tuple, s_targets: np.ndarray, stretch: float) -> tuple[np.ndarray, np.ndarray]:
    """A frame's points placed from the grasp on a string stretched by ``stretch``.

    ``grasp_arc``: :attr:`~stringcast.track.frame_tracker.FrameTrack.grasp_arc`, the frame's polyline
    (K, 2) m from the grasp, its observed segments (K - 1,) and the arc length, m, past which no point is
    trusted (the first ambiguity); ``s_targets`` (n,) m: i L / n. Returns positions (n, 2) m (NaN where
    invalid) and valid (n,), as :func:`~stringcast.track.centreline.resample_by_arc`.
    """
    xy, obs, hi = grasp_arc
    s_t = np.asarray(s_targets, float) * stretch
    pos, valid = resample_by_arc(xy, obs, s_t)
    valid &= s_t <= hi
    pos[~valid] = np.nan
    return pos, valid


def respread_frames(held: np.ndarray, arcs: dict, s_targets: np.ndarray) -> dict[int, tuple[np.ndarray, np.ndarray, float]]:
    """The points of the frames anchored at the grasp, spread by the stretch held from the frames that
    measured one (the module doc).

    Parameters
    ----------
    held : ndarray, (F,)
        Each frame's stretch, NaN where not known (:func:`held_stretch` of the stretch the frames measured,
        :attr:`FrameTrack.stretch` where :attr:`FrameTrack.stretch_seen`, over ``tracking.stretch_hold_ms``).
    arcs : dict
        {frame: :attr:`FrameTrack.grasp_arc`} of the frames anchored at the grasp.
    s_targets : ndarray, (n,)
        The points' arc lengths on the unstretched string, i L / n, m.

    Returns
    -------
    dict
        {frame: (positions (n, 2) m, NaN where invalid; valid (n,); the stretch)} for each frame of ``arcs``
        whose held stretch is known and not 1 (the others keep their points).
    """
    return {k: (*respread(arc, s_targets, float(held[k])), float(held[k]))
            for k, arc in arcs.items() if np.isfinite(held[k]) and held[k] != 1.0}
