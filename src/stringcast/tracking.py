"""Markerless string tracking: video -> mass-point series in the robot frame.

:func:`run_tracking` writes ``tracks.parquet`` (``frame, t_s, point, x_m, y_m, valid``;
point 0 = grasp, 1..n = the model's points at arc length s_i = i L / n, n = tip).
Settings: ``config['tracking']`` over :data:`DEFAULTS`.

1. **Background** (:func:`~stringcast.background.build_background`): the arm-masked temporal
   median of ``background_samples`` frames spread over the arm's motion in ``background_bursts``
   short runs (:func:`~stringcast.background.background_samples`: only the runs are decoded; the
   string and arm hang still before the motion, and again after it; ``background_window_s``
   limits the samples to the motion's first seconds, for containers that cannot seek: but a string that leaves its rest
   place late in that span becomes background there, and is lost at rest), pixels the arm
   covers throughout taken from pre-motion frames; the same samples give the sensor's noise
   model sigma^2 = a + b B. The main pass decodes ahead in a thread (:mod:`stringcast.prefetch`).
2. **Segmentation** (per frame, within L + ``roi_margin_mm`` of the grasp): a gain for
   flicker ``g = median(I / B)``, ``|I - g B|`` smoothed by a Gaussian, and a hysteresis
   threshold in units of the *local* noise sigma (``threshold_low/high``); polarity free.
3. **Arm mask** from the *measured* joints at the start, middle and end of each frame period
   (:func:`~stringcast.arm_mask.draw_arm_mask`), plus a guard band of ``arm_guard_px``.
4. **Centreline** (:mod:`stringcast.centreline`): skeleton of the foreground; the longest walk
   (:func:`~stringcast.junctions.walk_skeleton`) from near the grasp (or from just outside its clear
   zone, past a hook at the fingertips), through a crossing by
   the smoothest way on (a pass whose choice is a guess, or by an arm never walked, is an
   ambiguity), bridging gaps up to ``max_gap_px`` (bridged parts are never valid); the first
   ``grasp_clear_mm`` replaced by a circular arc from the grasp (:func:`hidden_arc`); sub-pixel
   refinement across the path, smoothing that keeps bends, chords of ``arc_step_px`` joined
   by a spline; a free end (:func:`clean_end`: not fading, not at an occluder's rim, not
   within ``end_touch_mm`` of the string's own earlier stretch, no branch within a point
   spacing) is extended to where the contrast fades (:func:`free_end_extension`).
5. **Metric resampling** (:func:`resample_by_arc`): :meth:`Calibration.pixel_to_robot`, arc
   length from the grasp, points at s_i = i L / n. With a trusted free end whose length
   agrees with L (within ``anchor_tol_mm`` / ``anchor_tol_px``), the mismatch is shared
   among the hidden head, the visible arc and the free end by their uncertainties
   (:func:`mismatch_split`); a longer mismatch (the start hidden or folded behind the
   gripper) anchors the arc at the free end, valid after the last ambiguity (a branch
   joining the walk, a guess at a crossing, a bridged gap) and, for a missing length D, not
   within D past the hidden head (a loop at the fingers); without a free end, at the grasp, valid before the
   first ambiguity. Invalid points keep NaN positions: never a guess.
6. **Markers** (``mode: markers``, :mod:`stringcast.markers`): strings with a band at each mass
   point; a point's position is its band's centre on the centreline, valid where step 5 trusts
   the order along the path and the band is found whole and unambiguous.
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
from skimage.morphology import skeletonize

from .arm import forward_kinematics, motion_window
from .arm_mask import draw_arm_mask
from .background import background_samples, build_background
from .calibration import Calibration
from .centreline import (
    arc_length,
    branch_vertices,
    clean_end,
    decimate_path,
    free_end_extension,
    hidden_arc,
    mismatch_split,
    odd_smooth,
    refine_centreline,
    resample_by_arc,
)
from .config import ConfigError
from .junctions import Zones, walk_skeleton
from .markers import MODES, POLARITIES, band_points, path_contrast
from .files import DataError, find_video, read_joint_table, read_json, write_parquet
from .overlay import write_overlay
from .prefetch import prefetch
from .sync import frame_times
from .video import open_video

DEFAULTS = {
    "rest_frames": 40, "background_samples": 31, "threshold_low": 4.0, "threshold_high": 8.0,
    "smooth_px": 0.8, "roi_margin_mm": 120.0, "grasp_search_mm": 60.0, "grasp_clear_mm": 15.0,
    "max_gap_px": 8.0, "end_tolerance_mm": 6.0, "arc_step_px": 4.0, "overlay_frames": 6,
    # the arm's outline for its mask (UR5e-sized; set them for your arm and gripper)
    "arm_link_widths_mm": [120.0, 100.0, 85.0], "arm_joint_radii_mm": [70.0, 60.0, 50.0, 45.0],
    "gripper_widths_mm": [66.0, 30.0], "gripper_mask_extend_mm": 3.0, "arm_mask_margin_px": 2.0,
    "arm_guard_px": 3.0, "branch_min_px": 6, "anchor_tol_mm": 3.0, "anchor_tol_px": 2.0, "end_sigma_px": 1.0,
    "scale_sigma": 0.003, "tip_shortfall_mm": 0.0, "end_contrast_min": 0.4, "end_edge_max": 0.25, "max_missing_frac": 0.3,
    "end_touch_mm": 12.0,
    "background_window_s": None, "background_bursts": 5, "prefetch_frames": 48,
    # markers (stringcast.markers): a band centred at each mass point gives its position
    "mode": "markerless", "band_width_mm": 8.0, "band_contrast_min": 0.25, "band_tolerance": 0.35,
    "band_length_tol": 0.5, "band_polarity": "auto", "band_step_px": 0.25,
}


def settings(config: dict | None) -> dict:
    """Tracking settings: ``config['tracking']`` over :data:`DEFAULTS`."""
    s = dict(DEFAULTS)
    s.update((config or {}).get("tracking", {}) or {})
    if s["mode"] not in MODES or s["band_polarity"] not in POLARITIES:
        raise ConfigError(f"tracking: mode {s['mode']!r} (one of {MODES}), band_polarity {s['band_polarity']!r}")
    return s


@dataclass(frozen=True)
class FrameTrack:
    """One frame's result: positions (n, 2) m of points 1..n (NaN where invalid), valid (n,),
    and the centreline in image px (M, 2) (x, y), grasp first (empty if none was found)."""

    positions: np.ndarray
    valid: np.ndarray
    path_px: np.ndarray

    def __post_init__(self):
        n = len(self.valid)
        if np.shape(self.positions) != (n, 2) or np.ndim(self.path_px) != 2 or np.shape(self.path_px)[1] != 2:
            raise ValueError(f"FrameTrack: positions {np.shape(self.positions)}, valid {np.shape(self.valid)}, "
                             f"path_px {np.shape(self.path_px)}")
        if np.any(np.isnan(self.positions[self.valid])) or not np.all(np.isnan(self.positions[~self.valid])):
            raise ValueError("FrameTrack: valid points need positions and invalid ones NaN")


class FrameTracker:
    """Segmentation and centreline of single frames, given the background and calibration.

    Args:
        bg: (H, W) background; noise: (a, b) of sigma^2 = a + b B (:func:`build_background`).
        cal: the trial's :class:`Calibration`. campaign: gives L and n. st: :func:`settings`.
    """

    def __init__(self, bg: np.ndarray, noise: tuple[float, float], cal: Calibration, campaign, st: dict):
        self.bg, self.cal, self.st = bg, cal, st
        # noise sigma of the smoothed difference, per pixel (white noise through the Gaussian)
        k = 1.0 / (2 * math.sqrt(math.pi) * st["smooth_px"]) if st["smooth_px"] > 0.3 else 1.0
        self.sigma = (np.sqrt(noise[0] + noise[1] * np.clip(bg, 0, None)) * k).astype(np.float32)
        self.L, self.n = campaign.string.length, campaign.string.n_points
        self.s_targets = np.arange(1, self.n + 1) * self.L / self.n

    def track(self, frame: np.ndarray, poses_px: np.ndarray) -> FrameTrack:
        """Track one frame (H, W); poses_px (P, J + 2, 2): the arm in px at P instants of the
        frame period, the middle one at the frame's time (its last row is the grasp)."""
        st, cal, n = self.st, self.cal, self.n
        gpx = poses_px[len(poses_px) // 2][-1]
        scale = float(cal.m_per_px(gpx[None])[0])  # m per px near the grasp
        R = (self.L + st["roi_margin_mm"] / 1000) / scale
        H, W = frame.shape
        x0, y0 = int(max(0, gpx[0] - R)), int(max(0, gpx[1] - R))
        x1, y1 = int(min(W, gpx[0] + R + 1)), int(min(H, gpx[1] + R + 1))
        def none(path=None):  # no points (NaN), with the centreline found (if any)
            return FrameTrack(np.full((n, 2), np.nan), np.zeros(n, bool), np.zeros((0, 2)) if path is None else path)
        if x1 - x0 < 8 or y1 - y0 < 8:
            return none()
        arm = draw_arm_mask((y1 - y0, x1 - x0), poses_px, st, scale, (x0, y0))
        absd, fg = self._segment(frame[y0:y1, x0:x1].astype(np.float32), self.bg[y0:y1, x0:x1],
                                 self.sigma[y0:y1, x0:x1], arm)
        absd[arm] = 0.0  # the arm's own contrast must not pull the centreline
        if st["arm_guard_px"] >= 1:  # the arm's rim (blur, anti-aliasing) leaves slivers by the mask
            k = 2 * round(st["arm_guard_px"]) + 1
            arm = cv2.dilate(arm.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))) > 0
            fg &= ~arm
        g = np.array([gpx[1] - y0, gpx[0] - x0])  # grasp (row, col) in the ROI
        self._bg = self.bg[y0:y1, x0:x1]
        rho = st["grasp_clear_mm"] / 1000 / scale
        found = self._centreline(fg, g, st["grasp_search_mm"] / 1000 / scale, rho)
        if found is None:
            return none()
        pts, bridged, branch = found
        end = pts[-1].astype(int)
        e0, e1 = np.maximum(end - 3, 0), end + 4
        free_end = bool(3 <= end[0] + y0 < H - 3 and 3 <= end[1] + x0 < W - 3
                        and not arm[e0[0]:e1[0], e0[1]:e1[1]].any() and np.hypot(*(end - g)) > 2 * rho
                        and clean_end(pts, self._skel, self._skel_at, absd, self._bg, st,
                                      st["end_touch_mm"] / 1000 / scale))
        hidden_start = np.hypot(*(pts[0] - g)) > rho + 3 or self._fallback
        loop_back = np.hypot(*(end - g)) <= 2 * rho  # the walk came back to the grasp
        pts = odd_smooth(refine_centreline(absd, pts), 1.5, twice=True)
        if free_end:  # the skeleton stops short of a free end: move the end to the string's end
            ext = free_end_extension(absd, pts)
            if ext > 0.05:
                t = pts[-1] - pts[-2]
                pts = np.vstack([pts, pts[-1] + ext * t / max(float(np.hypot(*t)), 1e-9)])
                bridged = np.r_[bridged, False]
                branch = np.r_[branch, False]
        cum_px = arc_length(pts)
        gap = np.nonzero(bridged & (np.r_[0.0, np.diff(cum_px)] > 2.5))[0]
        ev_px = np.sort(np.concatenate([cum_px[branch], cum_px[gap - 1], cum_px[gap]]))
        pts, obs = decimate_path(pts, ~bridged[1:], st["arc_step_px"], sub=4)
        head = hidden_arc(g, pts)  # grasp -> first visible vertex, under the gripper's mask
        px = np.vstack([head, pts])[:, ::-1] + [x0, y0]  # (x, y) image px, grasp first
        obs = np.concatenate([np.full(len(head), not hidden_start), obs])
        xy = cal.pixel_to_robot(px)
        s_poly = arc_length(xy)
        L_head = float(s_poly[len(head)])
        s_dec = np.linspace(0.0, cum_px[-1], len(pts))
        events = np.interp(ev_px, s_dec, s_poly[len(head):])  # ambiguities, polyline arc (m)
        if hidden_start:
            events = np.r_[L_head, events]
        D = self.L - st["tip_shortfall_mm"] / 1000 - float(s_poly[-1])  # missing length if the end is the tip
        tol = max(st["anchor_tol_mm"] / 1000, 0.01 * self.L, st["anchor_tol_px"] * scale)  # both ends +-1 px
        slack = L_head - float(np.linalg.norm(xy[len(head)] - xy[0]))  # the head may be shorter, not below its chord
        lo, hi, shift, split = -np.inf, np.inf, 0.0, None
        if free_end and len(events) and float(s_poly[-1]) - events[-1] < self.L / n:
            free_end = False  # a branch joins within a point spacing of the end: is the tip this end or the branch's?
        if free_end and abs(D) <= tol:  # both anchors agree: share the mismatch (head, visible arc, free end)
            split = mismatch_split(D, np.array([scale * st["end_sigma_px"] + slack, st["scale_sigma"] * (float(
                s_poly[-1]) - L_head), scale * st["end_sigma_px"]]))
        elif free_end and -tol - slack < D <= st["max_missing_frac"] * self.L:  # anchored at the tip: valid after the last ambiguity
            shift, lo = D, (events[-1] if len(events) else (L_head if hidden_start else -np.inf))
            if D > tol:  # the missing length hides by the grasp (a loop at the fingers, under the arm's mask):
                lo = max(lo, L_head + D)  # the visible path's first D past the head may be that loop's
        elif not hidden_start and not self._head_clutter and not ((loop_back or free_end) and D > tol):  # anchored at the grasp: valid before the first ambiguity
            hi = events[0] if len(events) else np.inf
            if free_end:
                hi = min(hi, float(s_poly[-1]))
        else:
            return none(px)
        s_t = self.s_targets - shift  # the targets' polyline arc
        if split is not None:  # model arc -> polyline arc: knots at the head's end and at the free end
            end = self.L - st["tip_shortfall_mm"] / 1000 - split[2]
            s_t = np.interp(self.s_targets, [0.0, L_head + split[0], end], [0.0, L_head, float(s_poly[-1])])
            s_t = np.where(self.s_targets > end, float(s_poly[-1]) + self.s_targets - end, s_t)
        pos, valid = resample_by_arc(xy, obs, s_t, st["end_tolerance_mm"] / 1000 if free_end else 0.0)
        trusted = (s_t >= max(lo, 0.0)) & (s_t <= hi) & (self.s_targets >= 0)
        valid &= trusted
        if st["mode"] == "markers":  # the bands' centres, where the order along the path is trusted
            pos, valid = band_points(frame, px, obs & (np.arange(len(obs)) >= len(head)), s_poly, s_t, trusted,
                                     free_end, path_contrast(absd, pts), cal, st)
        pos[~valid] = np.nan
        return FrameTrack(pos, valid, px)

    def _segment(self, img: np.ndarray, bg: np.ndarray, sigma: np.ndarray, arm: np.ndarray):
        """Smoothed |I - g B| (gain g for flicker) and its hysteresis foreground outside the arm."""
        st = self.st
        sub = (slice(None, None, 3), slice(None, None, 3))
        use = (bg[sub] > 10) & ~arm[sub]
        gain = float(np.median(img[sub][use] / bg[sub][use])) if use.sum() > 100 else 1.0
        diff = img - gain * bg
        if st["smooth_px"] > 0:
            diff = cv2.GaussianBlur(diff, (0, 0), st["smooth_px"])
        absd = np.abs(diff)
        z = absd / np.maximum(sigma * math.sqrt(max(gain, 1e-3)), 0.05)
        weak = (z > st["threshold_low"]) & ~arm
        nlab, lab = cv2.connectedComponents(weak.astype(np.uint8), connectivity=8)
        keep = np.zeros(nlab, bool)
        keep[lab[weak & (z > st["threshold_high"])]] = True
        keep[0] = False
        return absd, keep[lab]

    def _centreline(self, fg: np.ndarray, g: np.ndarray, r0: float, rho: float):
        """Skeleton path from near the grasp g (row, col): (M, 2) (row, col), (M,) bridged; or None.

        Seeds: the skeleton pixel nearest the grasp in each skeleton component within r0 px
        (at most 6), and up to 4 of the component's pixels just outside rho (a string that leaves
        the fingers in a short hook: the nearest pixel's walk takes the hook); the longest walk
        wins, a walk from outside rho only if it is longer by 2 rho than the nearest pixel's. A walk is cut where it comes closest to the grasp
        (dropping detours along slivers of the gripper's rim), then its vertices within rho
        px of the grasp are dropped (there the string mixes with the fingertips).
        """
        x, y, w, h = cv2.boundingRect(fg.astype(np.uint8))
        if w == 0:
            return None
        b = np.array([max(0, y - 1), max(0, x - 1)])  # the foreground's box, 1 px margin: all work is in it
        box = fg[b[0]:y + h + 1, b[1]:x + w + 1]
        skel = skeletonize(box)
        self._skel, self._skel_at = skel, b
        dist = cv2.distanceTransform(box.astype(np.uint8), cv2.DIST_L2, 3)  # the string's width: twice the
        self._width = 2.0 * float(np.median(dist[skel])) if skel.any() else 1.0  # skeleton's distance to the rim
        found = self._walk(skel, g - b, r0, rho)
        return None if found is None else (found[0] + b, found[1], found[2])

    def _walk(self, skel: np.ndarray, g: np.ndarray, r0: float, rho: float):
        """:meth:`_centreline` inside the foreground's box: skel (h, w) bool, g (row, col) in the box."""
        sy, sx = np.nonzero(skel)
        dist = np.hypot(sy - g[0], sx - g[1])
        idx = np.nonzero(dist <= r0)[0]
        if len(idx) == 0:
            return None
        _, comp = cv2.connectedComponents(skel.astype(np.uint8), connectivity=8)
        cid = comp[sy[idx], sx[idx]]
        seeds = []  # per component: its pixel nearest the grasp, then (if the walk from it ends in a spur of
        for c in np.unique(cid):  # the tangle at the fingertips) its pixels just outside the clear zone
            own = idx[cid == c]
            ring = own[(dist[own] >= rho) & (dist[own] < rho + 3)]
            ring = ring[np.argsort(dist[ring])]
            picked = []   # ring pixels >= 3 px apart: one per way out of the tangle (string, hook, finger rim)
            for r in ring:
                if all(np.hypot(sy[r] - sy[q], sx[r] - sx[q]) >= 3 for q in picked) and len(picked) < 4:
                    picked.append(r)
            seeds.append((own[np.argmin(dist[own])], *picked))
        best, zones = None, Zones(skel, self._width, int(self.st["branch_min_px"]))
        for pair in sorted(seeds, key=lambda p: dist[p[0]])[:6]:
            penalty = 0.0   # once the nearest pixel's walk leaves the clear zone, a ring pixel's must beat it
            for fallback, c in enumerate(pair):   # by 2 rho (a hook at the fingertips caught the first walk)
                d0 = np.array([sy[c], sx[c]], float) - g
                pts, bridged, amb, fold, passed = walk_skeleton(
                    skel, (sy[c], sx[c]), self.st["max_gap_px"], d0 if np.hypot(*d0) >= 1 else None, zones=zones)
                cum = arc_length(pts)
                head = np.nonzero(cum <= 2 * r0)[0]
                j0 = int(head[np.argmin(np.hypot(*(pts[head] - g).T))])
                far = np.nonzero(np.hypot(*(pts[j0:] - g).T) >= rho)[0]
                if len(far) == 0:
                    continue
                j1 = j0 + int(far[0])
                score = cum[-1] - cum[j1] - (penalty if fallback else 0.0)
                if best is None or score > best[2]:
                    b = bridged[j1:].copy()
                    b[0] = False
                    best = (pts[j1:], b, score, pts, fallback, amb, passed, fold)
                if not fallback:
                    penalty = 2 * rho
        if best is None:
            return None
        walk = best[3].astype(int)
        self._fallback = bool(best[4])  # the string's start is then not seen joining the grasp
        if best[4]:  # the walk skipped a tangle at the fingertips: not a branch
            skel = skel.astype(np.uint8)
            cv2.circle(skel, (round(g[1]), round(g[0])), round(rho + 1), 0, -1)
        ev = branch_vertices((skel > 0) & ~best[6], walk, int(self.st["branch_min_px"])) | best[5]
        # a branch joining the walk near the grasp: a loop there, the ordering is ambiguous; a fold there
        head = np.hypot(*(walk - g).T) <= 2 * rho  # (a spur) is the fingertips' tangle, or the loop at
        self._head_clutter = bool(np.any(ev & head))  # the fingers that a missing length is anchored for
        return best[0], best[1], (ev | (best[7] & ~head))[len(best[3]) - len(best[0]):]


