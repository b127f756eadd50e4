"""Markerless string tracking: video -> mass-point series in the robot frame.

:func:`run_tracking` writes ``tracks.parquet`` (``frame, t_s, point, x_m, y_m, valid``;
point 0 = grasp, 1..n = the model's points at arc length s_i = i L / n, n = tip).
Settings: ``config['tracking']`` over :data:`DEFAULTS`.

1. **Background** (:func:`build_background`): the temporal median of
   ``background_samples`` frames spread over the arm's motion window (from the joint log),
   each with the arm masked out (NaN-median), so neither the moving arm nor the moving
   string survives in it; pixels the arm covers in every sample come from pre-motion frames.
   Not the pre-motion frames alone: the string and the arm hang still there, exactly where
   the string starts. Not the whole clip: after the motion the string hangs still again
   under the end posture. The same samples give the sensor's noise model
   sigma^2 = a + b B (read + shot noise). The sampled frames are decoded once more (in
   order); every frame is then read once in the main pass.
2. **Segmentation** (per frame, within L + ``roi_margin_mm`` of the grasp): a gain for
   light flicker ``g = median(I / B)``, ``|I - g B|`` smoothed by a Gaussian, and a
   hysteresis threshold in units of the *local* noise sigma (``threshold_low/high``), so
   the string is found over dark parts of the scene too; polarity free (the string may be
   darker or lighter than the scene; its grey level is never keyed on).
3. **Arm mask** from the *measured* joints (``joints.csv`` at the frame times of
   ``sync.json``, at the start, middle and end of each frame period for motion blur):
   forward kinematics -> :meth:`Calibration.robot_to_pixel` -> link quadrilaterals, joint
   discs and the gripper's (tapered) quadrilateral (:func:`draw_arm_mask`), plus a guard
   band of ``arm_guard_px`` where the arm's rim leaves slivers.
4. **Centreline** (:mod:`stringcast.centreline`): ``skimage.morphology.skeletonize`` of the foreground; a walk
   (:func:`trace_path`) from near the grasp that continues straight at junctions and
   bridges gaps up to ``max_gap_px`` in a forward cone (bridged parts are never valid);
   the first ``grasp_clear_mm`` (mixed with the fingertips) replaced by a circular arc
   from the grasp (:func:`hidden_arc`); each path pixel moved to the weighted centroid of
   |I - g B| along the normal (sub-pixel, :func:`refine_centreline`); smoothed, and
   decimated to chords of ``arc_step_px`` (:func:`decimate_path`) so pixel noise does not
   lengthen the arc.
5. **Metric resampling** (:func:`resample_by_arc`): :meth:`Calibration.pixel_to_robot`,
   arc length in metres from the grasp, points at s_i = i L / n. A point is valid only on
   an observed part within the visible length (the tip may read up to
   ``end_tolerance_mm`` past a *free* end: skeletons stop short of it). When the string's
   start is hidden by the gripper for longer than the clear zone (it may fold behind it),
   the arc is anchored at the free end instead (using the free end's shortfall learnt on
   frames where the string was seen whole); without a free end the frame gives no points.
   Invalid points keep NaN positions: never a guess.
"""
from __future__ import annotations

import math
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
from skimage.morphology import skeletonize

from .arm import forward_kinematics, motion_window
from .calibration import Calibration
from .centreline import odd_smooth, decimate_path, hidden_arc, refine_centreline, resample_by_arc, trace_path
from .files import DataError, atomic_path, find_video, read_joint_table, read_json, write_parquet
from .sync import frame_times
from .video import open_video

DEFAULTS = {
    "rest_frames": 40, "background_samples": 31, "threshold_low": 4.0, "threshold_high": 8.0,
    "smooth_px": 0.8, "roi_margin_mm": 120.0, "grasp_search_mm": 60.0, "grasp_clear_mm": 15.0,
    "max_gap_px": 8.0, "end_tolerance_mm": 6.0, "arc_step_px": 4.0, "overlay_frames": 6,
    # the arm's outline for its mask (UR5e-sized; set them for your arm and gripper)
    "arm_link_widths_mm": [120.0, 100.0, 85.0], "arm_joint_radii_mm": [70.0, 60.0, 50.0, 45.0],
    "gripper_widths_mm": [66.0, 30.0], "gripper_mask_extend_mm": 3.0, "arm_mask_margin_px": 2.0,
    "arm_guard_px": 3.0,
}


def settings(config: dict | None) -> dict:
    """Tracking settings: ``config['tracking']`` over :data:`DEFAULTS`."""
    s = dict(DEFAULTS)
    s.update((config or {}).get("tracking", {}) or {})
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


