"""The skeleton walk at junctions (stringcast.track.junctions) and the pixel walk's NumPy reference."""
import math

import cv2
import numpy as np
from skimage.morphology import skeletonize

from stringcast.track.junctions import bending, junction_zones, walk_skeleton
from stringcast.track.skeleton_walk import trace_path, walk_pixels, walk_pixels_reference


def _skeleton(polylines, shape=(120, 160), width=3):
    """Skeleton of thick polylines ((K, 2) (x, y) px each) drawn into an image of ``shape``."""
    img = np.zeros(shape, np.uint8)
    for p in polylines:
        cv2.polylines(img, [np.round(np.asarray(p)).astype(np.int32)], False, 1, width)
    return skeletonize(img > 0)


def test_walk_goes_straight_through_an_x_crossing():
    """Two strokes cross at 50 deg; the walk from one end of stroke A leaves the crossing on A
    (a thin skeleton draws the crossing as two three-way junctions joined by a short piece)."""
    a = np.array([[10.0, 60.0], [150.0, 60.0]])  # horizontal
    t = math.radians(50)
    b = np.array([[80 - 60 * math.cos(t), 60 - 60 * math.sin(t)], [80 + 60 * math.cos(t), 60 + 60 * math.sin(t)]])
    skel = _skeleton([a, b])
    assert junction_zones(skel, 3.0).max() == 1  # one crossing (however the skeleton drew it)
    start = np.argwhere(skel)[np.argmin(np.argwhere(skel)[:, 1])]  # the left end of A
    pts, bridged, ambiguous, _, passed = walk_skeleton(skel, start, 6.0, (0, 1), width_px=3.0)
    assert abs(pts[-1][0] - 60) <= 1 and pts[-1][1] >= 145  # it ended at A's right end
    assert np.all(np.abs(pts[:, 0] - 60) <= 3)  # never turned onto B
    assert not bridged.any() and passed.any()
    # stroke B is never walked: something else crosses there, so the pass is marked ambiguous (only it)
    assert ambiguous.any() and np.all(np.hypot(pts[ambiguous, 0] - 60, pts[ambiguous, 1] - 80) <= 6)


def test_walk_follows_a_loop_through_its_crossing_twice():
    """An alpha loop: the string comes in, curls round and crosses its own path; the walk from the
    start visits the curve in order (through the crossing twice) and to its end, unambiguously."""
    u = np.linspace(-np.pi, np.pi, 600)  # a prolate trochoid: one loop, crossing itself at ~95 deg
    x, y = 80 + 12 * u - 30 * np.sin(u), 70 - 30 * np.cos(u)
    x = np.concatenate([np.linspace(10, x[0], 60, endpoint=False), x, np.linspace(x[-1], 150, 60)[1:]])
    y = np.concatenate([np.full(60, y[0]), y, np.full(59, y[-1])])
    curve = np.column_stack([x, y])
    skel = _skeleton([curve])
    zones = junction_zones(skel, 3.0)
    assert zones.max() >= 1
    start = np.argwhere(skel)[np.argmin(np.argwhere(skel)[:, 1])]
    pts, bridged, ambiguous, _, _ = walk_skeleton(skel, start, 6.0, (0, 1), width_px=3.0)
    k, worst = 0, 0.0  # follow the curve along the walk: each walk pixel near the curve just ahead
    for p in pts:
        j = np.arange(max(k - 10, 0), min(k + 30, len(curve)))
        d = np.hypot(curve[j, 0] - p[1], curve[j, 1] - p[0])
        k, worst = int(j[np.argmin(d)]), max(worst, float(d.min()))
    assert worst < 3.0, worst  # a wrong turn at the crossing would leave the curve just ahead
    assert k >= len(curve) - 10 and not ambiguous.any() and not bridged.any()


