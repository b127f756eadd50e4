"""The sync stage's strip sampling kernel: :func:`~stringcast.sync.arm_match.sample_strips` in one
compiled pass. Its NumPy/SciPy reference is ``arm_match.sample(image, calibration, strip_points(...))``,
which ``tests/sync`` holds it to bit for bit.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(inline="always", fastmath=False, error_model="numpy")
def _pixel_value(img, x, y, Hi, cam, r0, c0, h, w):
    """The (h, w) frame bilinear at the pixel of plane point (x, y) m: Hi (3, 3) plane -> undistorted pixel
    homography (as ``cv2.perspectiveTransform``), cam (10,) ``arm_match._camera`` (distortion as
    ``Calibration.distort``), the edge pixels held beyond the frame (``map_coordinates``, order 1, mode
    "nearest"). img is the frame's window from row r0, column c0 (the whole frame: 0, 0); NaN where the
    pixel and its neighbours are not all in the window."""
    z = Hi[2, 0] * x + Hi[2, 1] * y + Hi[2, 2]
    z = 1.0 / z if abs(z) > 2.220446049250313e-16 else 0.0
    u = (Hi[0, 0] * x + Hi[0, 1] * y + Hi[0, 2]) * z
    v = (Hi[1, 0] * x + Hi[1, 1] * y + Hi[1, 2]) * z
    if cam[9]:
        fx, fy, cx, cy, k1, k2, p1, p2, k3 = cam[0], cam[1], cam[2], cam[3], cam[4], cam[5], cam[6], cam[7], cam[8]
        xn, yn = (u - cx) / fx, (v - cy) / fy
        r2 = xn * xn + yn * yn
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = xn * radial + 2 * p1 * xn * yn + p2 * (r2 + 2 * xn * xn)
        yd = yn * radial + p1 * (r2 + 2 * yn * yn) + 2 * p2 * xn * yn
        u, v = xd * fx + cx, yd * fy + cy
    r = min(max(v, 0.0), h - 1.0)
    c = min(max(u, 0.0), w - 1.0)
    i, j = min(int(r), h - 2), min(int(c), w - 2)
    a, b = r - i, c - j
    i, j = i - r0, j - c0
    if i < 0 or j < 0 or i + 1 >= img.shape[0] or j + 1 >= img.shape[1]:
        return np.nan
    return ((1 - a) * ((1 - b) * img[i, j] + b * img[i, j + 1])
            + a * ((1 - b) * img[i + 1, j] + b * img[i + 1, j + 1]))


@njit(cache=True, fastmath=False, error_model="numpy")
def strips_kernel(img, fk, segments, u, v, shift, Hi, cam, out, r0, c0, h, w):
    """out[t, s, a, b] = :func:`_pixel_value` at strip point a + u[a] d + v[s, b] nrm + shift of segment
    segments[s] (from joint fk[t, j] to fk[t, j + 1], (T, J + 2, 2) m), as :func:`~stringcast.sync.arm_match.strip_points` computes it;
    img is the (h, w) frame's window from row r0, column c0."""
    for t in range(fk.shape[0]):
        for s in range(segments.shape[0]):
            j = segments[s]
            ax, ay = fk[t, j, 0], fk[t, j, 1]
            dx, dy = fk[t, j + 1, 0] - ax, fk[t, j + 1, 1] - ay
            norm = max(np.sqrt(dx * dx + dy * dy), 1e-9)
            ex, ey = dx / norm, dy / norm
            for a in range(u.shape[0]):
                for b in range(v.shape[1]):
                    x = ax + u[a] * dx + v[s, b] * -ey + shift[0]
                    y = ay + u[a] * dy + v[s, b] * ex + shift[1]
                    out[t, s, a, b] = _pixel_value(img, x, y, Hi, cam, r0, c0, h, w)
