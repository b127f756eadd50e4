"""Pixel-by-pixel walk along a skeleton (compiled with numba), with a plain NumPy reference
(:func:`walk_pixels_reference`, tested against it).

:func:`trace_path` walks a whole skeleton; :func:`walk_pixels` walks one stretch, stopping
beside a junction zone (:mod:`stringcast.track.junctions` chooses the way on). Pixels are (row, col)
of the skeleton image; skeletons are (H, W) bool.
"""
from __future__ import annotations

import numpy as np
from numba import njit


def trace_path(skel: np.ndarray, start: tuple[int, int], max_gap: float, direction=None):
    """Walk a skeleton from ``start`` (row, col), straight at junctions, bridging small gaps.

    At each step the unvisited 8-neighbour best aligned with the current direction (over the
    last 5 steps) is taken and all the current pixel's neighbours are marked visited; with
    no neighbour left, the nearest unvisited skeleton pixel within ``max_gap`` px and 35 deg
    of the direction is jumped to (a bridged gap). Compiled with numba. This is the plain
    pixel walk; :func:`stringcast.track.junctions.walk_skeleton` adds the choice at crossings.

    Args:
        skel: (H, W) bool skeleton. direction: (drow, dcol) initial direction or None.

    Returns:
        pts (M, 2) float (row, col) and bridged (M,) bool (True: reached by a gap jump).
    """
    skel = np.ascontiguousarray(skel, dtype=np.bool_)
    pts, bridged, _ = walk_pixels(skel, np.zeros(skel.shape, np.int32), np.zeros(skel.shape, np.bool_),
                                  start, max_gap, direction)
    return pts.astype(float), bridged


def walk_pixels(skel: np.ndarray, zone: np.ndarray, visited: np.ndarray, start, max_gap: float, direction=None,
                ignore: int = 0):
    """One stretch of the pixel walk of :func:`trace_path`, stopping at a junction zone.

    Args:
        skel: (H, W) contiguous bool skeleton. zone: (H, W) int32: > 0 the id of a junction
            zone (never stepped on, never marked visited), < 0 a zone's exit pixel (marked
            visited only when stepped on), 0 elsewhere. visited: (H, W) bool, updated in place.
        start: (row, col), the walk's first pixel. direction: (drow, dcol) or None.
        ignore: a zone id not to stop at (the zone the walk is leaving) until it is out of reach.

    Returns:
        pts (M, 2) int64 (row, col), bridged (M,) bool, and the id of the zone beside pts[-1]
        where the walk stopped (0: it ended: no unvisited pixel and no gap to bridge).
    """
    d = np.array([np.nan, np.nan]) if direction is None else np.asarray(direction, float)
    if not np.hypot(*d) > 0:  # no (or a zero) direction: the first step takes the first neighbour
        d = np.array([np.nan, np.nan])
    return _walk(skel, zone, visited, int(start[0]), int(start[1]), float(max_gap), d[0], d[1], int(ignore))


@njit(cache=True)
def _walk(skel, zone, visited, r0, c0, max_gap, d0r, d0c, ignore):  # pragma: no cover - compiled
    H, W = skel.shape
    cap = 1
    for i in range(H):
        for j in range(W):
            cap += skel[i, j]
    pts = np.empty((cap, 2), np.int64)
    bridged = np.zeros(cap, np.bool_)
    pts[0, 0], pts[0, 1] = r0, c0
    visited[r0, c0] = True
    m = 1
    have_d = not (np.isnan(d0r) or np.isnan(d0c))
    dn = np.hypot(d0r, d0c) if have_d else 1.0
    dr, dc = (d0r / dn, d0c / dn) if have_d else (0.0, 0.0)
    g = int(np.ceil(max_gap))
    cos_max = np.cos(np.radians(35.0))
    r, c = r0, c0
    while m < cap:
        stop, near = 0, False  # a junction zone beside the current pixel: stop there
        for a in range(-1, 2):
            for b in range(-1, 2):
                rr, cc = r + a, c + b
                if 0 <= rr < H and 0 <= cc < W and zone[rr, cc] > 0:
                    if zone[rr, cc] == ignore:
                        near = True
                    elif stop == 0:
                        stop = zone[rr, cc]
        if stop > 0:
            return pts[:m].copy(), bridged[:m].copy(), stop
        if not near:
            ignore = 0
        br, bc, bscore, found = -1, -1, -1e9, False
        for a in range(-1, 2):
            for b in range(-1, 2):
                rr, cc = r + a, c + b
                if (a == 0 and b == 0) or rr < 0 or rr >= H or cc < 0 or cc >= W:
                    continue
                if skel[rr, cc] and not visited[rr, cc] and zone[rr, cc] <= 0:
                    score = (a * dr + b * dc) / np.hypot(a, b) if have_d else 0.0
                    if not found or score > bscore:
                        br, bc, bscore, found = rr, cc, score, True
        jump = False
        if found:
            for a in range(-1, 2):
                for b in range(-1, 2):
                    rr, cc = r + a, c + b
                    if 0 <= rr < H and 0 <= cc < W and skel[rr, cc] and zone[rr, cc] == 0:
                        visited[rr, cc] = True
        elif have_d:
            best = 1e9
            for a in range(-g, g + 1):
                for b in range(-g, g + 1):
                    dist = np.hypot(a, b)
                    rr, cc = r + a, c + b
                    if dist <= 1.5 or dist > max_gap or rr < 0 or rr >= H or cc < 0 or cc >= W:
                        continue
                    if not skel[rr, cc] or visited[rr, cc] or zone[rr, cc] > 0:
                        continue
                    cosang = (a * dr + b * dc) / dist
                    if cosang > cos_max and dist * (2.0 - cosang) < best:
                        best, br, bc, found = dist * (2.0 - cosang), rr, cc, True
            jump = found
        if not found:
            break
        visited[br, bc] = True
        pts[m, 0], pts[m, 1] = br, bc
        bridged[m] = jump
        m += 1
        r, c = br, bc
        k = max(0, m - 6)
        vr, vc = r - pts[k, 0], c - pts[k, 1]
        nv = np.hypot(vr, vc)
        if nv > 0:
            dr, dc, have_d = vr / nv, vc / nv, True
    return pts[:m].copy(), bridged[:m].copy(), 0