def test_a_symmetric_fork_and_an_unwalked_branch_are_ambiguous():
    """A stroke that splits into two at +-35 deg: either way is a guess. A side branch the walk
    passes by: the ordering there is ambiguous too (the branch could be the string's)."""
    fork = _skeleton([[[10, 60], [80, 60]], [[80, 60], [150, 60 + 70 * math.tan(math.radians(35))]],
                      [[80, 60], [150, 60 - 70 * math.tan(math.radians(35))]]])
    start = np.argwhere(fork)[np.argmin(np.argwhere(fork)[:, 1])]
    pts, _, ambiguous, _, _ = walk_skeleton(fork, start, 6.0, (0, 1), width_px=3.0)
    assert ambiguous.any() and not ambiguous[:50].any()
    tee = _skeleton([[[10, 60], [150, 60]], [[80, 60], [80, 110]]])
    start = np.argwhere(tee)[np.argmin(np.argwhere(tee)[:, 1])]
    pts, _, ambiguous, _, _ = walk_skeleton(tee, start, 6.0, (0, 1), width_px=3.0)
    assert pts[-1][1] >= 145 and np.all(np.abs(pts[:, 0] - 60) <= 3)  # straight on
    assert ambiguous.any() and abs(float(np.mean(pts[ambiguous, 1])) - 80) < 5  # at the branch


def test_bending_is_zero_straight_and_grows_with_the_turn():
    t = np.array([1.0, 0.0])
    assert bending([0, 0], t, [10, 0], t) < 1e-12
    turns = [bending([0, 0], t, [10 * math.cos(a / 2), 10 * math.sin(a / 2)], np.array([math.cos(a), math.sin(a)]))
             for a in np.radians([20, 45, 90])]
    assert turns[0] < turns[1] < turns[2] and turns[2] > 1.0


def test_pixel_walk_matches_its_numpy_reference():
    """The compiled pixel walk and the plain NumPy one agree exactly on random skeletons with zones."""
    rng = np.random.default_rng(1)
    runs = 0
    for t in range(120):
        img = np.zeros((60, 80), np.uint8)
        for _ in range(rng.integers(1, 5)):
            p = (rng.random((rng.integers(2, 5), 2)) * [80, 60]).astype(np.int32)
            cv2.polylines(img, [p], False, 1, int(rng.integers(1, 5)))
        img[rng.random(img.shape) < 0.02] = 0  # holes: gaps to bridge
        skel = np.ascontiguousarray(skeletonize(img > 0))
        zl = junction_zones(skel, 3.0)
        zmap = zl.copy()
        zmap[skel & (zl == 0) & (cv2.dilate(zl.astype(np.float32), np.ones((3, 3), np.uint8)) > 0)] = -1
        ys, xs = np.nonzero(skel & (zl == 0))
        if len(ys) == 0:
            continue
        i = rng.integers(len(ys))
        d = None if t % 3 == 0 else rng.normal(size=2)
        v1, v2 = np.zeros(skel.shape, bool), np.zeros(skel.shape, bool)
        a = walk_pixels(skel, zmap, v1, (ys[i], xs[i]), 6.0, d)
        b = walk_pixels_reference(skel, zmap, v2, (ys[i], xs[i]), 6.0, d)
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) and a[2] == b[2] and np.array_equal(v1, v2)
        runs += 1
    assert runs > 100
    # without zones the stretch is the whole plain walk
    skel = _skeleton([[[10, 60], [150, 60]]])
    start = np.argwhere(skel)[0]
    p, _ = trace_path(skel, start, 6.0, (0, 1))
    assert p[-1][1] >= 145


def test_a_fork_of_two_spurs_at_the_end_is_a_fold_not_a_guess():
    """A stroke whose end splits into two short spurs (a small clay ball's skeleton, generalization
    seed 17): the string ends there whichever spur is taken, so the choice is no ambiguity (which
    refused the free end); the spur not taken marks a fold. Longer arms stay a guess."""
    def forked(arm):
        skel = np.zeros((120, 160), bool)
        skel[60, 10:81] = True
        for k in range(1, arm + 1):
            skel[60 - k, 80 + k] = skel[60 + k, 80 + k] = True
        return skel
    start = np.array([60, 10])
    pts, _, ambiguous, folded, _ = walk_skeleton(forked(3), start, 6.0, (0, 1), width_px=3.0)
    assert pts[-1][1] >= 82 and not ambiguous.any()
    assert folded.any() and np.all(pts[folded, 1] >= 78)   # at the fork only
    pts, _, ambiguous, _, _ = walk_skeleton(forked(20), start, 6.0, (0, 1), width_px=3.0)
    assert ambiguous.any() and np.all(pts[ambiguous, 1] >= 78)
