"""How well a set of calibration views determines the camera: the measures.

A calibration's reprojection error says how well the model fits the views, not how well
the views pin the model down: 12 shots covering only the top 45 % of an image gave a
principal point 24 / 52 px off at 0.30 px rms, with standard deviations 4-13 times smaller
than the errors (issue 25). So a fit is judged three ways (:func:`assess`):

* **Standard deviations**, from the views themselves. ``cv2.calibrateCameraExtended``'s
  standard deviations treat every corner's error as independent, but the corners of one
  view share its blur, lighting, board flatness and detection bias, so they are too small
  by an unknown factor (4-13 in the issue's weak set, < 1 on a clean set of the lab's). A
  delete-a-group jackknife over the views (:func:`jackknife_covariance`: the fit repeated
  with each of up to ``jackknife_groups`` groups of views left out, Efron & Stein 1981)
  measures how far the views disagree, whatever their errors' correlation; each
  parameter's deviation is the larger of the jackknife's and OpenCV's. The full covariance
  of the intrinsics (OpenCV's from the Jacobian, ``cv2.projectPoints``, the views' poses
  eliminated by the Schur complement; the jackknife's from its refits) gives the lens
  distortion's uncertainty at the image's corners, where k1, k2 and k3 are strongly
  correlated and their separate deviations say little.
* **Coverage**: the share of a coarse grid over the image (``coverage_grid``) whose cells
  hold a corner of some view, and the same share in each third of the image's rows and
  columns. Distortion grows towards the edges; a model fitted to corners in one part of the
  image extrapolates there, and trades its distortion for the principal point.
* **Tilt variety**: each view's board normal n (third column of its rotation) against the
  optical axis: the tilt arccos |n_z|, and the variety, the rms tilt about the weaker of
  two image axes (arcsin sqrt of the smaller eigenvalue of mean(n_xy n_xy^T)). Views all
  nearly fronto-parallel, or all turned about one axis, cannot separate the focal length
  from the distance nor place the principal point (Zhang 2000, Sturm & Maybank 1999).

Every limit is a share of the image (or of fx), so it holds for any resolution; the
standard deviations come from the data's own residuals. A deviation larger than what it is about
(a principal point uncertain by more than the image, fx by more than itself, the distortion by
more than the half-diagonal) is quoted as "not determined", not as a number (issue 51: "1.4e6 px").
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from stringcast.core import CalibrationSettings

from .charuco import Intrinsics

INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
"""The intrinsics, in the order of OpenCV's standard deviations."""
_HELD_BY_FLAG = ((cv2.CALIB_FIX_PRINCIPAL_POINT, ("cx", "cy")), (cv2.CALIB_FIX_FOCAL_LENGTH, ("fx", "fy")),
                 (cv2.CALIB_FIX_K1, ("k1",)), (cv2.CALIB_FIX_K2, ("k2",)), (cv2.CALIB_FIX_K3, ("k3",)),
                 (cv2.CALIB_ZERO_TANGENT_DIST, ("p1", "p2")))
ROW_WORDS = ("upper", "middle", "lower")
COLUMN_WORDS = ("left", "centre", "right")


def held_parameters(flags: int) -> tuple[str, ...]:
    """Names (:data:`INTRINSIC_NAMES`) of the intrinsics that ``cv2.calibrateCamera`` flags hold."""
    held = {n for f, names in _HELD_BY_FLAG if flags & f for n in names}
    return tuple(n for n in INTRINSIC_NAMES if n in held)


def intrinsics_covariance(intr: Intrinsics) -> np.ndarray:
    """(9, 9) covariance of :data:`INTRINSIC_NAMES` (rows of held ones 0), as OpenCV's fit sees it.

    sigma^2 (J^T J)^-1 with J the reprojection Jacobian (``cv2.projectPoints``) over the
    free intrinsics and every view's pose, the poses eliminated view by view (Schur
    complement); sigma^2 = SSE / (2 N - parameters). Its diagonal's square root is
    ``cv2.calibrateCameraExtended``'s standard deviations.

    Raises:
        ValueError: ``intr`` has no views (not from :func:`~stringcast.calibrate.charuco.fit_views`).
    """
    if intr.views is None or intr.rvecs is None:
        raise ValueError("intrinsics_covariance: the intrinsics carry no views (use charuco.fit_views)")
    held = held_parameters(intr.flags)
    free = [k for k, n in enumerate(INTRINSIC_NAMES) if n not in held]
    A = np.zeros((len(free), len(free)))
    sse, n_res = 0.0, 0
    for o, i, r, t in zip(intr.views.object_points, intr.views.image_points, intr.rvecs, intr.tvecs):
        p, J = cv2.projectPoints(o.reshape(-1, 3).astype(float), r, t, intr.K, intr.dist)
        res = (p.reshape(-1, 2) - i.reshape(-1, 2)).ravel()
        sse += float(res @ res)
        n_res += len(res)
        Je, Ji = J[:, :6], J[:, 6:15][:, free]          # pose (rvec, tvec); f, c, k1 k2 p1 p2 k3
        Jie = Ji.T @ Je
        A += Ji.T @ Ji - Jie @ np.linalg.solve(Je.T @ Je, Jie.T)
    dof = max(n_res - len(free) - 6 * len(intr.rvecs), 1)
    C = np.zeros((9, 9))
    C[np.ix_(free, free)] = sse / dof * np.linalg.pinv(A)
    return C


