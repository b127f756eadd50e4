"""One frame of markerless tracking: segmentation, centreline and metric points (steps 2-6 of
:mod:`stringcast.track.tracking`, whose module doc describes them; :func:`stringcast.track.tracking.run_tracking`
streams the video through a :class:`FrameTracker`)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from skimage.morphology import skeletonize

from .arm_mask import draw_arm_mask, near_arm
from .board_zone import board_outline_px, over_board
from stringcast.calibrate import Calibration
from stringcast.core import TrackingSettings
from .centreline import (
    arc_length,
    branch_vertices,
    decimate_path,
    hidden_arc,
    mismatch_split,
    odd_smooth,
    refine_centreline,
    resample_by_arc,
    seen_segments,
)
from .beyond_arm import tip_stretch
from .ends import clean_end, edge_cut, end_cut, locate_end, string_continues
from .junctions import Zones, walk_skeleton
from .markers import band_points, path_contrast
from .quality import UNPLACED


@dataclass(frozen=True)
class FrameTrack:
    """One frame's result: positions (n, 2) m of points 1..n (NaN where invalid), valid (n,),
    the centreline in image px (M, 2) (x, y), grasp first (empty if none was found), and
    ``length_mismatch_m``: L minus the centreline's length from the grasp to a trusted free end
    (the tip), m, NaN without one or with the string's start hidden (also where the mismatch is
    too large to anchor any point: a string longer or shorter than the campaign's); ``past_roi``:
    the walk from the grasp was cut by the region of interest's edge inside the image, i.e. the
    string was seen farther than L + ``roi_margin_mm`` from the grasp; ``off_image``: that walk was
    cut by the image's edge (the string runs out of the image); ``stretch``: the seen length over L
    where the points were spread over a stretched string's seen length, else 1; ``unplaced``: why the
    frame placed no point (:data:`~stringcast.track.quality.UNPLACED`; "" where it placed points, even
    if some fell past an ambiguity or the end seen). :mod:`stringcast.track.quality` reads the last five.
    ``stretch_seen``: the frame measured the string's stretch (``seen_ratio``), seeing it from the grasp to a
    trusted free end with no ambiguity between; ``grasp_arc``: where the
    points were anchored at the grasp by arc length (markerless), the frame's polyline (K, 2) m from the grasp, its observed segments
    (K - 1,) bool and the arc length, m, past which no point is trusted, which
    :mod:`stringcast.track.held_stretch` spreads the points over by the stretch seen about the frame (else
    None); ``tip_arc``: where points were placed beyond the arm from the tip (:meth:`FrameTracker._with_beyond`),
    that stretch's polyline (K', 2) m from the arm's rim to the tip, its observed segments, the arc length before
    which no point is trusted, the string's length from the rim to its tip and the tip's tolerance, m, which
    it spreads likewise (else None); ``seen_ratio``: where ``stretch_seen``, the length seen from the grasp to
    the free end over L (less the tip's shortfall), whether the points were spread over it (``stretch``) or
    the mismatch, within the anchor's tolerance, shared among the head, the arc and the end; else NaN."""

    positions: np.ndarray
    valid: np.ndarray
    path_px: np.ndarray
    length_mismatch_m: float = math.nan
    past_roi: bool = False
    off_image: bool = False
    stretch: float = 1.0
    unplaced: str = ""
    stretch_seen: bool = False
    grasp_arc: tuple | None = None
    tip_arc: tuple | None = None
    seen_ratio: float = math.nan

    def __post_init__(self):
        n = len(self.valid)
        if np.shape(self.positions) != (n, 2) or np.ndim(self.path_px) != 2 or np.shape(self.path_px)[1] != 2:
            raise ValueError(f"FrameTrack: positions {np.shape(self.positions)}, valid {np.shape(self.valid)}, "
                             f"path_px {np.shape(self.path_px)}")
        if np.any(np.isnan(self.positions[self.valid])) or not np.all(np.isnan(self.positions[~self.valid])):
            raise ValueError("FrameTrack: valid points need positions and invalid ones NaN")
        if self.unplaced not in ("", *UNPLACED):
            raise ValueError(f"FrameTrack: unplaced {self.unplaced!r} is none of {UNPLACED}")


def _events_px(pts: np.ndarray, bridged: np.ndarray, ambiguous: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Arc length (px) along a walk pts (M, 2) of each vertex, (M,), and of its ambiguities, sorted:
    the ``ambiguous`` (M,) vertices and both ends of each bridged gap longer than 2.5 px."""
    cum_px = arc_length(pts)
    gap = np.nonzero(bridged & (np.r_[0.0, np.diff(cum_px)] > 2.5))[0]
    return cum_px, np.sort(np.concatenate([cum_px[ambiguous], cum_px[gap - 1], cum_px[gap]]))


class FrameTracker:
    """Segmentation and centreline of single frames, given the background and calibration.

    Args:
        bg: (H, W) background; noise: (a, b) of sigma^2 = a + b B (:func:`build_background`).
        cal: the trial's :class:`Calibration`. campaign: gives L and n, and the arm's outline.
        st: tracking settings (:class:`~stringcast.core.TrackingSettings`).
    """

    def __init__(self, bg: np.ndarray, noise: tuple[float, float], cal: Calibration, campaign, st: TrackingSettings):
        self.bg, self.cal, self.st = bg, cal, st
        # noise sigma of the smoothed difference, per pixel (white noise through the Gaussian)
        k = 1.0 / (2 * math.sqrt(math.pi) * st.smooth_px) if st.smooth_px > 0.3 else 1.0
        self.sigma = (np.sqrt(noise[0] + noise[1] * np.clip(bg, 0, None)) * k).astype(np.float32)
        self.L, self.n, self.arm = campaign.string.length, campaign.string.n_points, campaign.arm
        self.s_targets = np.arange(1, self.n + 1) * self.L / self.n
        self.board = board_outline_px(cal, campaign.setup.board)

    def track(self, frame: np.ndarray, poses_px: np.ndarray) -> FrameTrack:
        """Track one frame (H, W); poses_px (P, J + 2, 2): the arm in px at P instants of the
        frame period, the middle one at the frame's time (its last row is the grasp)."""
        st, cal, n = self.st, self.cal, self.n
        gpx = poses_px[len(poses_px) // 2][-1]
        scale = float(cal.m_per_px(gpx[None])[0]) if np.all(np.isfinite(gpx)) else math.nan  # m per px near the grasp
        def none(path=None, mismatch=math.nan, cuts=(False, False), why="no_string"):  # no points (NaN): why not
            return FrameTrack(np.full((n, 2), np.nan), np.zeros(n, bool), np.zeros((0, 2)) if path is None else path,
                              mismatch, *cuts, unplaced=why)
        if not (math.isfinite(scale) and scale > 0):
            return none(why="no_view")   # the grasp maps to no place in the image (a mapping that degenerates there)
        R = (self.L + st.roi_margin_mm / 1000) / scale
        H, W = frame.shape
        x0, y0 = int(np.clip(gpx[0] - R, 0, W)), int(np.clip(gpx[1] - R, 0, H))
        x1, y1 = int(np.clip(gpx[0] + R + 1, 0, W)), int(np.clip(gpx[1] + R + 1, 0, H))
        if x1 - x0 < 8 or y1 - y0 < 8:
            return none(why="no_view")
        arm = draw_arm_mask((y1 - y0, x1 - x0), poses_px, self.arm, st, scale, (x0, y0))
        absd, fg = self._segment(frame[y0:y1, x0:x1].astype(np.float32), self.bg[y0:y1, x0:x1],
                                 self.sigma[y0:y1, x0:x1], arm)
        absd[arm] = 0.0  # the arm's own contrast must not pull the centreline
        if st.arm_guard_px >= 1:  # the arm's rim (blur, anti-aliasing) leaves slivers by the mask
            k = 2 * round(st.arm_guard_px) + 1
            arm = cv2.dilate(arm.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))) > 0
            fg &= ~arm
        g = np.array([gpx[1] - y0, gpx[0] - x0])  # grasp (row, col) in the ROI
        self._bg = self.bg[y0:y1, x0:x1]
        rho = st.grasp_clear_mm / 1000 / scale
        found = self._centreline(fg, g, st.grasp_search_mm / 1000 / scale, rho)
        if found is None:  # no walk from the grasp: the string may still come out from behind the arm
            return self._with_beyond(none(), absd, arm, np.zeros((0, 2)), cal.pixel_to_robot(gpx[None]), scale, (y0, x0))
        pts, bridged, branch, fold = found
        end = pts[-1].astype(int)
        off_image = bool(edge_cut(end + [y0, x0], (H, W), (0, 0), (H, W), self._width))
        cuts = (bool(edge_cut(end, arm.shape, (y0, x0), (H, W), self._width)) and not off_image, off_image)
        free_end = bool(not end_cut(end, arm, (y0, x0), (H, W), self._width) and np.hypot(*(end - g)) > 2 * rho
                        and clean_end(pts, self._skel, self._skel_at, absd, self._bg, st,
                                      st.end_touch_mm / 1000 / scale))
        hidden_start = np.hypot(*(pts[0] - g)) > rho + 3 or self._fallback
        behind = not free_end and near_arm(pts[-1], arm, self._width + 4)  # the string goes on behind the arm
        walked = pts
        loop_back = np.hypot(*(end - g)) <= 2 * rho  # the walk came back to the grasp
        pts, bridged, branch, free_end = self._refine(absd, pts, bridged, branch, fold, free_end)
        cum_px, ev_px = _events_px(pts, bridged, branch)
        pts, obs = decimate_path(pts, ~bridged[1:], st.arc_step_px, sub=4)
        head = hidden_arc(g, pts)  # grasp -> first visible vertex, under the gripper's mask
        px = np.vstack([head, pts])[:, ::-1] + [x0, y0]  # (x, y) image px, grasp first
        obs = np.concatenate([np.full(len(head), not hidden_start), obs]) & seen_segments(px, (x0, y0), arm.shape)
        xy = cal.pixel_to_robot(px)
        s_poly = arc_length(xy)
        L_head = float(s_poly[len(head)])
        s_dec = np.linspace(0.0, cum_px[-1], len(pts))
        events = np.interp(ev_px, s_dec, s_poly[len(head):])  # ambiguities, polyline arc (m)
        if hidden_start:
            events = np.r_[L_head, events]
        D = self.L - st.tip_shortfall_mm / 1000 - float(s_poly[-1])  # missing length if the end is the tip
        ratio = float(s_poly[-1]) / (self.L - st.tip_shortfall_mm / 1000)  # the seen length over L
        tol = self._anchor_tol(scale)
        slack = L_head - float(np.linalg.norm(xy[len(head)] - xy[0]))  # the head may be shorter, not below its chord
        lo, hi, shift, split, stretch, seen, arc = -np.inf, np.inf, 0.0, None, 1.0, False, None
        if free_end and len(events) and float(s_poly[-1]) - events[-1] < self.L / n:
            free_end = False  # a branch joins within a point spacing of the end: is the tip this end or the branch's?
        if free_end and abs(D) > tol and over_board(self.board, px[-1], self._width + 4):
            free_end = False  # a square of the string's shade may hide the rest: over the board, only the length says tip
        if free_end and abs(D) <= tol:  # both anchors agree: share the mismatch (head, visible arc, free end)
            split = mismatch_split(D, np.array([scale * st.end_sigma_px + slack, st.scale_sigma * (float(
                s_poly[-1]) - L_head), scale * st.end_sigma_px]))
            seen = not hidden_start and not len(events)
        elif free_end and -tol - slack < D <= st.max_missing_frac * self.L:  # anchored at the tip: valid after the last ambiguity
            shift, lo = D, (events[-1] if len(events) else (L_head if hidden_start else -np.inf))
            if D > tol:  # the missing length hides by the grasp (a loop at the fingers, under the arm's mask):
                lo = max(lo, L_head + D)  # the visible path's first D past the head may be that loop's
        elif free_end and not len(events) and -st.max_stretch_share * self.L <= D < 0:  # seen longer, no ambiguity:
            stretch = ratio  # a stretched string (or the scale off as much):
            seen = True
            # both ends anchor it, and its points lie at the same shares of the seen length as of L (uniform strain)
        elif not hidden_start and not self._head_clutter and not ((loop_back or free_end) and D > tol):  # anchored at the grasp: valid before the first ambiguity
            hi = events[0] if len(events) else np.inf
            if free_end:
                hi = min(hi, float(s_poly[-1]))
            arc = (xy, obs, hi) if st.mode == "markerless" else None   # a band's centre is where it is seen
        elif behind:  # the grasp's side holds no point: only the stretch beyond the arm may
            return self._with_beyond(none(px, cuts=cuts, why="behind_arm"), absd, arm, walked, xy, scale, (y0, x0))
        else:  # no anchor: with a free end, a string seen longer or shorter than L (its mismatch kept)
            return none(px, D if free_end and not hidden_start else math.nan, cuts, "no_anchor")
        s_t = self.s_targets * stretch - shift  # the targets' polyline arc
        if split is not None:  # model arc -> polyline arc: knots at the head's end and at the free end
            end = self.L - st.tip_shortfall_mm / 1000 - split[2]
            s_t = np.interp(self.s_targets, [0.0, L_head + split[0], end], [0.0, L_head, float(s_poly[-1])])
            s_t = np.where(self.s_targets > end, float(s_poly[-1]) + self.s_targets - end, s_t)
        pos, valid = resample_by_arc(xy, obs, s_t, st.end_tolerance_mm / 1000 if free_end else 0.0)
        trusted = (s_t >= max(lo, 0.0)) & (s_t <= hi) & (self.s_targets >= 0)
        valid &= trusted
        if st.mode == "markers":  # the bands' centres, where the order along the path is trusted
            pos, valid = band_points(frame, px, obs & (np.arange(len(obs)) >= len(head)), s_poly, s_t, trusted,
                                     free_end, path_contrast(absd, pts), cal, st)
        pos[~valid] = np.nan
        done = FrameTrack(pos, valid, px, D if free_end and not hidden_start else math.nan, *cuts, stretch,
                          stretch_seen=seen, grasp_arc=arc,
                          seen_ratio=ratio if seen else math.nan)
        return self._with_beyond(done, absd, arm, walked, xy, scale, (y0, x0)) if behind else done

    def _with_beyond(self, done: FrameTrack, absd, arm, walked, xy, scale: float, origin) -> FrameTrack:
        """``done`` (the grasp's side, its walk ``walked`` (M, 2) ROI px ending by the arm, its polyline xy
        (K, 2) m) with the points of the string's stretch beyond the arm (:mod:`stringcast.track.beyond_arm`),
        anchored at its free end: point s_i lies L - s_i back from the tip. None are taken (``done`` as it
        is) without exactly one such stretch, in markers mode, or when the stretch, the grasp's side
        and the straight line between them are together longer than the string (+ the anchor tolerance)."""
        st, n = self.st, self.n
        found = None if st.mode != "markerless" or self._skel is None else tip_stretch(
            self._skel, self._skel_at, walked, arm, absd, self._bg, self._width, st, st.end_touch_mm / 1000 / scale,
            self.L / n / scale)
        if found is None or over_board(self.board, found[0][-1, ::-1] + origin[::-1], self._width + 4):
            return done  # no stretch, or its end over the board (a square may hide the rest)
        if edge_cut(found[0][-1], arm.shape, origin, self.bg.shape, self._width):
            return done  # its end by the image's or the ROI's edge: the string may go on past it
        pts, bridged, amb = found
        pts, bridged, amb, free_end = self._refine(absd, pts, bridged, amb, np.zeros(len(pts), bool), True)
        if not free_end:
            return done
        cum_px, ev_px = _events_px(pts, bridged, amb)
        ev_px = np.r_[0.0, ev_px]  # the rim the stretch comes out of is an ambiguity too
        pts, obs = decimate_path(pts, ~bridged[1:], st.arc_step_px, sub=4)
        px = pts[:, ::-1] + [origin[1], origin[0]]  # (x, y) image px, from the arm's rim to the tip
        obs = obs & seen_segments(px, (origin[1], origin[0]), arm.shape)
        far = self.cal.pixel_to_robot(px)
        s_poly = arc_length(far)
        last = float(np.max(np.interp(ev_px, np.linspace(0.0, cum_px[-1], len(pts)), s_poly)))
        D = self.L - st.tip_shortfall_mm / 1000 - float(s_poly[-1])  # the length before the stretch
        tol = self._anchor_tol(scale)
        if float(s_poly[-1]) - last < self.L / n or D < arc_length(xy)[-1] + float(np.linalg.norm(far[0] - xy[-1])) - tol:
            return done  # a branch by the tip (which end is the tip?), or more string than there is
        s_t = self.s_targets - D
        pos, valid = resample_by_arc(far, obs, s_t, st.end_tolerance_mm / 1000)
        valid &= (s_t >= last) & ~done.valid
        positions = np.where(valid[:, None], pos, done.positions)
        path = np.vstack([done.path_px, px]) if len(done.path_px) else px
        return FrameTrack(positions, valid | done.valid, path, math.nan, done.past_roi, done.off_image,
                          grasp_arc=done.grasp_arc, tip_arc=(far, obs, last, self.L - D, st.end_tolerance_mm / 1000)
                          if done.grasp_arc is not None or not done.valid.any() else None)

    def _anchor_tol(self, scale: float) -> float:
        """How far (m) a walk's length may miss L and its free end still be the tip: ``anchor_tol_mm``,
        1 % of L or ``anchor_tol_px`` (both ends +-1 px) at ``scale`` m/px, whichever is largest."""
        st = self.st
        return max(st.anchor_tol_mm / 1000, 0.01 * self.L, st.anchor_tol_px * scale)

    def _refine(self, absd, pts, bridged, branch, fold, free_end):
        """Sub-pixel centreline of a walk (M, 2) (row, col); a free end moved to the string's end (or a
        clay ball's centre) and dropped if string-like contrast goes on past it; spurs within two
        widths of a free end are its lump's, others mark the path (``fold``) as ambiguous.
        Returns pts, bridged, branch (ambiguous) and free_end."""
        st = self.st
        pts = odd_smooth(refine_centreline(absd, pts), 1.5, twice=True)
        if free_end:  # the skeleton stops short of a free end: move the end to the string's end
            fe = locate_end(absd, pts)
            free_end = not string_continues(absd, pts, fe.edge, fe.tangent, self._width, st.end_contrast_min)
        if free_end:  # a spur within two widths of a free end is its lump's (a clay ball forks the skeleton)
            cum_px = arc_length(pts)
            fold = fold & (cum_px < cum_px[-1] - 2 * self._width)
        branch = branch | fold
        ball = fe.ball if free_end else None
        if ball is not None:  # a ball's centre, from its contrast (the walk ends on either spur of its fork)
            k = len(pts) - int(np.argmax(np.hypot(*(pts[::-1] - ball[0]).T) > ball[1]))
            pts, bridged, branch = np.vstack([pts[:k], ball[0]]), np.r_[bridged[:k], False], np.r_[branch[:k], False]
        elif free_end and fe.extension > 0.05:
            t = pts[-1] - pts[-2]
            pts = np.vstack([pts, pts[-1] + fe.extension * t / max(float(np.hypot(*t)), 1e-9)])
            bridged = np.r_[bridged, False]
            branch = np.r_[branch, False]
        return pts, bridged, branch, free_end

    def _segment(self, img: np.ndarray, bg: np.ndarray, sigma: np.ndarray, arm: np.ndarray):
        """Smoothed |I - g B| (gain g for flicker) and its hysteresis foreground outside the arm."""
        st = self.st
        sub = (slice(None, None, 3), slice(None, None, 3))
        use = (bg[sub] > 10) & ~arm[sub]
        gain = float(np.median(img[sub][use] / bg[sub][use])) if use.sum() > 100 else 1.0
        diff = img - gain * bg
        if st.smooth_px > 0:
            diff = cv2.GaussianBlur(diff, (0, 0), st.smooth_px)
        absd = np.abs(diff)
        # the noise model comes from the still frames before the motion; a lossy codec that
        # codes a still scene identically, light drift or compression around moving things
        # leave it far below the differences the moving frames show. The frame's own robust
        # spread of the difference (MAD, the string and arm being a small share of the ROI) is
        # a floor under it.
        r = diff[sub][use] if use.sum() > 100 else diff[sub].ravel()
        floor = 1.4826 * float(np.median(np.abs(r - np.median(r)))) if r.size else 0.0
        z = absd / np.maximum(np.maximum(sigma * math.sqrt(max(gain, 1e-3)), floor), 0.05)
        weak = (z > st.threshold_low) & ~arm
        nlab, lab = cv2.connectedComponents(weak.astype(np.uint8), connectivity=8)
        keep = np.zeros(nlab, bool)
        keep[lab[weak & (z > st.threshold_high)]] = True
        keep[0] = False
        return absd, keep[lab]

    def _centreline(self, fg: np.ndarray, g: np.ndarray, r0: float, rho: float):
        """Skeleton path from near the grasp g (row, col): (M, 2) (row, col), and (M,) bool each of
        bridged, ambiguous (a branch joins) and folded (a spur joins); or None.

        Seeds: the skeleton pixel nearest the grasp in each skeleton component within r0 px
        (at most 6), and up to 4 of the component's pixels just outside rho (a string that leaves
        the fingers in a short hook: the nearest pixel's walk takes the hook); the longest walk
        wins, a walk from outside rho only if it is longer by 2 rho than the nearest pixel's.
        When the nearest pixel's walk ends within r0 of the grasp (a stub: the string hooks off
        the fingers and back along itself in one skeleton path, or a sliver of the fingers), the
        walk from the stub's tip back past the grasp competes as a ring pixel's: the string's
        start is then not seen joining the grasp (taken as the string, generalization seed 11's
        sliver put every point 20-30 mm along the string). A walk is cut where it comes
        closest to the grasp (dropping detours along slivers of the gripper's rim), then its
        vertices within rho px of the grasp are dropped (there the string mixes with the
        fingertips).
        """
        self._skel = None  # no skeleton in this frame (yet)
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
        return None if found is None else (found[0] + b, *found[1:])

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
        best, zones = None, Zones(skel, self._width, int(self.st.branch_min_px))
        for pair in sorted(seeds, key=lambda p: dist[p[0]])[:6]:
            penalty = 0.0   # once the nearest pixel's walk leaves the clear zone, a ring pixel's must beat it
            for fallback, c in enumerate(pair):   # by 2 rho (a hook at the fingertips caught the first walk)
                d0 = np.array([sy[c], sx[c]], float) - g
                walk = walk_skeleton(skel, (sy[c], sx[c]), self.st.max_gap_px, d0 if np.hypot(*d0) >= 1 else None,
                                     zones=zones)
                walks, end = [(walk, fallback)], walk[0][-1]
                if fallback == 0 and len(walk[0]) > 2 and np.hypot(*(end - g)) <= r0:  # a stub by the grasp: the
                    walks.append((walk_skeleton(  # string may hook off and back along itself, or the stub is a
                        skel, tuple(end.astype(int)), self.st.max_gap_px, None, zones=zones), 1))  # sliver
                for (pts, bridged, amb, fold, passed), fb in walks:
                    cum = arc_length(pts)
                    head = np.nonzero(cum <= 2 * r0)[0]
                    j0 = int(head[np.argmin(np.hypot(*(pts[head] - g).T))])
                    far = np.nonzero(np.hypot(*(pts[j0:] - g).T) >= rho)[0]
                    if len(far) == 0:
                        continue
                    j1 = j0 + int(far[0])
                    score = cum[-1] - cum[j1] - (penalty if fb else 0.0)
                    if best is None or score > best[2]:
                        b = bridged[j1:].copy()
                        b[0] = False
                        best = (pts[j1:], b, score, pts, fb, amb, passed, fold)
                    if not fb:
                        penalty = 2 * rho
        if best is None:
            return None
        walk = best[3].astype(int)
        self._fallback = bool(best[4])  # the string's start is then not seen joining the grasp
        if best[4]:  # the walk skipped a tangle at the fingertips: not a branch
            skel = skel.astype(np.uint8)
            cv2.circle(skel, (round(g[1]), round(g[0])), round(rho + 1), 0, -1)
        ev = branch_vertices((skel > 0) & ~best[6], walk, int(self.st.branch_min_px)) | best[5]
        # a branch joining the walk near the grasp: a loop there, the ordering is ambiguous; a fold there
        head = np.hypot(*(walk - g).T) <= 2 * rho  # (a spur) is the fingertips' tangle, or the loop at
        self._head_clutter = bool(np.any(ev & head))  # the fingers that a missing length is anchored for
        k = len(best[3]) - len(best[0])
        return best[0], best[1], ev[k:], (best[7] & ~head & ~ev)[k:]