# ---------------------------------------------------------------------------- arm mask
def _quad(p0, p1, w0, w1):
    d = np.asarray(p1, float) - p0
    n = np.array([-d[1], d[0]]) / max(np.hypot(*d), 1e-9) / 2
    return np.array([p0 + n * w0, p1 + n * w1, p1 - n * w1, p0 - n * w0])


def draw_arm_mask(shape, poses_px, st: dict, m_per_px: float, offset=(0, 0), grow_px: float = 0.0) -> np.ndarray:
    """Binary mask (H, W) bool of the arm at one or more poses (their union).

    The outline comes from ``st`` (mm): ``arm_link_widths_mm`` (per link),
    ``arm_joint_radii_mm`` (discs at the base and each joint), ``gripper_widths_mm`` (at the
    wrist, at the fingertips; the gripper's quadrilateral ends ``gripper_mask_extend_mm``
    past the grasp point, square), each grown by ``arm_mask_margin_px`` + ``grow_px``.

    Args:
        poses_px: (J + 2, 2) or (P, J + 2, 2) base, joints and grasp point in px; several
            poses (the start, middle and end of a frame period) cover motion blur.
        m_per_px: image scale. offset: (x0, y0) of the mask's origin in the image (ROI).
    """
    m = np.zeros(shape, np.uint8)
    poses = np.asarray(poses_px, float).reshape(-1, *np.shape(poses_px)[-2:])
    grow = st["arm_mask_margin_px"] + grow_px
    px = lambda v: v / 1000 / m_per_px  # noqa: E731  (mm -> px)
    links, radii = st["arm_link_widths_mm"], st["arm_joint_radii_mm"]
    gw = [px(w) + 2 * grow for w in st["gripper_widths_mm"]]
    sh = 4  # fixed-point bits for sub-pixel polygons
    fix = lambda v: np.round(np.asarray(v) * 2 ** sh).astype(np.int32)  # noqa: E731
    for pose in poses:
        p = pose - offset
        J = len(p) - 2
        d = p[-1] - p[-2]
        tip = p[-1] + d / max(np.hypot(*d), 1e-9) * px(st["gripper_mask_extend_mm"])
        for j in range(J):
            w = px(links[min(j, len(links) - 1)]) + 2 * grow
            cv2.fillConvexPoly(m, fix(_quad(p[j], p[j + 1], w, w)), 1, cv2.LINE_8, sh)
        cv2.fillConvexPoly(m, fix(_quad(p[J], tip, gw[0], gw[-1])), 1, cv2.LINE_8, sh)
        for j in range(J + 1):
            r = px(radii[min(j, len(radii) - 1)]) + grow
            cv2.circle(m, tuple(int(v) for v in fix(p[j])), int(round(r * 2 ** sh)), 1, -1, cv2.LINE_8, sh)
    return m.astype(bool)


# ---------------------------------------------------------------------------- background
def build_background(video, sample_idx, pre_idx, arm_masks) -> tuple[np.ndarray, tuple[float, float]]:
    """Arm-masked temporal median background and the sensor's noise model.

    Args:
        video: :class:`~stringcast.video.VideoReader`.
        sample_idx: frames spread over the motion; pre_idx: pre-motion frames (fill-in).
        arm_masks: callable frame index -> (H, W) bool arm mask.

    Returns:
        background (H, W) float32 (grey levels), and (a, b) of sigma^2 = a + b B, fitted by
        weighted least squares to robust (MAD) spreads of the samples about the background
        in 16 brightness bins.
    """
    h, w = video.height, video.width
    stack = np.empty((len(sample_idx), h, w), np.float32)
    for j, k in enumerate(sample_idx):
        f = video.read(int(k)).astype(np.float32)
        f[arm_masks(int(k))] = np.nan
        stack[j] = f
    bg = np.empty((h, w), np.float32)
    with warnings.catch_warnings():  # all-NaN pixels (arm in every sample) are filled below
        warnings.simplefilter("ignore", RuntimeWarning)
        for r in range(0, h, 64):  # row chunks keep nanmedian's temporaries small
            bg[r:r + 64] = np.nanmedian(stack[:, r:r + 64], axis=0)
    hole = ~np.isfinite(bg)
    if hole.any():
        src = pre_idx if len(pre_idx) else sample_idx
        pre = np.median(np.stack([video.read(int(k)) for k in src[:15]]), axis=0).astype(np.float32)
        bg[hole] = pre[hole]
    d = (stack[:, ::2, ::2] - bg[None, ::2, ::2]).ravel()
    B = np.broadcast_to(bg[None, ::2, ::2], stack[:, ::2, ::2].shape).ravel()
    ok = np.isfinite(d)
    d, B = d[ok], B[ok]
    which = np.clip(np.searchsorted(np.quantile(B, np.linspace(0, 1, 17)), B, side="right") - 1, 0, 15)
    xs, ys, ws = [], [], []
    for i in range(16):
        di = d[which == i]
        if len(di) >= 500:
            xs.append(float(np.median(B[which == i])))
            ys.append((1.4826 * float(np.median(np.abs(di - np.median(di))))) ** 2)
            ws.append(math.sqrt(len(di)))
    if len(xs) >= 2:
        A = np.column_stack([np.ones(len(xs)), xs]) * np.asarray(ws)[:, None]
        a, b = np.linalg.lstsq(A, np.asarray(ys) * ws, rcond=None)[0]
        return bg, (max(float(a), 0.01), max(float(b), 0.0))
    return bg, (max(float(np.mean(ys)) if ys else 1.0, 0.01), 0.0)