def jackknife_covariance(intr: Intrinsics, groups: int = 10) -> np.ndarray:
    """(9, 9) delete-a-group jackknife covariance of :data:`INTRINSIC_NAMES` over the views.

    The views used by ``intr`` are dealt round-robin into g = min(V, ``groups``) groups; the
    fit (``cv2.calibrateCamera``, ``intr``'s flags, no outlier rejection) is repeated with
    each group left out, theta_j, and C = (g - 1) / g sum_j (theta_j - mean)(theta_j - mean)^T
    (Efron & Stein 1981). Held parameters have rows of 0. A refit that fails (too few views
    left for OpenCV) makes the covariance infinite on the diagonal.

    Raises:
        ValueError: ``intr`` has no views (not from :func:`~stringcast.calibrate.charuco.fit_views`).
    """
    if intr.views is None:
        raise ValueError("jackknife_covariance: the intrinsics carry no views (use charuco.fit_views)")
    obj, img = intr.views.object_points, intr.views.image_points
    V = len(obj)
    g = min(V, int(groups))
    if g < 3:
        return np.diag(np.full(9, np.inf))
    thetas = []
    for j in range(g):
        keep = [k for k in range(V) if k % g != j]
        try:
            _, K, dist, _, _ = cv2.calibrateCamera([obj[k] for k in keep], [img[k] for k in keep], intr.image_size,
                                                   intr.K.copy(), intr.dist.copy(), flags=intr.flags)
        except cv2.error:
            return np.diag(np.full(9, np.inf))
        d = np.asarray(dist, float).ravel()[:5]
        thetas.append([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *d])
    th = np.asarray(thetas, float)
    dev = th - th.mean(axis=0)
    return (g - 1) / g * dev.T @ dev


def _combined_covariance(C_cv: np.ndarray, C_jk: np.ndarray) -> np.ndarray:
    """The jackknife's covariance with each deviation raised to at least OpenCV's, its
    correlations kept; infinite on the diagonal (and 0 off it) where the jackknife is not finite."""
    if not np.all(np.isfinite(C_jk)):
        return np.where(np.eye(9, dtype=bool), np.inf, 0.0)
    sd_cv, sd_jk = np.sqrt(np.maximum(np.diag(C_cv), 0)), np.sqrt(np.maximum(np.diag(C_jk), 0))
    sd = np.maximum(sd_cv, sd_jk)
    with np.errstate(invalid="ignore", divide="ignore"):
        R = np.where(np.outer(sd_jk, sd_jk) > 0, C_jk / np.outer(sd_jk, sd_jk), 0.0)
    np.fill_diagonal(R, 1.0)
    return R * np.outer(sd, sd)


def coverage(image_points, image_size: tuple[int, int], grid: tuple[int, int]) -> dict:
    """Which cells of a ``grid`` = (columns, rows) over the image hold a corner of some view.

    Args:
        image_points: per view (N_v, 1, 2) or (N_v, 2) px. image_size: (width, height) px.

    Returns:
        ``{"grid", "share" (of all cells), "cells" (rows x columns of 0/1), "parts" (3 x 3:
        the share of the cells of each ninth of the image, upper to lower, left to right; a
        cell belongs to the ninth holding its centre), "u_span", "v_span" (the corners' extent
        as shares of width and height)}``.
    """
    (w, h), (cols, rows) = image_size, (int(grid[0]), int(grid[1]))
    uv = np.concatenate([np.asarray(p, float).reshape(-1, 2) for p in image_points]) if len(image_points) else np.zeros((0, 2))
    occ = np.zeros((rows, cols), bool)
    occ[np.clip((uv[:, 1] / h * rows).astype(int), 0, rows - 1), np.clip((uv[:, 0] / w * cols).astype(int), 0, cols - 1)] = True

    def third(n):
        return np.minimum(((np.arange(n) + 0.5) / n * 3).astype(int), 2)

    tr, tc = third(rows), third(cols)
    parts = [[float(occ[np.ix_(tr == a, tc == b)].mean()) for b in range(3)] for a in range(3)]

    def span(a, n):
        return [float(a.min() / n), float(a.max() / n)] if len(a) else [0.0, 0.0]

    return {"grid": [cols, rows], "share": float(occ.mean()), "cells": occ.astype(int).tolist(), "parts": parts,
            "u_span": span(uv[:, 0], w), "v_span": span(uv[:, 1], h)}


