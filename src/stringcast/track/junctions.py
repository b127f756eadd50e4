"""Skeleton walk through junctions: where the string crosses itself (or touches something).

A thin skeleton shows a crossing as one pixel with four branches, a 2 x 2 block, a triangle
or, more often, as two three-branch pixels joined by a short segment (the overlap of two
strokes of width w). :func:`junction_zones` groups each into one *zone* (see there); the
skeleton pixels beside a zone, grouped, are its *exits*, each the start of an *arm*.
:class:`Zones` measures each arm's direction over 1.5 w px of it, and whether it is a real
branch (at least ``min_branch_px`` long, or leading to another zone) or a spur.

:func:`walk_skeleton` walks pixel by pixel (:func:`stringcast.track.skeleton_walk.walk_pixels`)
up to a zone and leaves it by the exit joined most smoothly to the arm it came in by: the
least bending (:func:`bending`, ~ squared turn angle) of a cubic Hermite join from the entry
to the exit, positions and tangents. At a four-arm zone met first, the two arms left must
pair up as well (the string's other pass through the crossing), and the pairing bends the
least in total. The path crosses the zone along its skeleton. Zones are never marked
visited, so the second pass through a crossing finds its way too (the one exit left).

A choice is *ambiguous* (the ordering beyond it is a guess) when the runner-up bends less
than ``margin`` more, unless every exit left is a spur (the string ends or folds there,
whichever is taken: the spur not taken marks a fold); every pass through a zone where a choice
was ambiguous, or where a real branch is never walked (something joins there), is marked ambiguous; one by a spur never
walked (1 px or more out of the zone) is marked *folded*: a fold of the string (a hairpin,
a collapsed loop) leaves only a short spur and may hold length the walk does not measure.
The tracker treats both like branches joining the walk (points past them are not valid from
that side), but only ambiguities by the grasp make the ordering there unknown (spurs of the
fingertips' tangle are common).

Units: pixels of the skeleton image, (row, col); skeletons (H, W) bool.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from .skeleton_walk import walk_pixels

_RING = [(-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1)]  # the 8 neighbours


def _degree(skel: np.ndarray) -> np.ndarray:
    """Number of 8-neighbours of each pixel in the skeleton, (H, W) int."""
    k = np.ones((3, 3), np.float32)
    k[1, 1] = 0
    return np.rint(cv2.filter2D(skel.astype(np.float32), -1, k, borderType=cv2.BORDER_CONSTANT)).astype(int)


def junction_zones(skel: np.ndarray, width_px: float) -> np.ndarray:
    """Junction zones of a skeleton: (H, W) int32, zone ids 1..Z on their pixels, 0 elsewhere.

    Candidates are pixels with 3 or more neighbours (a junction of an 8-connected skeleton is
    one pixel, a 2 x 2 block where two lines cross between pixels, or a triangle; staircase
    corners are candidates too, and fail the test of arms below). A zone is the skeleton
    within w / 4 of candidates, with the pieces of skeleton without an end that join two
    three-way junctions within 2 w px (a crossing: strokes crossing at an angle a overlap along
    ~ w cot(a / 2), 2 w at 53 deg; shallower crossings stay two zones, and the choice at the
    second is mostly a tie) or loop back to one within 1.5 w px (a small loop),
    grouped by 8-connectivity, and only if three or more separate arms leave it (else it is
    a thick spot of a line). A short spur stays an arm (:class:`Zones` tells it from a branch).

    Args:
        skel: (H, W) bool skeleton. width_px: the string's width w in px (the foreground's).
    """
    return _zone_parts(np.asarray(skel, bool), width_px)[0]


def _zone_parts(skel: np.ndarray, width_px: float):
    """:func:`junction_zones` (ids), with the exit pixels' group labels (H, W) int (0 elsewhere),
    the zone id beside each pixel (H, W) int, and the skeleton's degrees."""
    deg = _degree(skel)
    jp = skel & (deg >= 3)
    if not jp.any():
        zero = np.zeros(skel.shape, np.int32)
        return zero, zero, zero, deg
    d = cv2.distanceTransform((~jp).astype(np.uint8), cv2.DIST_L2, 3)
    core = skel & (d <= max(1.0, 0.25 * width_px))
    rest = skel & ~core
    n, lab, stats, _ = cv2.connectedComponentsWithStats(rest.astype(np.uint8), connectivity=8)
    nc, cl = cv2.connectedComponents(core.astype(np.uint8), connectivity=8)
    ring = cv2.dilate(cl.astype(np.float32), np.ones((3, 3), np.uint8)).astype(np.int32)
    ends = np.zeros(n, bool)  # pieces with an end pixel (one neighbour): spurs and the string's ends
    ends[lab[rest & (deg == 1)]] = True
    pairs = np.unique(np.column_stack([lab[rest & (ring > 0)], ring[rest & (ring > 0)]]), axis=0)  # (piece, core)
    cores = np.bincount(pairs[:, 0], minlength=n)  # how many cores each piece touches
    size = stats[:, cv2.CC_STAT_AREA]
    short = ~ends & (cores == 1) & (size <= max(2.0, 1.5 * width_px))  # a small loop on a core
    _, el = cv2.connectedComponents((rest & (ring > 0)).astype(np.uint8), connectivity=8)
    arms = np.bincount(np.unique(np.column_stack([ring[el > 0], el[el > 0]]), axis=0)[:, 0], minlength=nc)
    for k in np.nonzero(~ends & (cores == 2) & (size <= 2 * width_px))[0]:  # two three-way junctions joined
        short[k] = bool(np.all(arms[pairs[pairs[:, 0] == k, 1]] == 3))  # by a short piece: a crossing
    short[0] = False
    zone = core | short[lab]
    nz, zl = cv2.connectedComponents(zone.astype(np.uint8), connectivity=8)
    ring = cv2.dilate(zl.astype(np.float32), np.ones((3, 3), np.uint8)).astype(np.int32)
    ex = skel & ~zone & (ring > 0)  # exit pixels, grouped into arms
    _, el = cv2.connectedComponents(ex.astype(np.uint8), connectivity=8)
    arms = np.bincount(np.unique(np.column_stack([ring[ex], el[ex]]), axis=0)[:, 0], minlength=nz)
    keep = arms >= 3
    keep[0] = False
    new = np.where(keep, np.cumsum(keep), 0).astype(np.int32)  # kept zones renumbered 1..Z
    ring = new[ring]
    return new[zl], np.where(ex & (ring > 0), el, 0), ring, deg


