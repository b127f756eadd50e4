"""The arm's links read across their forward-kinematics axes in one image.

Across each link (and the gripper) the image is sampled on profiles normal to its FK axis,
over the arm outline's width plus ``margin_mm`` each side, clear of the joint discs; on each
profile the strongest pair of edges whose spacing fits the outline is the link as seen
(:func:`edge_pair_centre`), and the profiles that agree give its offset along the normal
(:func:`link_consensus`). The still-arm check (:mod:`.board_check`) and the arm's sweep
(:mod:`.arm_sweep`) both read the arm this way.
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d, map_coordinates

from stringcast.core import BoardCheckSettings, forward_kinematics


def _sample(image: np.ndarray, calibration, pts: np.ndarray) -> np.ndarray:
    uv = calibration.robot_to_pixel(pts.reshape(-1, 2))
    h, w = image.shape
    vals = map_coordinates(image, [uv[:, 1], uv[:, 0]], order=1, mode="nearest")
    inside = (uv[:, 0] >= 0) & (uv[:, 0] <= w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= h - 1)
    vals = np.where(inside, vals, np.nan)
    return vals.reshape(pts.shape[:-1])


def _refine(g: np.ndarray, i: int) -> float:
    """Sub-sample position of the |g| extremum at index i (parabola)."""
    if 0 < i < len(g) - 1:
        y0, y1, y2 = np.abs(g[i - 1:i + 2])
        den = y0 - 2 * y1 + y2
        if den < 0:
            return i + 0.5 * (y0 - y2) / den
    return float(i)


def edge_pair_centre(profile: np.ndarray, step: float, v0: float, width_lo: float, width_hi: float) -> float | None:
    """Centre (m, in the profile's coordinate v = v0 + i step) of the strongest pair of
    edges spaced within [width_lo, width_hi] m; None if there is none.

    Edges are local maxima of |gradient|, of either sign (a link in front of a darker
    region on one side and a lighter one on the other has two rising edges). Pair
    strength = the weaker edge's |gradient|, so one strong clutter edge cannot win with a
    faint partner. The 12 strongest edges' pairs are scored at once; the first strongest in
    the order of :func:`edge_pair_centre_reference`'s loops wins, so the two agree exactly.
    """
    found = _edge_peaks(profile)
    if found is None:
        return None
    g, a, peaks = found
    i, j = peaks[:, None], peaks[None, :]
    sep = (j - i) * step
    s = np.where((j > i) & (width_lo <= sep) & (sep <= width_hi), np.minimum(a[i], a[j]), 0.0)
    k = int(np.argmax(s))               # row-major: the loops' order, first of equals
    if not s.flat[k] > 0.0:
        return None
    bi, bj = peaks[k // len(peaks)], peaks[k % len(peaks)]
    return v0 + step * 0.5 * (_refine(g, bi) + _refine(g, bj))


def _edge_peaks(profile: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(gradient, |gradient|, the indices of its 12 largest local maxima, strongest first), or None
    when the profile has a NaN or fewer than two maxima."""
    if not np.all(np.isfinite(profile)):
        return None
    g = np.gradient(profile)
    a = np.abs(g)
    peaks = np.nonzero((a[1:-1] >= a[:-2]) & (a[1:-1] > a[2:]))[0] + 1
    if len(peaks) < 2:
        return None
    return g, a, peaks[np.argsort(a[peaks])[::-1][:12]]


def edge_pair_centre_reference(profile: np.ndarray, step: float, v0: float, width_lo: float,
                               width_hi: float) -> float | None:
    """:func:`edge_pair_centre` as plain loops over the pairs (the reference the tests hold it to)."""
    found = _edge_peaks(profile)
    if found is None:
        return None
    g, a, peaks = found
    best, centre = 0.0, None
    for i in peaks:
        for j in peaks:
            if j <= i:
                continue
            sep = (j - i) * step
            if width_lo <= sep <= width_hi:
                s = min(a[i], a[j])
                if s > best:
                    best, centre = s, v0 + step * 0.5 * (_refine(g, i) + _refine(g, j))
    return centre


def link_profiles(image, calibration, arm, q, st: BoardCheckSettings) -> list[tuple]:
    """The arm's links (and gripper) at pose q, each read on ``st.rows`` profiles across its FK axis.

    Args:
        image: (H, W) float grey image. calibration: robot_to_pixel. arm: the arm with its outline.
        q: (J,) rad. st: the profiles' settings (:class:`~stringcast.core.BoardCheckSettings`).

    Returns:
        per link long enough to show its sides clear of the joint discs: (a, b (2,) its FK ends, m;
        its unit normal (2,); u (R,) the places along a -> b of the profiles where an edge pair of
        the outline's width was found (:func:`edge_pair_centre`); their centres (R,) m along the
        normal; the profiles tried).
    """
    pts = forward_kinematics(arm, np.asarray(q, float))
    J = arm.n_joints
    links, radii = arm.link_widths, arm.joint_radii
    out = []
    for s in range(J + 1):
        a, b = pts[s], pts[s + 1]
        L = float(np.hypot(*(b - a)))
        if s < J:
            w0 = w1 = float(links[min(s, len(links) - 1)])
            r_a, r_b = float(radii[min(s, len(radii) - 1)]), float(radii[min(s + 1, len(radii) - 1)])
        else:
            w0, w1 = (float(w) for w in arm.gripper_widths)
            r_a, r_b = float(radii[min(J, len(radii) - 1)]), 0.0
        clear = st.clear_mm / 1000
        u0, u1 = (r_a + clear) / L, 1 - (r_b + clear) / L
        if s == J:
            u1 = min(u1, 0.9)
        if L <= 0 or (u1 - u0) * L < 0.02:
            continue  # too short to show its sides clear of the joint discs
        e = (b - a) / L
        nrm = np.array([-e[1], e[0]])
        step = st.step_mm / 1000
        us = np.linspace(u0, u1, int(st.rows))
        ws = [w0 + (w1 - w0) * u for u in us]
        vs = [np.arange(-(w / 2 + st.margin_mm / 1000), w / 2 + st.margin_mm / 1000 + step / 2, step) for w in ws]
        # every profile of the link sampled in one call (pointwise: the same values as row by row)
        samples = _sample(image, calibration, np.concatenate([a + u * (b - a) + v[:, None] * nrm for u, v in zip(us, vs)]))
        found = []
        for u, w, v, prof in zip(us, ws, vs, _smoothed_profiles(samples, [len(v) for v in vs], 1.0 / st.step_mm)):
            c = edge_pair_centre(prof, step, v[0], st.width_range[0] * w, st.width_range[1] * w)
            if c is not None:
                found.append((u, c))
        u_c = np.asarray(found, float).reshape(-1, 2)
        out.append((a, b, nrm, u_c[:, 0], u_c[:, 1], len(us)))
    return out


def _smoothed_profiles(samples: np.ndarray, lengths: list[int], sigma: float) -> list[np.ndarray]:
    """The profiles (``samples`` cut into ``lengths``), each smoothed by ``gaussian_filter1d`` (sigma in
    samples) where it is finite throughout, else as it is; the profiles of one length in one call
    (row by row the same values)."""
    profiles = np.split(samples, np.cumsum(lengths)[:-1])
    out = list(profiles)
    for n in set(lengths):
        rows = [i for i, p in enumerate(profiles) if len(p) == n and np.all(np.isfinite(p))]
        if rows:
            smoothed = gaussian_filter1d(np.stack([profiles[i] for i in rows]), sigma, axis=-1)
            for i, row in zip(rows, smoothed):
                out[i] = row
    return out


def link_consensus(centres: np.ndarray, tried: int, st: BoardCheckSettings) -> tuple[float, float] | None:
    """(median, spread) m of a link's profile centres (:func:`link_profiles`) that agree within
    ``max_spread_mm``: at least ``min_rows`` of them and ``min_share`` of the ``tried``; else None."""
    return _consensus(centres, st.max_spread_mm / 1000, max(int(st.min_rows), int(np.ceil(st.min_share * tried))))


def _consensus(values: np.ndarray, tol: float, min_count: int) -> tuple[float, float] | None:
    """(median, MAD spread) of the largest group of values within +-tol of one of them
    (rows where clutter behind the arm won the edge pair fall out); None if it has fewer
    than min_count members."""
    if len(values) < min_count:
        return None
    near = np.abs(values[:, None] - values[None, :]) <= tol
    group = values[near[int(np.argmax(near.sum(axis=1)))]]
    if len(group) < min_count:
        return None
    med = float(np.median(group))
    return med, float(np.median(np.abs(group - med)) * 1.4826)