def _joint_px(cal: Calibration, arm, q: np.ndarray) -> np.ndarray:
    pts = forward_kinematics(arm, q)  # (F, J + 2, 2)
    return cal.robot_to_pixel(pts.reshape(-1, 2)).reshape(pts.shape)


def _interp_joints(t: np.ndarray, t_j: np.ndarray, q_j: np.ndarray) -> np.ndarray:
    return np.column_stack([np.interp(t, t_j, q_j[:, j]) for j in range(q_j.shape[1])])


def run_tracking(trial_dir, calibration_json, sync_json, campaign, config, out_parquet,
                 overlay_png=None) -> pd.DataFrame:
    """Track the string in one trial; write ``tracks.parquet`` (and the overlay PNG).

    Args:
        trial_dir: holds the video (``files.find_video``) and ``joints.csv``.
        calibration_json, sync_json: this trial's ``calibration.json`` and ``sync.json``.
        campaign: the resolved campaign (arm, string length L and n). config: the config.
        overlay_png: if given, a strip of ``overlay_frames`` frames with the tracked points.

    Returns:
        The long table ``frame, t_s, point, x_m, y_m, valid``, (n + 1) rows per frame, in m
        in the robot frame; frames outside the joint log are all invalid.

    Raises:
        DataError: missing or malformed inputs (named), or a frame count or image size that
            disagrees with ``sync.json`` / ``calibration.json``.
    """
    from tqdm import tqdm

    trial_dir = Path(trial_dir)
    st = settings(config)
    cal = Calibration.from_json(calibration_json)
    sync = read_json(sync_json)
    t_j, q_j, _ = read_joint_table(trial_dir / "joints.csv")
    arm, n = campaign.arm, campaign.string.n_points
    vpath = find_video(trial_dir)
    video = open_video(vpath)
    if (video.width, video.height) != tuple(cal.image_size):
        raise DataError(f"{video.path}: frames are {video.width}x{video.height}, {calibration_json} is for "
                        f"{cal.image_size[0]}x{cal.image_size[1]}")
    F = video.n_frames
    if "frames" in sync and int(sync["frames"]) != F:
        raise DataError(f"{video.path}: {F} frames, but {sync_json} (from video.yaml) says {sync['frames']}")
    t = frame_times(sync, F)
    in_log = (t >= t_j[0]) & (t <= t_j[-1])
    half = 0.5 / float(sync["fps"])  # the arm at the start, middle and end of each frame period
    jpx = np.stack([_joint_px(cal, arm, _interp_joints(t + dt, t_j, q_j)) for dt in (-half, 0.0, half)], axis=1)
    scale = float(np.median(cal.m_per_px(jpx[:, 1, -1])))
    try:
        t_start, t_end = motion_window(t_j, q_j)
    except ValueError:  # the arm never moves
        t_start, t_end = t_j[0], t_j[-1]
    win = np.nonzero((t >= t_start) & (t <= t_end + 0.1) & in_log)[0]
    if len(win) < 9:
        win = np.arange(F)
    span = st["background_window_s"]   # None: the whole motion window (the string hangs still in a short one)
    early = win if span is None else win[t[win] <= t[win[0]] + span]
    bwin = early if len(early) >= 9 else win
    samples = background_samples(bwin, int(st["background_samples"]), int(st["background_bursts"]))
    pre = np.nonzero(t < t_start - 0.02)[0][-int(st["rest_frames"]):]
    frames = prefetch(video, int(st["prefetch_frames"]))  # the main pass decodes while the background is built
    second = open_video(vpath)
    try:
        bg, noise = build_background(second, samples.astype(int), pre, lambda k: draw_arm_mask(
            (video.height, video.width), jpx[k], st, scale, grow_px=2.0))
    finally:
        second.close()
    tracker = FrameTracker(bg, noise, cal, campaign, st)

    xy = np.full((F, n + 1, 2), np.nan)
    valid = np.zeros((F, n + 1), bool)
    xy[:, 0] = forward_kinematics(arm, _interp_joints(t, t_j, q_j))[:, -1]  # point 0: the grasp
    valid[:, 0] = in_log
    xy[~in_log, 0] = np.nan
    shows = set(np.round(np.linspace(win[0], win[-1], int(st["overlay_frames"]))).astype(int)) if overlay_png else set()
    shown = []
    for k, frame in tqdm(frames, total=F, desc="tracking", unit="frame", disable=not sys.stderr.isatty()):
        if not in_log[k]:
            continue
        ft = tracker.track(frame, jpx[k])
        xy[k, 1:], valid[k, 1:] = ft.positions, ft.valid
        if k in shows:
            shown.append((k, frame, ft.path_px, cal.robot_to_pixel(np.nan_to_num(xy[k])), valid[k].copy()))
    video.close()
    df = pd.DataFrame({
        "frame": np.repeat(np.arange(F), n + 1).astype(np.int64),
        "t_s": np.repeat(t, n + 1),
        "point": np.tile(np.arange(n + 1), F).astype(np.int64),
        "x_m": xy[..., 0].ravel(), "y_m": xy[..., 1].ravel(),
        "valid": valid.ravel(),
    })
    write_parquet(out_parquet, df)
    if overlay_png is not None:
        write_overlay(overlay_png, shown, t, scale, campaign.string.length)
    return df
