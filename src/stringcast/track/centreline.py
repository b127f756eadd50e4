"""Centreline geometry of one frame's string: skeleton walk, sub-pixel refinement, arc resampling.

Plain functions on arrays used by :mod:`stringcast.track.tracking` (steps 4-5 of its pipeline),
NumPy/SciPy; the skeleton walk is in :mod:`stringcast.track.skeleton_walk` (pixel by pixel, numba)
and :mod:`stringcast.track.junctions` (the choice at crossings).
"""
from __future__ import annotations

import math

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter1d, map_coordinates


from .skeleton_walk import trace_path  # noqa: F401 (part of this module's interface)


def odd_smooth(p: np.ndarray, sigma: float, twice: bool = False) -> np.ndarray:
    """Gaussian smoothing along a path with odd (point-reflected) ends, so ends do not shrink.

    With ``twice`` the smoothed residual is added back (Tukey's twicing, the filter 2G - G^2):
    noise is still smoothed, but a bend of radius r is no longer pulled inward by ~ sigma^2 / (2 r)
    (on a loop of 5 px radius with sigma 1.5 px that made its length 4 % short).
    """
    k = int(min(len(p) - 1, math.ceil(3 * sigma)))
    if k < 1 or sigma <= 0:
        return p
    pad = np.concatenate([2 * p[0] - p[k:0:-1], p, 2 * p[-1] - p[-2:-k - 2:-1]])
    out = gaussian_filter1d(pad, sigma, axis=0, mode="nearest")[k:k + len(p)]
    return out + odd_smooth(p - out, sigma) if twice else out


def refine_centreline(absdiff: np.ndarray, pts: np.ndarray, half_width: float = 3.0) -> np.ndarray:
    """Move path points (M, 2) (row, col) to the weighted centroid of ``absdiff`` across the path."""
    if len(pts) < 3:
        return pts
    sm = odd_smooth(pts, 2.0)
    tan = np.gradient(sm, axis=0)
    tan /= np.linalg.norm(tan, axis=1, keepdims=True) + 1e-12
    nrm = np.column_stack([-tan[:, 1], tan[:, 0]])
    offs = np.arange(-half_width, half_width + 1e-9, 0.5)
    samp = pts[:, None, :] + offs[None, :, None] * nrm[:, None, :]
    prof = map_coordinates(absdiff, [samp[..., 0].ravel(), samp[..., 1].ravel()], order=1, mode="nearest")
    prof = prof.reshape(len(pts), len(offs))
    w = np.clip(prof - np.min(prof, axis=1, keepdims=True), 0, None)
    shift = (w @ offs) / np.maximum(w.sum(axis=1), 1e-12)
    return pts + np.clip(shift, -half_width, half_width)[:, None] * nrm


def hidden_arc(g: np.ndarray, pts: np.ndarray, n: int = 8) -> np.ndarray:
    """Vertices (n, 2) from the grasp g up to (not including) pts[0] along a circular arc.

    The string's first part is hidden under the gripper's mask; the arc through g that
    arrives at the first visible vertex along the path's tangent there is its
    constant-curvature estimate (length chord * a / sin a, a = angle between chord and
    tangent, capped at 100 deg): a straight chord would be short where the string bends
    around the fingertips.
    """
    c = pts[0] - g
    chord = float(np.hypot(*c))
    if len(pts) < 3 or chord < 1e-6:
        return g[None].astype(float)
    t = pts[1] - pts[0]
    a = math.atan2(c[0] * t[1] - c[1] * t[0], c @ t)
    a = float(np.clip(a, -math.radians(100), math.radians(100)))
    if abs(a) < 1e-3:
        return g + np.outer(np.arange(n) / n, c)
    length = chord * a / math.sin(a)
    z0 = complex(c[0], c[1]) / chord * complex(math.cos(-a), math.sin(-a))  # start direction
    k = 2 * a / length
    s = np.arange(n) / n * length
    z = z0 * (np.exp(1j * k * s) - 1) / (1j * k)
    return g + np.column_stack([z.real, z.imag])


def arc_length(pts: np.ndarray) -> np.ndarray:
    """Cumulative arc length along a polyline: pts (M, 2) -> (M,), 0 at pts[0], in pts' units."""
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])


def decimate_path(pts: np.ndarray, observed: np.ndarray, step: float, sub: int = 1):
    """Vertices every ``step`` px of arc along a dense path (first and last kept).

    Arc length summed over ~1 px steps grows with the centreline's lateral noise (by about
    the mean of (dx / ds)^2 / 2); chords ``step`` px long are insensitive to it, but cut bends:
    a chord c on a radius r is short by c^2 / (24 r^2) (0.07 % for 4 px on 30 px, 2.7 % on a
    5 px loop). With ``sub`` > 1 the vertices are joined by cubic Hermite pieces (tangents along
    the neighbours' chord, as long as the arc between vertices), sampled ``sub`` times per chord
    instead, which follow the bend (0.7 % short on that loop, ends included).

    Args:
        pts: (M, 2) dense path. observed: (M - 1,) bool per segment. step: px. sub: >= 1.

    Returns:
        (K, 2) vertices and (K - 1,) observed (a decimated segment is observed only if
        every dense segment it spans is; a spline's pieces as their chord).
    """
    if len(pts) < 3 or step <= 0:
        return pts, observed
    cum = arc_length(pts)
    n = max(1, round(cum[-1] / step))
    s = np.linspace(0.0, cum[-1], n + 1)
    out = np.column_stack([np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])])
    bad = np.concatenate([[0], np.cumsum(~np.asarray(observed, bool))])  # unobserved segments before vertex j
    ja = np.clip(np.searchsorted(cum, s[:-1], side="right") - 1, 0, len(pts) - 2)
    jb = np.clip(np.searchsorted(cum, s[1:], side="left"), 1, len(pts) - 1)
    obs = bad[jb] - bad[ja] == 0
    if sub <= 1 or len(out) < 3:
        return out, obs
    tan = np.gradient(out, axis=0)  # Catmull-Rom directions; lengths: the arc between vertices
    tan *= (cum[-1] / n) / np.maximum(np.hypot(*tan.T), 1e-12)[:, None]
    t = (np.arange(sub) / sub)[None, :, None]
    p0, p1, m0, m1 = out[:-1, None], out[1:, None], tan[:-1, None], tan[1:, None]
    h = ((2 * t ** 3 - 3 * t ** 2 + 1) * p0 + (t ** 3 - 2 * t ** 2 + t) * m0 + (-2 * t ** 3 + 3 * t ** 2) * p1
         + (t ** 3 - t ** 2) * m1)
    return np.vstack([h.reshape(-1, 2), out[-1:]]), np.repeat(obs, sub)