_NB = np.array([(a, b) for a in (-1, 0, 1) for b in (-1, 0, 1) if (a, b) != (0, 0)])  # the kernel's scan order


def walk_pixels_reference(skel: np.ndarray, zone: np.ndarray, visited: np.ndarray, start, max_gap: float,
                          direction=None, ignore: int = 0):
    """:func:`walk_pixels` in plain NumPy, one step at a time (the compiled walk's reference, for tests)."""
    H, W = skel.shape

    def around(r, c, off):  # neighbours inside the image: offsets (K, 2) and their rows, cols
        rr, cc = r + off[:, 0], c + off[:, 1]
        ok = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
        return off[ok], rr[ok], cc[ok]

    g = int(np.ceil(max_gap))
    gap = np.array([(a, b) for a in range(-g, g + 1) for b in range(-g, g + 1)])
    have_d = direction is not None and bool(np.hypot(*direction) > 0)
    u = np.asarray(direction, float) / np.hypot(*direction) if have_d else np.zeros(2)
    r, c = int(start[0]), int(start[1])
    pts, bridged = [(r, c)], [False]
    visited[r, c] = True
    while len(pts) < 1 + int(skel.sum()):
        _, rr, cc = around(r, c, _NB)
        z = zone[rr, cc]
        stop = z[(z > 0) & (z != ignore)]
        if len(stop):
            return np.array(pts, np.int64), np.array(bridged), int(stop[0])
        if not np.any(z == ignore):
            ignore = 0
        off, rr, cc = around(r, c, _NB)
        free = skel[rr, cc] & ~visited[rr, cc] & (zone[rr, cc] <= 0)
        jump = False
        if free.any():
            score = (off @ u) / np.hypot(off[:, 0], off[:, 1]) if have_d else np.zeros(len(off))
            j = int(np.argmax(np.where(free, score, -np.inf)))
            nxt = (rr[j], cc[j])
            mark = skel[rr, cc] & (zone[rr, cc] == 0)
            visited[rr[mark], cc[mark]] = True
        elif have_d:
            off, rr, cc = around(r, c, gap)
            dist = np.hypot(off[:, 0], off[:, 1])
            cosang = (off @ u) / np.maximum(dist, 1e-12)
            ok = ((dist > 1.5) & (dist <= max_gap) & skel[rr, cc] & ~visited[rr, cc] & (zone[rr, cc] <= 0)
                  & (cosang > np.cos(np.radians(35.0))))
            if not ok.any():
                break
            j = int(np.argmin(np.where(ok, dist * (2.0 - cosang), np.inf)))
            nxt, jump = (rr[j], cc[j]), True
        else:
            break
        visited[nxt] = True
        pts.append(nxt)
        bridged.append(jump)
        r, c = int(nxt[0]), int(nxt[1])
        v = np.array([r, c]) - np.array(pts[max(0, len(pts) - 6)])
        if np.hypot(*v) > 0:
            u, have_d = v / np.hypot(*v), True
    return np.array(pts, np.int64), np.array(bridged), 0
