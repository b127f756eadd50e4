"""Marker mode of tracking: bands on the string at the mass points, found along the centreline.

For strings that carry a band (a short sleeve of tape, another colour or shade than the
string) centred at each of the model's mass points i = 1..n (arc s_i = i L / n from the
grasp; the tip's band covers the string's last half band width and ends at the tip).
Cameras are mono, so a band is a stretch of the string whose grey level differs from the
string's own, brighter or darker. ``tracking.mode: markers`` (:mod:`stringcast.track.tracking`)
finds the markerless centreline as usual and then, per frame (:func:`band_points`):

1. samples the frame along the centreline every ``band_step_px`` of arc, averaging across it
   over -0.5, 0, +0.5 px (weights 1, 2, 1; bilinear) (:func:`centreline_profile`);
2. subtracts the profile's running median over 4 band widths (taken over the seen stretch
   only: the hidden head under the gripper and bridged gaps are left out);
3. finds runs whose residual exceeds ``band_contrast_min`` x the string's contrast against
   the background, for the polarity that gives more well-formed runs (or the one set by
   ``band_polarity``), and measures each at half its peak: its two edges, interpolated
   between samples, give its centre and length (:func:`find_band_runs`);
4. assigns runs to points in order from the grasp (:func:`assign_bands`): point i takes
   the run within ``band_tolerance`` x the point spacing of its expected arc position; it is
   valid only if that run is the only one there, is whole (not cut by an occluder, a gap,
   the image's edge or the path's end) and its length is the band's within
   ``band_length_tol``. A tip band (i = n) reaching a *free* end (within 1.5 px) is valid when its
   length is half a band's within the same tolerance; the tip is half a band width past its
   near edge along the path (extrapolated past the path's end if need be).

Invalid points have NaN positions: a hidden, blurred, cut or doubtful band is never
guessed. The expected positions and which points the order along the path can be trusted
for come from the markerless anchoring (tracking's step 5); a band replaces only the
arc-length estimate of a point's position. A band's image position goes through the
calibration as it is: a local calibration offset is not cancelled along the string as it is
for the markerless arc, anchored at the grasp from the forward kinematics (the tiny lab
render of tests/test_markers.py: 0.10 px median in the image, but 0.94 mm in the robot
frame against the markerless 0.75 mm, its calibration being ~0.7 px off there). Limits: the
string must be wide enough (about 2 px) for its centre pixels to show its own shade, and a
lump (clay, a pipe's end) at a band's place looks like a band.
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates, median_filter

from .centreline import arc_length
from stringcast.core import POLARITIES, TrackingSettings



def centreline_profile(image: np.ndarray, path_px: np.ndarray, step_px: float = 0.25):
    """Grey level along a centreline, sampled every ``step_px`` of its arc.

    Args:
        image: (H, W) frame (any real dtype). path_px: (M, 2) centreline (x, y) image px, M >= 2.
        step_px: sample spacing along the path, px (> 0).

    Returns:
        t (K,) sample arc along the path from path_px[0], px; value (K,) grey level (mean
        across the path at -0.5, 0, +0.5 px, weights 1, 2, 1; bilinear); seg (K,) int, the
        path segment each sample lies on.

    Raises:
        ValueError: a path of fewer than 2 vertices or a step <= 0.
    """
    path_px = np.asarray(path_px, float)
    if path_px.ndim != 2 or path_px.shape[1] != 2 or len(path_px) < 2 or not step_px > 0:
        raise ValueError(f"centreline_profile: path {path_px.shape}, step {step_px}: need (M >= 2, 2) and step > 0")
    cum = arc_length(path_px)
    t = np.arange(0.0, cum[-1] + 1e-9, step_px)
    seg = np.clip(np.searchsorted(cum, t, side="right") - 1, 0, len(path_px) - 2)
    d = path_px[seg + 1] - path_px[seg]
    ln = np.hypot(*d.T)
    a = np.where(ln > 0, (t - cum[seg]) / np.maximum(ln, 1e-12), 0.0)
    p = path_px[seg] + a[:, None] * d
    nrm = np.column_stack([-d[:, 1], d[:, 0]]) / np.maximum(ln, 1e-12)[:, None]
    img = np.asarray(image, np.float32)
    value = np.zeros(len(t))
    for off, w in ((-0.5, 0.25), (0.0, 0.5), (0.5, 0.25)):
        q = p + off * nrm
        value += w * map_coordinates(img, [q[:, 1], q[:, 0]], order=1, mode="nearest")
    return t, value, seg


def _half_max_run(r: np.ndarray, ok: np.ndarray, peak: int, step: float):
    """Edges (px, sample arc) where r falls to half r[peak] on each side, and whether each
    side is cut (a sample not ``ok`` or the profile's end reached first)."""
    half = 0.5 * r[peak]
    edges, cut = [], []
    for sgn in (-1, 1):
        j = peak
        while 0 <= j + sgn < len(r) and ok[j + sgn] and r[j + sgn] >= half:
            j += sgn
        k = j + sgn
        if not (0 <= k < len(r)) or not ok[k]:
            edges.append(j * step)
            cut.append(True)
            continue
        f = (r[j] - half) / max(r[j] - r[k], 1e-12)  # linear between samples j and k
        edges.append((j + sgn * f) * step)
        cut.append(False)
    return edges[0], edges[1], cut[0], cut[1]


def running_median(v: np.ndarray, window: int) -> np.ndarray:
    """Median of v (K,) over ``window`` samples centred on each (odd; shortened at the ends, not padded:
    a padded end would repeat a band lying there)."""
    h = max(0, int(window) // 2)
    if h == 0 or len(v) < 2:
        return np.asarray(v, float).copy()
    out = median_filter(v, size=2 * h + 1, mode="nearest")
    for k in list(range(min(h, len(v)))) + list(range(max(h, len(v) - h), len(v))):
        out[k] = np.median(v[max(0, k - h):k + h + 1])
    return out


def find_band_runs(value: np.ndarray, seen: np.ndarray, step_px: float, window: int, threshold: float,
                   polarity: str = "auto"):
    """Band runs in a centreline profile: stretches brighter or darker than the running median.

    Args:
        value: (K,) grey level along the path (:func:`centreline_profile`). seen: (K,) bool,
            samples on the string's seen stretch (others are skipped and cut runs).
        step_px: sample spacing, px. window: running-median length, samples (odd is best).
        threshold: least |residual| of a run, grey levels (> 0).
        polarity: ``auto`` (the sign with more runs whose length is plausible is taken by the
            caller: both are returned), ``brighter`` or ``darker``.

    Returns:
        dict sign (+1 brighter, -1 darker) -> (R, 5) array of runs: left edge, right edge
        (px of sample arc, at half the run's peak residual), peak residual (> 0, grey
        levels), cut at the left, cut at the right (0/1). Runs are in arc order.

    Raises:
        ValueError: an unknown polarity, mismatched shapes, or threshold <= 0.
    """
    if polarity not in POLARITIES:
        raise ValueError(f"band_polarity must be one of {POLARITIES}, got {polarity!r}")
    value, seen = np.asarray(value, float), np.asarray(seen, bool)
    if value.shape != seen.shape or value.ndim != 1 or not threshold > 0:
        raise ValueError(f"find_band_runs: value {value.shape}, seen {seen.shape}, threshold {threshold}")
    resid = np.zeros(len(value))
    idx = np.nonzero(seen)[0]
    if len(idx):
        v = value[idx]
        resid[idx] = v - running_median(v, int(window))
    signs = {"auto": (1, -1), "brighter": (1,), "darker": (-1,)}[polarity]
    out = {}
    for sign in signs:
        r = sign * resid
        above = seen & (r > threshold)
        runs, last_right = [], -np.inf
        starts = np.nonzero(above & ~np.r_[False, above[:-1]])[0]
        ends = np.nonzero(above & ~np.r_[above[1:], False])[0]
        for a, b in zip(starts, ends):
            peak = a + int(np.argmax(r[a:b + 1]))
            left, right, cl, cr = _half_max_run(r, seen, peak, step_px)
            if left <= last_right:  # the same half-maximum run reached from two threshold runs
                continue
            runs.append((left, right, r[peak], cl, cr))
            last_right = right
        out[sign] = np.array(runs, float).reshape(-1, 5)
    return out


def assign_bands(centres: np.ndarray, whole: np.ndarray, expected: np.ndarray, tol: float) -> np.ndarray:
    """Which run each point takes, in order from the grasp.

    Args:
        centres: (R,) runs' arc positions. whole: (R,) bool, runs that are a well-formed band
            (right length, not cut). expected: (n,) the points' expected arc positions,
            increasing, same unit. tol: how far a run may lie from its point's expected position.

    Returns:
        (n,) int: the index of the run point i takes, -1 where none is found or it is
        ambiguous (two runs within tol, a run within tol of two points, or a malformed run).
    """
    centres, whole, expected = np.asarray(centres, float), np.asarray(whole, bool), np.asarray(expected, float)
    near = np.abs(centres[None, :] - expected[:, None]) <= tol  # (n, R)
    take = np.full(len(expected), -1)
    for i in range(len(expected)):
        cand = np.nonzero(near[i])[0]
        if len(cand) == 1 and whole[cand[0]] and near[:, cand[0]].sum() == 1:
            take[i] = cand[0]
    return take


def find_bands(image: np.ndarray, path_px: np.ndarray, seen_seg: np.ndarray, s_path: np.ndarray,
               expected: np.ndarray, band_width: float, contrast: float, st: TrackingSettings,
               free_end: bool = False):
    """Band centres for the points, along one frame's centreline (image px in, image px out).

    Args:
        image: (H, W) frame. path_px: (M, 2) centreline (x, y) px, grasp first.
        seen_seg: (M - 1,) bool, segments where the string itself is seen (not the hidden
            head, not a bridged gap). s_path: (M,) the path vertices' arc positions in the
            unit u of the model's arc (m in tracking; px works too), increasing.
        expected: (n,) the points' expected positions on that arc, u. band_width: the bands'
            length along the string, u. contrast: the string's contrast against the
            background, grey levels (the threshold is ``band_contrast_min`` x it).
        st: tracking settings (:class:`~stringcast.core.TrackingSettings`): ``band_contrast_min``,
            ``band_tolerance`` (x the points' spacing),
            ``band_length_tol``, ``band_polarity``, ``band_step_px``.
        free_end: the path's last vertex is the string's free end (the tip).

    Returns:
        (n, 2) band centres (x, y) px, NaN where invalid, and (n,) valid.

    Raises:
        ValueError: bad shapes, a band width <= 0, or bands longer than half their spacing
            (the running median needs the string's own shade to dominate 4 band widths).
            A contrast <= 0 finds nothing (all invalid).
    """
    path_px, s_path, expected = np.asarray(path_px, float), np.asarray(s_path, float), np.asarray(expected, float)
    n = len(expected)
    pos, valid = np.full((n, 2), np.nan), np.zeros(n, bool)
    if len(path_px) != len(s_path) or len(seen_seg) != len(path_px) - 1 or not band_width > 0:
        raise ValueError(f"find_bands: path {path_px.shape}, s_path {s_path.shape}, seen {np.shape(seen_seg)}, "
                         f"band width {band_width}")
    spacing = float(np.median(np.diff(expected))) if n >= 2 else (abs(float(expected[0])) if n else np.inf)
    if band_width > 0.5 * spacing:
        raise ValueError(f"find_bands: bands {band_width:.4g} long at a spacing of {spacing:.4g}: at most half of it")
    if len(path_px) < 2 or not contrast > 0 or n == 0:
        return pos, valid
    step = float(st.band_step_px)
    t, value, seg = centreline_profile(image, path_px, step)
    cum_px = arc_length(path_px)
    s_t = np.interp(t, cum_px, s_path)  # samples' arc in u
    u_per_px = (s_path[-1] - s_path[0]) / max(cum_px[-1], 1e-12)
    window = int(round(4 * band_width / max(u_per_px, 1e-12) / step)) | 1
    runs = find_band_runs(value, np.asarray(seen_seg, bool)[seg], step, window,
                          float(st.band_contrast_min) * contrast, st.band_polarity)
    lt = float(st.band_length_tol)
    best = None
    for _sign, rr in runs.items():
        left, right = (np.interp(rr[:, k], t, s_t) for k in (0, 1))
        length = right - left
        whole = (rr[:, 3] == 0) & (rr[:, 4] == 0) & (np.abs(length - band_width) <= lt * band_width)
        centre = 0.5 * (left + right)
        tip = np.zeros(len(rr), bool)
        if free_end and len(rr):  # a tip band ends at the free end: there its far edge is the tip
            at_end = (rr[:, 3] == 0) & (rr[:, 1] >= t[-1] - 1.5)  # reaching the end (fading within 1.5 px)
            tip = at_end & (np.abs(length - band_width / 2) <= lt * band_width / 2)
            centre = np.where(at_end, right, centre)
            whole = (whole & ~at_end) | tip  # a run reaching a free end is the tip's band or nothing
        score = (int(whole.sum()), float(rr[whole, 2].sum()) if len(rr) else 0.0)
        if best is None or score > best[0]:
            best = (score, centre, whole, tip, rr)
    _, centre, whole, tip, rr = best
    take = assign_bands(centre, whole, expected, float(st.band_tolerance) * spacing)
    for i, k in enumerate(take):
        if k < 0 or (tip[k] and i != n - 1):  # a run cut by the end belongs to the tip only
            continue
        c_px = 0.5 * (rr[k, 0] + rr[k, 1])
        if tip[k]:  # the tip: half a band width past the band's near edge (extrapolated past the path's end)
            c_px = rr[k, 0] + band_width / 2 / max(u_per_px, 1e-12)
        j = int(np.clip(np.searchsorted(cum_px, c_px, side="right") - 1, 0, len(path_px) - 2))
        d = path_px[j + 1] - path_px[j]
        pos[i] = path_px[j] + (c_px - cum_px[j]) / max(float(np.hypot(*d)), 1e-12) * d
        valid[i] = True
    return pos, valid


def path_contrast(contrast_img: np.ndarray, path_rc: np.ndarray) -> float:
    """Median of a contrast image (H, W) (tracking's smoothed |I - g B|) at path pixels (M, 2)
    (row, col), rounded down and clipped into the image: the string's contrast, grey levels."""
    ij = np.clip(np.asarray(path_rc).astype(int), 0, np.array(contrast_img.shape) - 1)
    return float(np.median(contrast_img[ij[:, 0], ij[:, 1]])) if len(ij) else 0.0


def band_points(frame: np.ndarray, path_px: np.ndarray, seen_seg: np.ndarray, s_path: np.ndarray,
                expected: np.ndarray, trusted: np.ndarray, free_end: bool, contrast: float, cal, st: TrackingSettings):
    """Marker mode's points for one frame, in the robot frame (the hook in ``FrameTracker.track``).

    Args:
        frame: (H, W) image. path_px: (M, 2) the tracked centreline (x, y) px, grasp first.
        seen_seg: (M - 1,) bool, segments where the string is seen. s_path: (M,) the path's
            arc from the grasp, m (the robot-frame polyline's). expected: (n,) where the points
            should lie on that arc, m (the markerless anchoring's targets). trusted: (n,) bool,
            points for which the markerless anchoring trusts the order along the path.
        free_end: the path ends at the string's free end. contrast: the string's contrast
            against the background along the path, grey levels. cal: :class:`Calibration`.
        st: tracking settings (``band_width_mm`` and :func:`find_bands`'s).

    Returns:
        (n, 2) positions, m (NaN where invalid) and (n,) valid.
    """
    px, valid = find_bands(frame, path_px, seen_seg, s_path, expected, float(st.band_width_mm) / 1000,
                           contrast, st, free_end)
    valid &= np.asarray(trusted, bool)
    pos = np.full(px.shape, np.nan)
    if valid.any():
        pos[valid] = cal.pixel_to_robot(px[valid])
    return pos, valid