def resample_by_arc(xy: np.ndarray, observed_seg: np.ndarray, s_targets: np.ndarray, end_tol: float = 0.0):
    """Points at increasing arc lengths ``s_targets`` (K,) m along a polyline xy (M, 2) m.

    Args:
        observed_seg: (M - 1,) bool, False for bridged (unobserved) segments.
        end_tol: the last target (the tip) may lie up to this far past the polyline's end
            and then takes the end point (a skeleton stops about half a width short of a
            free end); every other target must lie on the polyline.

    Returns:
        (K, 2) positions (NaN where invalid) and (K,) valid.
    """
    seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    out = np.full((len(s_targets), 2), np.nan)
    valid = np.zeros(len(s_targets), bool)
    if len(xy) < 2:
        return out, valid
    for i, st in enumerate(s_targets):
        if st > s[-1] + (end_tol if i == len(s_targets) - 1 else 0.0):
            continue
        st = min(st, s[-1])
        j = int(np.clip(np.searchsorted(s, st, side="right") - 1, 0, len(seg) - 1))
        if not observed_seg[j]:
            continue
        a = (st - s[j]) / max(seg[j], 1e-12)
        out[i] = xy[j] + a * (xy[j + 1] - xy[j])
        valid[i] = True
    return out, valid


def branch_vertices(skel: np.ndarray, walk: np.ndarray, min_branch_px: int) -> np.ndarray:
    """Vertices of a skeleton walk where another skeleton branch of >= ``min_branch_px`` px joins.

    Such a vertex is a junction the walk went straight through: a crossing of the string
    with itself (or with something else), where the ordering along the string is ambiguous.
    Short spurs (noise, the rim of a clay lump) are ignored.

    Args:
        skel: (H, W) bool skeleton. walk: (M, 2) int (row, col) pixels of the walk.

    Returns:
        (M,) bool.
    """
    rest = skel.copy()
    r, c = walk[:, 0].astype(int), walk[:, 1].astype(int)
    rest[r, c] = False
    _nlab, lab, stats, _ = cv2.connectedComponentsWithStats(rest.astype(np.uint8), connectivity=8)
    big = stats[:, cv2.CC_STAT_AREA] >= min_branch_px
    big[0] = False
    near = np.zeros(len(walk), bool)  # a big branch pixel in the walk vertex's 3x3 neighbourhood
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            rr, cc = r + dr, c + dc
            ok = (rr >= 0) & (rr < lab.shape[0]) & (cc >= 0) & (cc < lab.shape[1])
            near[ok] |= big[lab[rr[ok], cc[ok]]]
    return near


def mismatch_split(D: float, sigmas) -> np.ndarray:
    """Share a length mismatch D (m) among independent parts by their variances (least squares).

    The string's measured length (hidden head + visible centreline + free-end extension)
    should equal L; with both ends observed the difference D is their joint error. The
    minimum-norm correction sum_i d_i^2 / sigma_i^2 subject to sum_i d_i = D is
    d_i = D sigma_i^2 / sum_j sigma_j^2.

    Args:
        D: mismatch, m. sigmas: (K,) each part's length uncertainty, m (>= 0; all zero: equal shares).

    Returns:
        (K,) corrections d_i, m, summing to D.
    """
    v = np.square(np.asarray(sigmas, float))
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        raise ValueError(f"mismatch_split: sigmas must be finite, got {sigmas}")
    tot = float(v.sum())
    return np.full(len(v), D / len(v)) if tot <= 0 else D * v / tot


def seen_segments(px: np.ndarray, origin_xy, roi_shape) -> np.ndarray:
    """(M - 1,) bool: the segments of a path px (M, 2) (x, y) image px whose both vertices lie in
    the region of interest (``origin_xy`` (x0, y0), ``roi_shape`` (h, w): pixel centres 0 .. w - 1,
    their areas to -0.5 .. w - 0.5), i.e. where the frame was looked at. A vertex outside it (the
    hidden head from a grasp outside the image, a centreline refined or extended past the edge)
    was not seen, and no point on its segments is valid."""
    x, y = px[:, 0] - origin_xy[0], px[:, 1] - origin_xy[1]
    inside = (x >= -0.5) & (x <= roi_shape[1] - 0.5) & (y >= -0.5) & (y <= roi_shape[0] - 0.5)
    return inside[:-1] & inside[1:]