# ---------------------------------------------------------------------------- per frame
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
        self.shortfalls: list[float] = []

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
        none = lambda path=np.zeros((0, 2)): FrameTrack(np.full((n, 2), np.nan), np.zeros(n, bool), path)  # noqa: E731
        if x1 - x0 < 8 or y1 - y0 < 8:
            return none()
        arm = draw_arm_mask((y1 - y0, x1 - x0), poses_px, st, scale, (x0, y0))
        absd, fg = self._segment(frame[y0:y1, x0:x1].astype(np.float32), self.bg[y0:y1, x0:x1],
                                 self.sigma[y0:y1, x0:x1], arm)
        absd[arm] = 0.0  # the arm's own contrast must not pull the centreline
        if st["arm_guard_px"] >= 1:  # the arm's rim (blur, anti-aliasing) leaves slivers by the mask
            k = 2 * int(round(st["arm_guard_px"])) + 1
            arm = cv2.dilate(arm.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))) > 0
            fg &= ~arm
        g = np.array([gpx[1] - y0, gpx[0] - x0])  # grasp (row, col) in the ROI
        rho = st["grasp_clear_mm"] / 1000 / scale
        found = self._centreline(fg, g, st["grasp_search_mm"] / 1000 / scale, rho)
        if found is None:
            return none()
        pts, bridged = found
        end = pts[-1].astype(int)
        e0, e1 = np.maximum(end - 3, 0), end + 4
        free_end = bool(3 <= end[0] + y0 < H - 3 and 3 <= end[1] + x0 < W - 3
                        and not arm[e0[0]:e1[0], e0[1]:e1[1]].any())
        hidden_start = np.hypot(*(pts[0] - g)) > rho + 3
        pts = odd_smooth(refine_centreline(absd, pts), 1.5)
        pts, obs = decimate_path(pts, ~bridged[1:], st["arc_step_px"])
        head = hidden_arc(g, pts)  # grasp -> first visible vertex, under the gripper's mask
        px = np.vstack([head, pts])[:, ::-1] + [x0, y0]  # (x, y) image px, grasp first
        obs = np.concatenate([np.full(len(head), not hidden_start), obs])
        xy = cal.pixel_to_robot(px)
        seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
        L_vis, L_head = float(seg.sum()), float(seg[:len(head)].sum())
        targets = self.s_targets
        if free_end and not hidden_start and abs(self.L - L_vis) < 0.05 * self.L:
            self.shortfalls.append(self.L - L_vis)  # seen whole: how short the free end reads
        if hidden_start:  # unknown hidden length: only the free end (tip) can anchor the arc
            deficit = self.L - L_vis - self.shortfall()
            if not (free_end and -2 * scale < deficit < max(L_head, 0.02) + 3 * scale):
                return none(px)
            targets = targets - max(deficit, 0.0)
        pos, valid = resample_by_arc(xy, obs, targets, st["end_tolerance_mm"] / 1000 if free_end else 0.0)
        valid &= targets >= 0
        pos[~valid] = np.nan
        return FrameTrack(pos, valid, px)

    def shortfall(self) -> float:
        """Median of L - visible length on frames where the string was seen whole, m (0 if < 5)."""
        return float(np.median(self.shortfalls[-200:])) if len(self.shortfalls) >= 5 else 0.0

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
        keep[np.unique(lab[weak & (z > st["threshold_high"])])] = True
        keep[0] = False
        return absd, keep[lab]

    def _centreline(self, fg: np.ndarray, g: np.ndarray, r0: float, rho: float):
        """Skeleton path from near the grasp g (row, col): (M, 2) (row, col), (M,) bridged; or None.

        Seeds: the skeleton pixel nearest the grasp in each skeleton component within r0 px
        (at most 6); the longest walk wins. A walk is cut where it comes closest to the grasp
        (dropping detours along slivers of the gripper's rim), then its vertices within rho
        px of the grasp are dropped (there the string mixes with the fingertips).
        """
        rows, cols = np.nonzero(fg)
        if len(rows) == 0:
            return None
        b0, b1 = max(0, rows.min() - 1), max(0, cols.min() - 1)
        skel = np.zeros_like(fg)
        skel[b0:rows.max() + 2, b1:cols.max() + 2] = skeletonize(fg[b0:rows.max() + 2, b1:cols.max() + 2])
        sy, sx = np.nonzero(skel)
        dist = np.hypot(sy - g[0], sx - g[1])
        idx = np.nonzero(dist <= r0)[0]
        if len(idx) == 0:
            return None
        _, comp = cv2.connectedComponents(skel.astype(np.uint8), connectivity=8)
        cid = comp[sy[idx], sx[idx]]
        seeds = [idx[cid == c][np.argmin(dist[idx[cid == c]])] for c in np.unique(cid)]
        best = None
        for c in sorted(seeds, key=lambda i: dist[i])[:6]:
            d0 = np.array([sy[c], sx[c]], float) - g
            pts, bridged = trace_path(skel, (sy[c], sx[c]), self.st["max_gap_px"], d0 if np.hypot(*d0) >= 1 else None)
            cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
            head = np.nonzero(cum <= 2 * r0)[0]
            j0 = int(head[np.argmin(np.hypot(*(pts[head] - g).T))])
            far = np.nonzero(np.hypot(*(pts[j0:] - g).T) >= rho)[0]
            if len(far) == 0:
                continue
            j1 = j0 + int(far[0])
            if best is None or cum[-1] - cum[j1] > best[2]:
                b = bridged[j1:].copy()
                b[0] = False
                best = (pts[j1:], b, cum[-1] - cum[j1])
        return None if best is None else best[:2]