class Zones:
    """A skeleton's junction zones, their exits and arms (built once per skeleton, shared by walks).

    Attributes: id (H, W) int32 zone ids (:func:`junction_zones`); map (H, W) int32 for
    :func:`~stringcast.track.skeleton_walk.walk_pixels` (zone ids, -1 on exits); exits {zone: [(K, 2) int
    pixels of each exit]}; core {zone: (2,) mean of its branch pixels}; reach, skip: an arm's
    direction is measured from skip to skip + reach px out of its zone; fold: px.
    """

    def __init__(self, skel: np.ndarray, width_px: float, min_branch_px: int):
        self.skel = skel
        self.id, el, ring, deg = _zone_parts(np.asarray(skel, bool), width_px)
        self.reach = max(3.0, 1.5 * width_px)
        self.fold = 1  # a spur this many px out of its zone may be the end of a fold
        self.skip = 0.5 * width_px  # the skeleton bends toward a junction within about w / 2 of it
        self.min_branch = int(min_branch_px)
        self.map = self.id.copy()  # for the walk: > 0 zone, -1 exit pixel
        self.map[el > 0] = -1
        px = np.argwhere(el > 0)
        order = np.argsort(el[el > 0], kind="stable")
        px, g = px[order], el[el > 0][order]
        self.exits: dict[int, list[np.ndarray]] = {}
        for grp in np.split(px, np.nonzero(np.diff(g))[0] + 1) if len(px) else []:
            self.exits.setdefault(int(ring[grp[0, 0], grp[0, 1]]), []).append(grp)
        self._arm: dict[tuple, tuple] = {}
        jp = np.argwhere((deg >= 3) & (self.id > 0))
        zj = self.id[jp[:, 0], jp[:, 1]]
        self.core = {int(z): jp[zj == z].mean(axis=0) for z in np.unique(zj)}

    def arm(self, z: int, k: int):
        """Exit k of zone z: (first pixel, unit direction outward over ``reach`` px past w / 2, real
        branch?, the zone it leads to or 0, its length in px as far as measured)."""
        key = (z, k)
        if key not in self._arm:
            px = self.exits[z][k]
            H, W = self.skel.shape
            seen = {tuple(p) for p in px}
            front, depth, real, to, far, near = [tuple(p) for p in px], 0, False, 0, None, None
            while front and depth < max(self.skip + self.reach, self.min_branch) and not to:
                nxt = []
                for r, c in front:
                    for dr, dc in _RING:
                        q = (r + dr, c + dc)
                        if 0 <= q[0] < H and 0 <= q[1] < W and self.skel[q] and q not in seen:
                            seen.add(q)
                            if self.id[q] == 0:
                                nxt.append(q)
                            elif self.id[q] != z:
                                real, to = True, int(self.id[q])  # the arm leads to another junction
                if not nxt:
                    break
                depth += 1
                if depth <= self.skip:
                    near = nxt
                if depth <= self.skip + self.reach:
                    far = nxt
                front = nxt
            real = real or depth >= self.min_branch
            tip = np.mean(far, axis=0) if far else px.mean(axis=0).astype(float)
            start = px[np.argmin(np.hypot(*(px - tip).T))]
            v = tip - (np.mean(near, axis=0) if near and depth > self.skip else start)
            n = float(np.hypot(*v))
            self._arm[key] = (start, v / n if n > 0 else v * 0.0, real, to, depth)
        return self._arm[key]


