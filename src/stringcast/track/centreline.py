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

from stringcast.core import TrackingSettings

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


def _fwhm_across(absdiff: np.ndarray, p: np.ndarray, t: np.ndarray) -> float:
    """Full width (px) at half contrast of ``absdiff`` across the direction t at point p."""
    off = np.arange(-6.0, 6.0 + 1e-9, 0.25)
    t = np.asarray(t, float) / max(float(np.hypot(*t)), 1e-9)
    q = p + off[:, None] * np.array([-t[1], t[0]])
    v = map_coordinates(absdiff, [q[:, 0], q[:, 1]], order=1, mode="nearest")
    return 0.25 * float(np.count_nonzero(v > v.min() + 0.5 * (v.max() - v.min())))


def _end_tangent(pts: np.ndarray, cum: np.ndarray, n_tangent: float):
    """Unit tangent (2,) of a path (M, 2) at its end, over its last ``n_tangent`` px of arc
    ``cum`` (M,); None where those vertices coincide."""
    a = int(np.searchsorted(cum, cum[-1] - n_tangent))
    t = pts[-1] - pts[min(a, len(pts) - 2)]
    nt = float(np.hypot(*t))
    return None if nt < 1e-6 else t / nt


def string_continues(absdiff: np.ndarray, pts: np.ndarray, width_px: float, share: float,
                     n_tangent: int = 6, reach: float = 8.0) -> bool:
    """Whether string-like contrast goes on past a walk's end: the end is then where the string
    fades below the segmentation's threshold (a faint stretch, the light behind it changing),
    not its free end.

    Past the end's far half-contrast edge (:func:`end_edge`; ``reach`` px where the contrast
    does not fall within it) by one string width, and for two widths + 4 px more, ``absdiff`` is sampled along 9 directions within
    +-40 deg of the end tangent (over its last ``n_tangent`` px), but not within a width of the
    walk itself; the string goes on when the best direction's mean reaches ``share``
    (``end_contrast_min``) of the contrast along the path.

    Args:
        absdiff: (H, W) smoothed contrast. pts: (M, 2) (row, col) centreline, the end last.
        width_px: the string's width in the foreground. share: of the path's median contrast.
    """
    edge, t = end_edge(absdiff, pts, n_tangent, reach)
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
    ij = np.round(pts).astype(int)
    along = float(np.median(absdiff[ij[:, 0], ij[:, 1]]))
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


def free_end_extension(absdiff: np.ndarray, pts: np.ndarray, n_tangent: int = 6, reach: float = 8.0) -> float:
    """How far (px) the string's free end lies past the last vertex of its centreline.

    A skeleton stops short of a free end (by about the foreground's half-width, more under
    blur). The end is the half-contrast edge along the end tangent (:func:`end_edge`). Where
    the string is wider at its end than along its length, a lump ends it (:func:`end_lump`): a
    ball (clay: the end is its centre, half its width back) or a sleeve longer than wide (a
    pipe: the end is its far edge).

    Args:
        absdiff: (H, W) contrast image. pts: (M, 2) (row, col) centreline, the free end last.

    Returns:
        Extension in px (>= 0; 0 where the profile gives no edge within ``reach`` px).
    """
    edge, t = end_edge(absdiff, pts, n_tangent, reach)
    if edge is None:
        return 0.0
    kind, w_lump = end_lump(absdiff, pts, edge, t)
    return max(0.0, float(edge) - (w_lump / 2 if kind == "ball" else 0.0))


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
    w = np.array([_fwhm_across(absdiff, P[i], T[i]) for i in range(len(back))])
    w = np.median(np.stack([w, np.r_[w[:1], w[:-1]], np.r_[w[1:], w[-1:]]]), axis=0)
    w_lump = float(np.max(w[back <= 2.0 * w_mid + 4.0]))
    if w_lump - w_mid <= 0.5:
        return "plain", w_mid
    narrow = np.nonzero(w < w_mid + 0.5 * (w_lump - w_mid))[0]
    length = float(edge) + (float(back[narrow[0]]) if len(narrow) else float(back[-1]))
    return ("sleeve" if length > 1.5 * w_lump else "ball"), w_lump


def end_ball(absdiff: np.ndarray, pts: np.ndarray, n_tangent: int = 6, reach: float = 8.0):
    """The centre (2,) (row, col) and radius (px) of a ball that ends the path, or None.

    A skeleton forks inside a ball, and the walk ends on one spur or the other, frame by frame
    (generalization seeds 0 and 7: the tip jittered by ~1 mm across and along the string). The
    centre is found from the contrast, not the walk: near half the ball's width back from its
    far edge (:func:`end_edge`, :func:`end_lump`), the deepest point of the foreground at half
    the contrast there (the maximum of its distance transform, ``cv2.distanceTransform``; the
    centroid of the top 1 px of it). None also where that centre is farther than
    the radius from the walk's end (the walk does not end inside it: not a ball, or not this one).
    """
    edge, t = end_edge(absdiff, pts, n_tangent, reach)
    if edge is None:
        return None
    kind, w_lump = end_lump(absdiff, pts, edge, t)
    j = len(pts) // 2
    if kind != "ball" or w_lump < 1.5 * _fwhm_across(absdiff, pts[j], pts[min(j + 2, len(pts) - 1)] - pts[max(j - 2, 0)]):
        return None   # a lump barely wider than the string (a band of tape at the tip) has no centre of its own
    r = w_lump / 2
    c0 = pts[-1] + (float(edge) - r) * t
    h = int(math.ceil(2 * r)) + 2   # the ball's window: its foreground at half the contrast there
    r0, c0_ = int(round(c0[0])) - h, int(round(c0[1])) - h
    if r0 < 0 or c0_ < 0 or r0 + 2 * h + 1 > absdiff.shape[0] or c0_ + 2 * h + 1 > absdiff.shape[1]:
        return None
    win = absdiff[r0:r0 + 2 * h + 1, c0_:c0_ + 2 * h + 1]
    dt = cv2.distanceTransform((win > 0.5 * float(win.max())).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    rr, cc = np.nonzero(dt >= float(dt.max()) - 1.0)   # the deepest point inside the blob: its centre, which
    wts = dt[rr, cc] - (float(dt.max()) - 1.0) + 1e-6  # the string's stretch into the ball does not move
    c = np.array([float(wts @ rr) / wts.sum() + r0, float(wts @ cc) / wts.sum() + c0_])
    return (c, r) if np.hypot(*(c - pts[-1])) <= r else None   # the walk ends inside the ball


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
    ij = pts.astype(int)
    v = absd[ij[:, 0], ij[:, 1]]
    t = pts[-1] - pts[max(len(pts) - 7, 0)]
    t = t / max(float(np.hypot(*t)), 1e-9)
    ray = pts[-1] + np.arange(-4.0, 5.0)[:, None] * t  # behind and past the end
    b = map_coordinates(bg, ray.T, order=1, mode="nearest")
    step = abs(float(np.median(b[6:])) - float(np.median(b[:3])))  # the background changes at the end:
    return (float(v[-3:].mean()) >= st.end_contrast_min * float(np.median(v))  # an occluder's rim
            and step < st.end_edge_max * float(np.median(v)))