# ---------------------------------------------------------------------------- trial
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
    video = open_video(find_video(trial_dir))
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
    samples = np.unique(np.round(np.linspace(win[0], win[-1], min(len(win), int(st["background_samples"])))))
    pre = np.nonzero(t < t_start - 0.02)[0][-int(st["rest_frames"]):]
    bg, noise = build_background(video, samples.astype(int), pre, lambda k: draw_arm_mask(
        (video.height, video.width), jpx[k], st, scale, grow_px=2.0))
    tracker = FrameTracker(bg, noise, cal, campaign, st)

    xy = np.full((F, n + 1, 2), np.nan)
    valid = np.zeros((F, n + 1), bool)
    xy[:, 0] = forward_kinematics(arm, _interp_joints(t, t_j, q_j))[:, -1]  # point 0: the grasp
    valid[:, 0] = in_log
    xy[~in_log, 0] = np.nan
    shows = set(np.round(np.linspace(win[0], win[-1], int(st["overlay_frames"]))).astype(int)) if overlay_png else set()
    shown = []
    for k, frame in tqdm(video, total=F, desc="tracking", unit="frame", disable=not sys.stderr.isatty()):
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


def write_overlay(path, shown, t, m_per_px: float, L: float, tile: int = 320) -> None:
    """A strip of frames (crops around the grasp) with the centreline and tracked points drawn."""
    tiles = []
    for k, frame, path_px, pts_px, ok in shown:
        img = frame if frame.dtype == np.uint8 else cv2.convertScaleAbs(frame, alpha=255.0 / max(1, int(frame.max())))
        rgb = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
        if len(path_px) > 1:
            cv2.polylines(rgb, [np.round(path_px * 4).astype(np.int32)], False, (255, 160, 0), 1, cv2.LINE_AA, 2)
        for i, (p, v) in enumerate(zip(pts_px, ok)):
            if v:
                cv2.circle(rgb, tuple(np.round(p * 4).astype(int)), 12, (0, 0, 255) if i == 0 else (0, 200, 0), 1,
                           cv2.LINE_AA, 2)
        R = int((L + 0.12) / m_per_px)
        c = pts_px[0].astype(int)
        crop = cv2.copyMakeBorder(rgb, R, R, R, R, cv2.BORDER_CONSTANT, value=(0, 0, 0))[c[1]:c[1] + 2 * R, c[0]:c[0] + 2 * R]
        crop = cv2.resize(crop, (tile, tile), interpolation=cv2.INTER_AREA)
        cv2.putText(crop, f"frame {k}  t={t[k]:.3f} s", (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 255, 255), 1, cv2.LINE_AA)
        tiles.append(crop)
    if not tiles:
        tiles = [np.zeros((tile, tile, 3), np.uint8)]
        cv2.putText(tiles[0], "no frames tracked", (10, tile // 2), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 1)
    ok, buf = cv2.imencode(".png", np.hstack(tiles))
    with atomic_path(path) as tmp:
        tmp.write_bytes(buf.tobytes())