def thin_parts(cov: dict, limit: float) -> str | None:
    """Where the coverage (:func:`coverage`) is under ``limit``, in words: whole thirds first
    ("the middle and lower thirds"), then single ninths ("the upper-left part"); None if nowhere."""
    thin = np.asarray(cov["parts"]) < limit
    rows = [ROW_WORDS[a] for a in range(3) if thin[a].all()]
    cols = [COLUMN_WORDS[b] for b in range(3) if thin[:, b].all()]
    rest = ["central" if (a, b) == (1, 1) else f"{ROW_WORDS[a]}-{COLUMN_WORDS[b]}" for a in range(3) for b in range(3)
            if thin[a, b] and not thin[a].all() and not thin[:, b].all()]
    words = []
    for names, what in ((rows, "third"), (cols, "third"), (rest, "part")):
        if names:
            words.append(f"the {' and '.join(names)} {what}{'s' if len(names) > 1 else ''}")
    return ", ".join(words) if words else None


def tilt_spread(rvecs: np.ndarray) -> dict:
    """How the views' boards tilt against the optical axis.

    Args:
        rvecs: (V, 3) Rodrigues vectors, board -> camera.

    Returns:
        ``{"tilt_deg" (per view: arccos |n_z| of the board normal n), "min_deg", "median_deg",
        "max_deg", "spread_deg" (their standard deviation), "variety_deg" (rms tilt about the
        weaker image axis: views all tilted 30 deg about one axis have a spread of 0 and
        a variety of 0, about random axes a spread of 0 and a variety of ~21), "weak_axis"
        ("vertical": turns about the image's vertical axis are missing, or "horizontal")}``.
    """
    n = np.array([cv2.Rodrigues(np.asarray(r, float))[0][:, 2] for r in np.asarray(rvecs, float).reshape(-1, 3)])
    tilt = np.degrees(np.arccos(np.clip(np.abs(n[:, 2]), 0, 1)))
    lam, vec = np.linalg.eigh(n[:, :2].T @ n[:, :2] / max(len(n), 1))
    # the normal lacks its x component (vec along x) when the board never turns left/right,
    # i.e. about the image's vertical axis
    return {"tilt_deg": [float(t) for t in tilt], "min_deg": float(tilt.min()), "median_deg": float(np.median(tilt)),
            "max_deg": float(tilt.max()), "spread_deg": float(np.std(tilt)),
            "variety_deg": float(np.degrees(np.arcsin(math.sqrt(min(max(lam[0], 0.0), 1.0))))),
            "weak_axis": "vertical" if abs(vec[0, 0]) > abs(vec[1, 0]) else "horizontal"}


def distortion_sd_px(intr: Intrinsics, C: np.ndarray) -> float:
    """The largest standard deviation (px) of the lens distortion's displacement at the image's
    four corners, from the covariance ``C`` (9, 9) of (fx .. k3): the rays seen at the corners
    held, only (k1, k2, p1, p2, k3) varied (OpenCV's model, its derivatives in closed form)."""
    w, h = intr.image_size
    corners = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], float).reshape(-1, 1, 2)
    xy = cv2.undistortPoints(corners, intr.K, intr.dist).reshape(-1, 2)
    Cd = C[4:, 4:]
    out = 0.0
    for x, y in xy:
        r2 = x * x + y * y
        gx = intr.K[0, 0] * np.array([x * r2, x * r2 ** 2, 2 * x * y, r2 + 2 * x * x, x * r2 ** 3])
        gy = intr.K[1, 1] * np.array([y * r2, y * r2 ** 2, r2 + 2 * y * y, 2 * x * y, y * r2 ** 3])
        out = max(out, math.sqrt(max(gx @ Cd @ gx + gy @ Cd @ gy, 0.0)))
    return out


