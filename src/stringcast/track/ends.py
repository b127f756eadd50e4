"""The string's free end: where it lies, whether the walk's end is the string's end, what ends it.

A skeleton stops short of a free end, forks inside a clay ball, and stops wherever the string
fades under the segmentation's threshold or goes behind something. These tests and measures
take the walk's end (its centreline, :mod:`stringcast.track.centreline`) and the frame's contrast
``absdiff``; :meth:`stringcast.track.frame_tracker.FrameTracker.track` uses them to decide
whether the end is the tip (step 4 of :mod:`stringcast.track.tracking`). Units: pixels of the
region of interest, (row, col).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import cv2
import numpy as np
from scipy.ndimage import distance_transform_edt, map_coordinates

from stringcast.core import TrackingSettings
from .arm_mask import near_arm
from .centreline import arc_length


def _fwhm_across(absdiff: np.ndarray, p: np.ndarray, t: np.ndarray) -> float:
    """Full width (px) at half contrast of ``absdiff`` across the direction t (2,) at point p (2,)."""
    return float(_fwhm_across_many(absdiff, np.reshape(p, (1, 2)), np.reshape(t, (1, 2)))[0])


def _fwhm_across_many(absdiff: np.ndarray, P: np.ndarray, T: np.ndarray) -> np.ndarray:
    """:func:`_fwhm_across` at points P (N, 2) across directions T (N, 2): (N,) px, in one sampling call
    (the same arithmetic per point; a ball's end profile takes some 60 of them per frame)."""
    off = np.arange(-6.0, 6.0 + 1e-9, 0.25)
    T = np.asarray(T, float)
    T = T / np.maximum(np.hypot(T[:, 0], T[:, 1]), 1e-9)[:, None]
    Q = np.asarray(P, float)[:, None, :] + off[None, :, None] * np.stack([-T[:, 1], T[:, 0]], axis=1)[:, None, :]
    v = map_coordinates(absdiff, [Q[..., 0].ravel(), Q[..., 1].ravel()], order=1, mode="nearest").reshape(Q.shape[:2])
    lo, hi = v.min(axis=1, keepdims=True), v.max(axis=1, keepdims=True)
    return 0.25 * np.count_nonzero(v > lo + 0.5 * (hi - lo), axis=1).astype(float)


def _at_pixels(image: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """``image`` (H, W) at the pixels of path points pts (M, 2) (row, col), rounded down (round them
    first for the nearest pixel) and clipped into the image: (M,). A refined centreline may lie up
    to its refinement's half width past the edge of the region it was found in (a string that goes
    on past the ROI); those vertices read the edge's pixels, never an index out of bounds."""
    ij = np.clip(np.asarray(pts).astype(int), 0, np.array(image.shape[:2]) - 1)
    return image[ij[:, 0], ij[:, 1]]


def _end_tangent(pts: np.ndarray, cum: np.ndarray, n_tangent: float):
    """Unit tangent (2,) of a path (M, 2) at its end, over its last ``n_tangent`` px of arc
    ``cum`` (M,); None where those vertices coincide."""
    a = int(np.searchsorted(cum, cum[-1] - n_tangent))
    t = pts[-1] - pts[min(a, len(pts) - 2)]
    nt = float(np.hypot(*t))
    return None if nt < 1e-6 else t / nt


def string_continues(absdiff: np.ndarray, pts: np.ndarray, edge: float | None, t: np.ndarray | None,
                     width_px: float, share: float, reach: float = 8.0) -> bool:
    """Whether string-like contrast goes on past a walk's end: the end is then where the string
    fades below the segmentation's threshold (a faint stretch, the light behind it changing),
    not its free end.

    Past the end's far half-contrast edge (``edge``, ``t``: :func:`end_edge`, or
    :func:`locate_end`'s; ``reach`` px where the contrast does not fall within it) by one string
    width, and for two widths + 4 px more, ``absdiff`` is sampled along 9 directions within
    +-40 deg of the end tangent ``t``, but not within a width of the walk itself; the string
    goes on when the best direction's mean reaches ``share`` (``end_contrast_min``) of the
    contrast along the path.

    Args:
        absdiff: (H, W) smoothed contrast. pts: (M, 2) (row, col) centreline, the end last.
        edge: px past the last vertex, or None. t: (2,) unit end tangent, or None (then False).
        width_px: the string's width in the foreground. share: of the path's median contrast.
    """
    if t is None:
        return False
    edge = reach if edge is None else edge   # past a lump (a clay ball), not from inside it
    phi = np.arctan2(t[1], t[0]) + np.radians(np.linspace(-40.0, 40.0, 9))
    d = edge + width_px + np.arange(0.0, 2 * width_px + 4 + 1e-9, 0.5)
    ray = pts[-1] + d[None, :, None] * np.stack([np.cos(phi), np.sin(phi)], axis=-1)[:, None, :]  # (9, K, 2)
    v = map_coordinates(absdiff, [ray[..., 0].ravel(), ray[..., 1].ravel()], order=1, mode="constant",
                        cval=0.0).reshape(ray.shape[:2])   # nothing is seen outside the image
    own = pts[np.hypot(*(pts - pts[-1]).T) <= d[-1] + width_px]   # the walk's vertices a sample can be near
    near = np.min(np.hypot(ray[..., None, 0] - own[:, 0], ray[..., None, 1] - own[:, 1]), axis=-1)
    v[near < width_px] = 0.0   # the string's own walked stretch (a tip curled back onto it) goes on nowhere
    along = float(np.median(_at_pixels(absdiff, np.round(pts))))
    return bool(along > 0 and float(np.max(v.mean(axis=1))) >= share * along)


def end_edge(absdiff: np.ndarray, pts: np.ndarray, n_tangent: int = 6, reach: float = 8.0):
    """Where the contrast past a walk's end falls to half: the end's far edge.

    Along the path's end tangent (over its last ``n_tangent`` px), the smoothed contrast
    ``absdiff`` is sampled every 0.25 px from 2 px before the last vertex to ``reach`` px past
    it; the edge is where it falls to half way between the contrast on the centreline just
    before the end and the ray's floor (linear interpolation between samples).

    Args:
        absdiff: (H, W) contrast image. pts: (M, 2) (row, col) centreline, the end last.

    Returns:
        ``(edge, t)``: the edge's distance past the last vertex, px (>= 0; ``None`` where the contrast
        does not fall within ``reach`` px or the path is too short or flat), and the unit end
        tangent (2,) (``None`` with it where there is none).
    """
    t = _end_tangent(pts, arc_length(pts), n_tangent) if len(pts) >= 8 else None
    if t is None:
        return None, None
    off = np.arange(-2.0, reach + 1e-9, 0.25)
    ray = pts[-1] + off[:, None] * t
    prof = map_coordinates(absdiff, [ray[:, 0], ray[:, 1]], order=1, mode="nearest")
    peak, floor = float(np.max(prof[off <= 0])), float(np.min(prof))
    if peak - floor <= 0:
        return None, t
    half = floor + 0.5 * (peak - floor)
    below = np.nonzero((off > 0) & (prof < half))[0]
    if len(below) == 0:
        return None, t
    i = int(below[0])
    a, b = float(prof[i - 1]), float(prof[i])
    frac = (a - half) / (a - b) if a > half else 0.0   # already below half at the last vertex: the edge is there
    return max(0.0, float(off[i - 1] + frac * (off[i] - off[i - 1]))), t


class FreeEnd(NamedTuple):
    """Where a free end lies (:func:`locate_end`).

    ``edge``: px from the last vertex to the far half-contrast edge along ``tangent`` (the unit
    end tangent, (2,)), None where the contrast does not fall within reach (``tangent`` None too
    where the path is too short); ``extension``: px from the last vertex to the end along the
    tangent (>= 0); ``ball``: ``(centre (2,) (row, col), radius px)`` of a clay ball that ends
    the path (its centre is then the end), or None.
    """

    edge: float | None
    tangent: np.ndarray | None
    extension: float
    ball: tuple[np.ndarray, float] | None


def locate_end(absdiff: np.ndarray, pts: np.ndarray, n_tangent: int = 6, reach: float = 8.0) -> FreeEnd:
    """Where the string's free end lies, past (or, inside a ball, behind) the walk's last vertex.

    A skeleton stops short of a free end (by about the foreground's half-width, more under
    blur). The end is the half-contrast edge along the end tangent (:func:`end_edge`). Where
    the string is wider at its end than along its length, a lump ends it (:func:`end_lump`): a
    sleeve longer than wide (a pipe) ends at its far edge; a ball (clay) at its centre, half its
    width back, and where it is at least 1.5 times as wide as the string the centre is found from
    its contrast (:func:`_ball_centre`), not from the spur of its skeleton the walk ends on.

    Args:
        absdiff: (H, W) contrast image. pts: (M, 2) (row, col) centreline, the free end last.
    """
    edge, t = end_edge(absdiff, pts, n_tangent, reach)
    if edge is None:
        return FreeEnd(None, t, 0.0, None)
    kind, w_lump = end_lump(absdiff, pts, edge, t)
    if kind != "ball":
        return FreeEnd(edge, t, max(0.0, float(edge)), None)
    return FreeEnd(edge, t, max(0.0, float(edge) - w_lump / 2), _ball_centre(absdiff, pts, edge, t, w_lump))


def end_lump(absdiff: np.ndarray, pts: np.ndarray, edge: float, t: np.ndarray):
    """What ends the string: ``("plain" | "sleeve" | "ball", lump width px)``.

    Widths across the path (full widths at half contrast) every 0.5 px back from its last
    vertex, 3-sample running median. The lump's width is the widest within 2 string widths +
    4 px of the end; it is a lump if 0.5 px wider than the string at a third and two thirds
    of its length. It ends where its width falls half way back to the string's; a ball's length
    from there to the far edge (``edge`` px past the last vertex along the unit tangent ``t``,
    :func:`end_edge`) is under 1.5 of its widths (a blurred disc: ~0.95), a sleeve's is more.
    """
    cum = arc_length(pts)
    mids = [int(np.searchsorted(cum, f * cum[-1])) for f in (1 / 3, 2 / 3)]
    w_mid = min(_fwhm_across(absdiff, pts[j], pts[min(j + 2, len(pts) - 1)] - pts[max(j - 2, 0)]) for j in mids)
    back = np.arange(0.0, min(float(cum[-1]) - 1.0, 6.0 * w_mid + 8.0), 0.5)
    if len(back) < 4:
        return "plain", w_mid
    at = cum[-1] - back
    P = np.column_stack([np.interp(at, cum, pts[:, 0]), np.interp(at, cum, pts[:, 1])])
    T = np.column_stack([np.interp(at + 1, cum, pts[:, 0]) - np.interp(at - 1, cum, pts[:, 0]),
                         np.interp(at + 1, cum, pts[:, 1]) - np.interp(at - 1, cum, pts[:, 1])])
    w = _fwhm_across_many(absdiff, P, T)
    w = np.median(np.stack([w, np.r_[w[:1], w[:-1]], np.r_[w[1:], w[-1:]]]), axis=0)
    w_lump = float(np.max(w[back <= 2.0 * w_mid + 4.0]))
    if w_lump - w_mid <= 0.5:
        return "plain", w_mid
    narrow = np.nonzero(w < w_mid + 0.5 * (w_lump - w_mid))[0]
    length = float(edge) + (float(back[narrow[0]]) if len(narrow) else float(back[-1]))
    return ("sleeve" if length > 1.5 * w_lump else "ball"), w_lump


BALL_UPSAMPLE = 4
"""A ball's window is upsampled this many times before its rim is thresholded: on the pixel grid the
deepest point moved in steps of ~0.5 px as noise flipped rim pixels (generalization seed 21, a 6 px
ball at 2.6 mm per px: the tip at rest jittered by 1.3 mm)."""


def _ball_centre(absdiff: np.ndarray, pts: np.ndarray, edge: float, t: np.ndarray, w_lump: float):
    """The centre (2,) (row, col) and radius (px) of the ball of width ``w_lump`` that ends the
    path (far ``edge`` px past its last vertex along ``t``), or None.

    A skeleton forks inside a ball, and the walk ends on one spur or the other, frame by frame
    (generalization seeds 0 and 7: the tip jittered by ~1 mm across and along the string). A
    ball is a lump at least 1.5 times as wide as the string at the path's middle (clay balls in
    the lab: 2-2.6 times; a light band of tape at the tip: 1.2 times). The centre is found from
    the contrast, not the walk: near half the ball's width back from its far edge, the deepest
    point of the foreground at half the contrast there (the maximum of its distance transform,
    ``scipy.ndimage.distance_transform_edt``; the centroid of the top 1 px of it), on the window
    upsampled :data:`BALL_UPSAMPLE` times (bilinear, ``cv2.resize``). None also where that centre
    is farther than the radius from the walk's end (the walk does not end inside it).
    """
    j = len(pts) // 2
    if w_lump < 1.5 * _fwhm_across(absdiff, pts[j], pts[min(j + 2, len(pts) - 1)] - pts[max(j - 2, 0)]):
        return None   # a lump barely wider than the string (a band of tape at the tip) has no centre of its own
    r = w_lump / 2
    c0 = pts[-1] + (float(edge) - r) * t
    h = int(math.ceil(2 * r)) + 2   # the ball's window: its foreground at half the contrast there
    r0, c0_ = int(round(c0[0])) - h, int(round(c0[1])) - h
    if r0 < 0 or c0_ < 0 or r0 + 2 * h + 1 > absdiff.shape[0] or c0_ + 2 * h + 1 > absdiff.shape[1]:
        return None
    win = absdiff[r0:r0 + 2 * h + 1, c0_:c0_ + 2 * h + 1]
    k = BALL_UPSAMPLE   # fine pixel j lies at (j + 0.5) / k - 0.5 of the window
    fine = cv2.resize(win, None, fx=k, fy=k, interpolation=cv2.INTER_LINEAR)
    dt = distance_transform_edt(fine > 0.5 * float(win.max()))   # exact, and the same bits in any process
    rr, cc = np.nonzero(dt >= float(dt.max()) - k)   # the deepest point inside the blob: its centre, which
    wts = dt[rr, cc] - (float(dt.max()) - k) + 1e-6  # the string's stretch into the ball does not move
    c = (np.array([float(wts @ rr), float(wts @ cc)]) / wts.sum() + 0.5) / k - 0.5 + [r0, c0_]
    return (c, r) if np.hypot(*(c - pts[-1])) <= r else None   # the walk ends inside the ball


def clean_end(pts: np.ndarray, skel: np.ndarray, skel_at: np.ndarray, absd: np.ndarray, bg: np.ndarray,
              st: TrackingSettings, touch_px: float) -> bool:
    """Whether a skeleton walk's last vertex is the string's free end.

    It is not when: the walk more than 3 ``touch_px`` back comes within ``touch_px`` of the
    end (``end_touch_mm``, a clay lump's size: a tip curled back onto the string, in a hook
    or a closed loop, can end the walk on either strand); a skeleton pixel off the walk lies
    within 2 px (a walk stopped by its own visited pixels, in a loop); the contrast fades
    (``absd`` over the last 3 px below ``end_contrast_min`` of the path's median: a blurred
    tip); or the background ``bg`` steps across the end (by ``end_edge_max`` x that median:
    the rim of an occluder or of a region the string left).

    Args:
        pts: (M, 2) (row, col) walk, the end last (image px). skel: (h, w) bool skeleton whose
            pixel (0, 0) is ``skel_at`` (row, col) in the image. absd, bg: (H, W) contrast and
            background. st: tracking settings (:class:`~stringcast.core.TrackingSettings`:
            ``branch_min_px``, ``end_contrast_min``, ``end_edge_max``).
    """
    cum = arc_length(pts)
    back = pts[cum < cum[-1] - 3 * touch_px]
    if len(back) and float(np.min(np.hypot(*(back - pts[-1]).T))) < touch_px:
        return False
    r, c = pts[-1].astype(int) - skel_at  # in the skeleton's box
    r0, c0 = max(r - 6, 0), max(c - 6, 0)
    win = skel[r0:r + 7, c0:c + 7].copy()
    wr, wc = (pts.astype(int) - skel_at - [r0, c0]).T
    inside = (wr >= 0) & (wr < win.shape[0]) & (wc >= 0) & (wc < win.shape[1])
    win[wr[inside], wc[inside]] = False  # off the walk: a loop's other strand, or a spur
    _, lab, stats, _ = cv2.connectedComponentsWithStats(win.astype(np.uint8), connectivity=8)
    core = np.unique(lab[max(r - 2 - r0, 0):r + 3 - r0, max(c - 2 - c0, 0):c + 3 - c0])
    if np.any(stats[core[core > 0], cv2.CC_STAT_AREA] >= st.branch_min_px):
        return False
    v = _at_pixels(absd, pts)
    t = pts[-1] - pts[max(len(pts) - 7, 0)]
    t = t / max(float(np.hypot(*t)), 1e-9)
    ray = pts[-1] + np.arange(-4.0, 5.0)[:, None] * t  # behind and past the end
    b = map_coordinates(bg, ray.T, order=1, mode="nearest")
    step = abs(float(np.median(b[6:])) - float(np.median(b[:3])))  # the background changes at the end:
    return (float(v[-3:].mean()) >= st.end_contrast_min * float(np.median(v))  # an occluder's rim
            and step < st.end_edge_max * float(np.median(v)))


def end_cut(end, arm: np.ndarray, origin, image_shape, width_px: float) -> bool:
    """Whether a skeleton walk's end may be cut by the arm, the image's edge or the region of
    interest's edge, not the string's own.

    The skeleton stops about half a string's width short of the foreground's end, and the
    foreground stops at the guarded arm mask, the image's edge and the ROI's edge (the ROI
    clips the frame to L + ``roi_margin_mm`` around the grasp; a string seen past it, where the
    image scale or the grasp's place is wrong, goes on beyond it); blur and fading take up to
    another half width and a few px. An end within ``width_px + 4`` px of any of them is therefore
    taken as cut (ends of generalization seed 11 cut by a joint disc lay 4.6-6.7 px from it at a
    3.8 px width; seed 2's free tip 12.9 px from a disc at 5.5 px must stay free; a square size
    configured 50 instead of 60 mm put walks' ends on the ROI's edge, taken for free ends).

    Args:
        end: (row, col) of the end in the ROI, px. arm: (h, w) bool guarded arm mask of the ROI
            (its shape is the ROI's). origin: (row, col) of the ROI in the image. image_shape:
            (H, W). width_px: the string's width in the foreground, px.
    """
    return edge_cut(end, arm.shape, origin, image_shape, width_px) or near_arm(end, arm, math.ceil(width_px) + 4)


def edge_cut(end, roi_shape, origin, image_shape, width_px: float) -> bool:
    """Whether an end (row, col) in the ROI lies within ``width_px + 4`` px of the image's edge or
    the ROI's (``roi_shape`` (h, w) at ``origin`` (row, col) in an image of ``image_shape`` (H, W)):
    the foreground stops there, so the string may go on (:func:`end_cut`)."""
    r = math.ceil(width_px) + 4
    row, col = end[0] + origin[0], end[1] + origin[1]
    if not (r <= row < image_shape[0] - r and r <= col < image_shape[1] - r):
        return True
    return not (r <= end[0] < roi_shape[0] - r and r <= end[1] < roi_shape[1] - r)