def _unit(v):
    """v / |v| as floats, or None for None."""
    return None if v is None else np.asarray(v, float) / max(float(np.hypot(*v)), 1e-9)


def _through(zone: np.ndarray, z: int, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Pixels strictly between p and q on a shortest 8-connected path over zone z's pixels, (K, 2)
    int (row, col); a straight line where the zone does not join them."""
    H, W = zone.shape
    prev = {tuple(p): None}
    front, goal = [tuple(p)], tuple(q)
    while front and goal not in prev:
        nxt = []
        for r, c in front:
            for dr, dc in _RING:
                u = (r + dr, c + dc)
                if u not in prev and 0 <= u[0] < H and 0 <= u[1] < W and (zone[u] == z or u == goal):
                    prev[u] = (r, c)
                    nxt.append(u)
        front = nxt
    if goal in prev:
        out, u = [], prev[goal]
        while u is not None and u != tuple(p):
            out.append(u)
            u = prev[u]
        return np.array(out[::-1], np.int64).reshape(-1, 2)
    n = int(math.ceil(float(np.max(np.abs(q - p)))))
    t = np.arange(1, max(n, 1))[:, None] / max(n, 1)
    return np.round(p + t * (q - p)).astype(np.int64).reshape(-1, 2)


def _direction(path: np.ndarray, length: float):
    """Unit direction of a path over its last ``length`` px of arc, or None if too short."""
    steps = np.hypot(*np.diff(path[::-1], axis=0).T)
    cum = np.cumsum(steps)
    if len(cum) == 0 or cum[-1] < 1.5:
        return None
    j = int(min(np.searchsorted(cum, length), len(cum) - 1)) + 1
    v = (path[-1] - path[-1 - j]).astype(float)
    return v / float(np.hypot(*v))


def bending(p0, t0, p1, t1) -> float:
    """Bending of the smoothest join from p0 (unit tangent t0) to p1 (unit tangent t1).

    The cubic Hermite curve H(u), u in [0, 1], with tangents of the chord's length L; returns
    the integral of |H''|^2 du / L^2 (~ L times the integrated squared curvature: scale-free,
    0 for a straight join, ~ (turn angle)^2 in rad^2 for a circular arc). Points (2,), px."""
    delta = np.asarray(p1, float) - np.asarray(p0, float)
    L = max(float(np.hypot(*delta)), 1.0)
    a = 6 * delta - L * (4 * t0 + 2 * t1)  # H'' at u = 0, 1/2, 1 (|H''|^2 is quadratic: Simpson is exact)
    m = L * (t1 - t0)
    b = -6 * delta + L * (2 * t0 + 4 * t1)
    return float((a @ a + 4 * m @ m + b @ b) / (6 * L ** 2))


def walk_skeleton(skel: np.ndarray, start, max_gap: float, direction=None, width_px: float = 3.0,
                  min_branch_px: int = 6, margin: float = 0.5, zones: Zones | None = None):
    """Walk a skeleton from ``start`` (row, col), straight through crossings, bridging small gaps.

    Args:
        skel: (H, W) bool skeleton. start: (row, col). max_gap: longest gap bridged, px.
        direction: (drow, dcol) initial direction or None. width_px: the string's width, px.
        min_branch_px: a zone's exit whose arm is shorter (and ends) is a spur, not a branch.
        margin: the least lead in :func:`bending` of the choice at a zone over the runner-up
            (0.5 ~ a turn of 40 deg) for the choice not to be ambiguous.
        zones: :class:`Zones` of this skeleton (built here if None).

    Returns:
        pts (M, 2) float (row, col); bridged (M,) bool (reached by a gap jump); ambiguous (M,)
        bool (on the path across a zone where a choice was a guess or a branch is never walked);
        folded (M,) bool (across a zone, not ambiguous, where a spur is never walked); passed
        (H, W) bool, the pixels of the zones walked through (they belong to the walk).
    """
    skel = np.ascontiguousarray(skel, dtype=np.bool_)
    Z = zones if zones is not None else Zones(skel, width_px, min_branch_px)
    visited = np.zeros(skel.shape, np.bool_)
    parts, brid, amb = [], [], []
    passages: dict[int, list[tuple[int, int, bool]]] = {}  # zone: (first, last index on the path, a guess?)
    pos, d, total = np.asarray(start, np.int64), direction, 0
    z = int(Z.id[pos[0], pos[1]])
    if z == 0:
        p, b, z = walk_pixels(skel, Z.map, visited, pos, max_gap, d)
        parts.append(p), brid.append(b), amb.append(np.zeros(len(p), bool))
        total = len(p)
    else:  # the start lies in a zone: choose its exit with the initial direction
        parts.append(pos[None]), brid.append(np.zeros(1, bool)), amb.append(np.zeros(1, bool))
        total = 1
    while z > 0:
        path = np.concatenate(parts)
        groups = Z.exits.get(z, [])
        free = [k for k, px in enumerate(groups) if not visited[px[:, 0], px[:, 1]].any()]
        if not free:
            break  # every way out walked already: the walk ends in the zone
        entry = [k for k, px in enumerate(groups) if np.any(np.all(px == path[-1], axis=1))]
        if entry:
            p0, v0 = Z.arm(z, entry[0])[:2]
            t0 = -v0
        else:  # the walk starts in the zone (heading for its branch pixels), or reached it by a gap
            p0, t0 = path[-1], _direction(path, Z.reach)
            if t0 is None and np.hypot(*(Z.core[z] - p0)) >= 1:  # from the start on through the branch pixels
                p0, t0 = Z.core[z], _unit(Z.core[z] - p0)
            elif t0 is None:
                t0 = _unit(d)
        real = [k for k in free if Z.arm(z, k)[2]]
        spurs = not real   # only spurs left: the string ends (or folds) here whichever is taken, a fold, not a guess
        real = real or free
        pairing = bool(entry) and sum(Z.arm(z, k)[2] for k in range(len(groups))) == 4 and len(real) == 3
        cost = {}
        for k in real:
            p1, v1 = Z.arm(z, k)[:2]
            cost[k] = bending(p0, t0, p1, v1) if t0 is not None else 0.0
            if pairing:  # the other two arms pair up too: the string's other pass through the crossing
                y, w = [j for j in real if j != k]
                (py, vy), (pw, vw) = Z.arm(z, y)[:2], Z.arm(z, w)[:2]
                cost[k] += bending(py, -vy, pw, vw)
        order = sorted(cost, key=cost.get)
        k = order[0]
        unsure = not spurs and len(order) > 1 and (t0 is None or cost[order[1]] - cost[k] < margin)
        first, v = Z.arm(z, k)[:2]
        line = _through(Z.id, z, path[-1], first)
        visited[first[0], first[1]] = True
        passages.setdefault(z, []).append((total, total + len(line), unsure))
        parts.append(line), brid.append(np.zeros(len(line), bool)), amb.append(np.full(len(line), unsure))
        total += len(line)
        p, b, nz = walk_pixels(skel, Z.map, visited, first, max_gap, v, ignore=z)
        parts.append(p), brid.append(b), amb.append(np.r_[unsure, np.zeros(len(p) - 1, bool)])
        total += len(p)
        d, z = v, nz
    pts = np.concatenate(parts).astype(float)
    ambiguous = np.concatenate(amb)
    passed = np.isin(Z.id, list(passages)) if passages else np.zeros(skel.shape, bool)
    folded = np.zeros(len(pts), bool)
    for zz, spans in passages.items():  # every pass through a zone is ambiguous after a guess at any of them,
        left = [Z.arm(zz, k) for k, px in enumerate(Z.exits[zz]) if not visited[px[:, 0], px[:, 1]].any()]
        hard = any(u for _, _, u in spans) or any(arm[2] for arm in left)  # or by a branch never walked; folded
        fold = any(arm[4] >= Z.fold for arm in left)  # by a spur never walked (the end of a fold, a hairpin or a
        for i, j, _ in spans:  # collapsed loop, may hold string length the walk does not measure)
            ambiguous[i:j + 1] |= hard
            folded[i:j + 1] |= fold and not hard
    return pts, np.concatenate(brid), ambiguous, folded, passed
