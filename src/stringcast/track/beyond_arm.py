"""The string's stretch beyond the arm: where it passes behind a link and comes out again.

A swing often lays the string across the arm's own links (generalization seed 6: 43 of 80
lost frames). The walk from the grasp then stops at the arm's mask, and without a free end
nothing past the grasp side is trusted. The string's far side is still in view: a skeleton
stretch that begins at the arm's rim and ends free. Its points are known from the tip, as
in the tip-anchored case of :meth:`stringcast.track.frame_tracker.FrameTracker.track`: point
s_i lies L - s_i back along the stretch from the tip, whatever length hides behind the arm.

:func:`tip_stretch` finds that stretch; it gives none when there is no such stretch, or more
than one (a guess between two would be a wrong point, never a lost one).
"""
from __future__ import annotations

import cv2
import numpy as np

from stringcast.core import TrackingSettings
from .centreline import arc_length
from .ends import clean_end
from .arm_mask import near_arm
from .junctions import Zones, _degree, walk_skeleton



def tip_stretch(skel: np.ndarray, skel_at: np.ndarray, walked: np.ndarray, arm: np.ndarray, absd: np.ndarray,
                bg: np.ndarray, width_px: float, st: TrackingSettings, touch_px: float, min_px: float):
    """The one skeleton stretch that comes out from behind the arm and ends free.

    Candidates are skeleton components the grasp's walk never touched, at least ``min_px``
    long, with an end within ``width_px + 4`` px of the arm (where the string comes out: the
    reach of :func:`~stringcast.track.ends.end_cut`) and another end that is free
    (:func:`~stringcast.track.ends.clean_end`, not by the arm). Each candidate is walked from its
    free end (:func:`~stringcast.track.junctions.walk_skeleton`), and kept if the walk ends by the
    arm.

    Args:
        skel: (h, w) bool skeleton of the foreground's box, whose pixel (0, 0) is ``skel_at``
            (row, col) in the ROI. walked: (M, 2) (row, col) ROI px of the grasp's walk.
            arm: (H, W) bool guarded arm mask of the ROI. absd, bg: (H, W) contrast and background
            of the ROI. width_px: the string's width, px. st: tracking settings
            (``max_gap_px``, ``branch_min_px``). touch_px: ``end_touch_mm`` in px. min_px: the
            least length of a stretch, px (a point spacing: a shorter one holds no point).

    Returns:
        None, or (pts (M, 2) float (row, col) ROI px from the arm's rim to the tip, bridged (M,)
        bool, ambiguous (M,) bool): the walk's ambiguities (its crossings that were guesses).
    """
    ncomp, comp = cv2.connectedComponents(skel.astype(np.uint8), connectivity=8)
    w = np.round(walked).astype(int) - skel_at
    inside = (w[:, 0] >= 0) & (w[:, 0] < skel.shape[0]) & (w[:, 1] >= 0) & (w[:, 1] < skel.shape[1])
    taken = set(np.unique(comp[w[inside, 0], w[inside, 1]]).tolist()) | {0}
    sizes = np.bincount(comp.ravel(), minlength=ncomp)
    reach = width_px + 4
    ends = np.argwhere(skel & (_degree(skel) == 1))  # end pixels: one 8-neighbour
    found = []
    zones = None
    for c in range(1, ncomp):
        if c in taken or sizes[c] < min_px:
            continue
        own = ends[comp[ends[:, 0], ends[:, 1]] == c]
        at_arm = np.array([near_arm(e + skel_at, arm, reach) for e in own], bool)
        if not at_arm.any() or at_arm.all():
            continue
        for e in own[~at_arm]:
            zones = Zones(skel, width_px, int(st.branch_min_px)) if zones is None else zones
            pts, bridged, amb, _, _ = walk_skeleton(skel, tuple(e), st.max_gap_px, None, zones=zones)
            if len(pts) < 2 or arc_length(pts)[-1] < min_px or not near_arm(pts[-1] + skel_at, arm, reach):
                continue
            pts, bridged, amb = pts[::-1] + skel_at, np.r_[False, bridged[:0:-1]], amb[::-1]
            if clean_end(pts, skel, skel_at, absd, bg, st, touch_px):
                found.append((pts, bridged, amb))
    return found[0] if len(found) == 1 else None