def assess(intr: Intrinsics, st: CalibrationSettings) -> tuple[dict, dict[str, tuple[str, str]]]:
    """The measures of one fit and what they find wrong.

    Args:
        intr: a fit from :func:`~stringcast.calibrate.charuco.fit_views`.
        st: :class:`~stringcast.core.CalibrationSettings` (the limits).

    Returns:
        (measures for ``calibration.json``, problems ``{kind: (what was found, which shots to
        add, the measure over its limit (> 1))}`` with kind among ``coverage``, ``tilt``,
        ``principal_point``, ``fx``, ``distortion``).
    """
    w, h = intr.image_size
    C_cv = intrinsics_covariance(intr)
    C = _combined_covariance(C_cv, jackknife_covariance(intr, st.jackknife_groups))
    sd = np.sqrt(np.maximum(np.diag(C), 0))
    cov = coverage(intr.views.image_points, intr.image_size, st.coverage_grid)
    tilt = tilt_spread(intr.rvecs)
    half_diag = 0.5 * math.hypot(w, h)
    d_sd = distortion_sd_px(intr, C)
    pp = (float(sd[2] / w), float(sd[3] / h))
    fx_sd = float(sd[0] / intr.K[0, 0])
    doc = {"rms_px": intr.rms_px, "n_views": intr.n_views, "views_found": intr.views_found,
           "views_rejected": intr.views_rejected, "held": list(held_parameters(intr.flags)),
           "std": dict(zip(INTRINSIC_NAMES, map(float, intr.std))),
           "std_used": dict(zip(INTRINSIC_NAMES, map(float, sd))),
           "principal_point_sd_share": list(pp), "fx_sd_share": fx_sd,
           "distortion_sd_px": d_sd, "distortion_sd_share": d_sd / half_diag,
           "covariance": C.tolist() if np.all(np.isfinite(C)) else None,
           "per_view_rms_px": dict(zip(intr.views.names, intr.per_view_rms_px)),
           "coverage": cov, "tilt": tilt}
    problems: dict[str, tuple[str, str, float]] = {}
    thin = thin_parts(cov, st.min_coverage)
    if cov["share"] < st.min_coverage or thin:
        problems["coverage"] = (f"the views' corners cover {cov['share']:.0%} of a {cov['grid'][0]}x{cov['grid'][1]} "
                                f"grid over the image (rows {cov['v_span'][0]:.0%}-{cov['v_span'][1]:.0%}, columns "
                                f"{cov['u_span'][0]:.0%}-{cov['u_span'][1]:.0%})",
                                f"add shots with the board in {thin or 'the image edges and corners'} of the image",
                                st.min_coverage / max(cov["share"], 1e-9))
    lo = st.min_tilt_variety_deg
    turn = {"vertical": "its vertical axis (left/right)", "horizontal": "its horizontal axis (top/bottom)"}
    tilt_advice = f"add shots with the board tilted by {2 * lo:.0f}-{4 * lo:.0f} deg about {turn[tilt['weak_axis']]}"
    if tilt["variety_deg"] < lo:
        problems["tilt"] = (f"the views vary little in tilt ({tilt['variety_deg']:.1f} deg rms about the weaker axis, "
                            f"< {lo:g}; tilts {tilt['min_deg']:.0f}-{tilt['max_deg']:.0f} deg)", tilt_advice,
                            lo / max(tilt["variety_deg"], 1e-9))
    if "cx" not in doc["held"] and max(pp) > st.max_principal_point_sd:
        what = ("not determined (uncertain by more than the image's size)" if not max(pp) <= 1 else
                f"uncertain by {sd[2]:.1f} / {sd[3]:.1f} px ({max(pp):.1%} of the image, standard deviations, "
                "jackknife over the views)")
        problems["principal_point"] = (f"the principal point is {what}", tilt_advice, max(pp) / st.max_principal_point_sd)
    if fx_sd > st.max_fx_sd:
        what = ("not determined (uncertain by more than itself)" if not fx_sd <= 1 else
                f"uncertain by {fx_sd:.1%} (standard deviation, jackknife over the views)")
        problems["fx"] = (f"fx is {what}", tilt_advice, fx_sd / st.max_fx_sd)
    if d_sd / half_diag > st.max_distortion_sd:
        what = ("not determined (uncertain by more than the half-diagonal)" if not d_sd <= half_diag else
                f"uncertain by {d_sd:.1f} px ({d_sd / half_diag:.2%} of the half-diagonal)")
        problems["distortion"] = (f"the lens distortion at the image's corners is {what}",
                                  "add shots with the board near the image's corners",
                                  d_sd / half_diag / st.max_distortion_sd)
    return doc, problems
