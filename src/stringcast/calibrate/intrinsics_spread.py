"""How far the intrinsics' own uncertainty moves the swing plane's mapping away from the board (issue 51).

The calibration maps a pixel to the swing plane by undistorting it (K, dist) and one homography
fitted to the trial's board under those intrinsics. At the board the mapping is right whatever
the intrinsics (the homography absorbs them there); away from it an error of the intrinsics is
carried along, growing with the distance from the board: a weak calibration set (the issue's
field footage: the still arm seen 6-36 mm from where a right board pose put it) moves the arm
seen far from the board by many millimetres, while a wrong board pose moves every point alike.

:func:`mapping_modes` propagates the intrinsics' covariance (the calibration's
``intrinsics.covariance``: the jackknife over the views with OpenCV's deviations as a floor,
:func:`stringcast.calibrate.quality.assess`) to points of the plane, to first order: each
parameter is moved by one standard deviation either way, the homography refitted to the trial's
board under it (``refit``), and the points' mapped positions differenced (central differences on
the scale of the uncertainty itself, which also catches the mapping's curvature there). Where the
calibration held parameters (the views did not determine them), the held values are
assumptions: the error about the mapping used is then the held fit's distance from the free fit
(an equally good fit of the views) plus the free fit's own covariance.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
"""The intrinsics in the covariance's order (:data:`stringcast.calibrate.quality.INTRINSIC_NAMES`)."""


def _with(K: np.ndarray, dist: np.ndarray, i: int, step: float) -> tuple[np.ndarray, np.ndarray]:
    """(K, dist) with parameter ``i`` of :data:`NAMES` moved by ``step`` (px or unitless)."""
    K, d = np.array(K, float), np.zeros(5)
    d[:min(5, len(np.ravel(dist)))] = np.ravel(dist)[:5]
    if i < 4:
        K[(0, 1, 0, 1)[i], (0, 1, 2, 2)[i]] += step
    else:
        d[i - 4] += step
    return K, d


def mapping_modes(points: np.ndarray, calibration, covariance, refit: Callable, free: dict | None = None
                  ) -> np.ndarray | None:
    """(N, 2, M) m: the modes of how the intrinsics' uncertainty moves where ``calibration`` maps the
    swing-plane ``points`` (N, 2) m (module doc): the mapped points move by G xi with xi standard normal
    (M,), so their covariance is G G^T (:func:`mapping_covariance`), and that of any linear function of
    them (the board check's translation) follows.

    Args:
        points: (N, 2) m, robot-frame points of the swing plane (seen at ``calibration.robot_to_pixel``).
        calibration: the :class:`~stringcast.calibrate.mapping.Calibration` used (with K, dist).
        covariance: (9, 9) of :data:`NAMES` for its intrinsics (rows of held ones 0), or None.
        refit: ``(K, dist) -> Calibration``: the mapping with the homography refitted to the trial's
            board under those intrinsics (:func:`~stringcast.calibrate.calibration.plane_homography`).
        free: where parameters were held, the free fit's ``{"K", "dist", "covariance"}``, else None: its
            distance from the held fit is one more mode, of weight 1.

    Returns:
        The modes, or None without a finite covariance (the intrinsics' uncertainty not determined)
        or without intrinsics.
    """
    base = free if free is not None else {"K": calibration.K, "dist": calibration.dist, "covariance": covariance}
    C = None if base.get("covariance") is None else np.asarray(base["covariance"], float)
    if calibration.K is None or C is None or C.shape != (9, 9) or not np.all(np.isfinite(C)):
        return None
    pts = np.asarray(points, float).reshape(-1, 2)
    u = calibration.robot_to_pixel(pts)
    at = calibration.pixel_to_robot(u)
    sd = np.sqrt(np.maximum(np.diag(C), 0.0))
    J = np.zeros((len(pts), 2, 9))
    for i in np.nonzero(sd > 0)[0]:
        hi, lo = (refit(*_with(base["K"], base["dist"], i, s * sd[i])).pixel_to_robot(u) for s in (1, -1))
        J[:, :, i] = (hi - lo) / (2 * sd[i])
    lam, V = np.linalg.eigh(0.5 * (C + C.T))
    G = J @ (V * np.sqrt(np.maximum(lam, 0.0)))                     # C = (V sqrt(lam)) (V sqrt(lam))^T
    if free is not None:   # the held fit's distance from the free fit, a known part of its error
        delta = refit(np.asarray(free["K"], float), np.asarray(free["dist"], float)).pixel_to_robot(u) - at
        G = np.concatenate([G, delta[:, :, None]], axis=2)
    return G


def mapping_covariance(*args, **kwargs) -> np.ndarray | None:
    """(N, 2, 2) m^2: the covariance of each mapped point, G G^T of :func:`mapping_modes` (same arguments)."""
    G = mapping_modes(*args, **kwargs)
    return None if G is None else np.einsum("nam,nbm->nab", G, G)
