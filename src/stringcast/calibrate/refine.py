"""The swing plane's mapping refined by the arm's sweep and the trial's board (issue 25).

The calibration maps a recorded pixel to the swing plane by undistorting it (K, dist from the
calib/ shots) and one homography H fitted to the trial's board. Away from the board both
extrapolate: a distortion a weak shot set got wrong bends the far side of the swing region by
2-7 mm, while the board's corners stay right. The arm's link rows
(:func:`~stringcast.calibrate.arm_sweep.sweep_rows`) say, across the region the arm sweeps,
where the mapping puts each link's centre line against forward kinematics.

:func:`refine_mapping` re-estimates the mapping's parameters that a plane's view depends on,
the distortion (k1, k2), its centre (cx, cy, with the camera matrix's) and H, from both:

* each row: n . (map(u) - p) = v dt, with u the pixel where the calibration saw the link's
  centre, p the FK point, n the link's normal, v the point's velocity along n and dt the
  clock's error (fitted too, when asked: the moving rows then measure the sync);
* each board corner the calibration used: map(u_c) = its robot-frame point, within the
  board's reprojection error;
* optionally a Gaussian prior on the lens parameters freed (``prior_sd``): how far the trial
  may move the calibration's k1 and principal point. The rows pin the mapping where the arm
  reaches; the prior keeps a lens parameter that the rows barely see (a principal point under
  a weak distortion) from wandering, and so from bending the mapping beyond the arm's reach.

``scipy.optimize.least_squares`` solves it, with a Huber loss on the rows and corners and a
plain quadratic on the prior; the rows' noise scale is taken from the rows themselves (their
median absolute deviation after a first fit), not set.

**Covariance.** The rows of one frame share that frame's errors (its blur, its links' edges
found against the same background, its exposure's timing), so they are not independent pieces of
evidence: the Gauss-Newton covariance, which treats them so, put the clock's standard error at
0.01-0.03 ms on the generalization setups whose even and odd frames' clocks differed by 0.07-0.3
ms (issue 51). The covariance is the M-estimator's sandwich with the rows clustered by frame
(Liang & Zeger 1986; White 1980): B^-1 M B^-1, B = sum w J^T J (w the Huber loss's weight of
each residual), M = sum over frames of (sum of the frame's w r J)(...)^T, each board corner a
cluster of its own, and the prior's own precision; times G / (G - 1) for G frames (the
small-sample factor CR1). ``covariance_iid`` keeps the old one.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.optimize import least_squares

from .mapping import Calibration, apply_homography

SCALE_M = 0.5
"""Robot-frame coordinates are divided by this inside the fit (the swing region is ~1 m)."""


def _calibration(base: Calibration, theta: np.ndarray) -> Calibration:
    """The mapping of parameters theta = (h (8), dk1, dk2, dcx px, dcy px[, dt]) around ``base``."""
    h = theta[:8]
    S = np.diag([SCALE_M, SCALE_M, 1.0])
    C = S @ np.array([[1 + h[0], h[1], h[2]], [h[3], 1 + h[4], h[5]], [h[6], h[7], 1.0]]) @ np.linalg.inv(S)
    K, dist = base.K.copy(), base.dist.copy()
    dist[0] += theta[8]
    dist[1] += theta[9]
    K[0, 2] += theta[10]
    K[1, 2] += theta[11]
    # the old undistorted pixels move with the new centre: H' maps the new undistorted pixels
    return replace(base, H_pixel_to_robot=C @ base.H_pixel_to_robot, K=K, dist=dist)


PARAMETERS = ("h0", "h1", "h2", "h3", "h4", "h5", "h6", "h7", "k1", "k2", "cx", "cy", "dt")
"""The fit's parameters: the homography's correction, the distortion's, its centre's, the clock's."""
GROUPS = {"H": PARAMETERS[:8], "k1": ("k1",), "k2": ("k2",), "c": ("cx", "cy"), "dt": ("dt",)}
DT = PARAMETERS.index("dt")
LENS = slice(PARAMETERS.index("k1"), PARAMETERS.index("cy") + 1)
"""The lens's parameters in theta (k1, k2, cx, cy): the pixels' undistortion depends on these alone."""


def _robust_sigma(r: np.ndarray) -> float:
    """1.4826 x the median absolute deviation of r, floored at 1e-5 (m)."""
    return max(float(1.4826 * np.median(np.abs(r - np.median(r)))), 1e-5)


class _Undistorted:
    """The rows' and corners' pixels (N, 2) undistorted under the lens of theta, kept per lens: a
    finite-difference step in the homography or the clock reuses its point's undistortion
    (``Calibration.undistort`` is most of a residual's cost)."""

    def __init__(self, uv: np.ndarray):
        self.uv, self.kept = uv, {}

    def __call__(self, theta: np.ndarray, cal: Calibration) -> np.ndarray:
        key = theta[LENS].tobytes()
        if key not in self.kept:
            if len(self.kept) > 8:
                self.kept.clear()
            self.kept[key] = cal.undistort(self.uv)
        return self.kept[key]


def _residuals(free_theta, free, base, undistorted, rows, xy_corners, sigma_rows, sigma_corners, prior_sd):
    theta = np.zeros(len(PARAMETERS))
    theta[free] = free_theta   # dt stays 0 unless it is free
    cal = _calibration(base, theta)
    xy = apply_homography(cal.H_pixel_to_robot, undistorted(theta, cal))   # cal.pixel_to_robot of rows, corners
    m = xy[:len(rows)] - rows[:, 1:3]
    r_rows = (np.sum(m * rows[:, 3:5], 1) - rows[:, 6] * theta[DT]) / sigma_rows
    r_corners = ((xy[len(rows):] - xy_corners) / sigma_corners).ravel()
    return np.concatenate([r_rows, r_corners, (free_theta / prior_sd)[np.isfinite(prior_sd)]])


def _huber_then_quadratic(scale: float, n_robust: int):
    """``least_squares``' loss (rho, rho', rho'' of z = r**2): Huber of scale ``scale`` on the first
    ``n_robust`` residuals (rows, corners), plain least squares on the rest (the prior)."""
    def loss(z):
        with np.errstate(divide="ignore", invalid="ignore"):
            s = z / scale ** 2
            inner = s <= 1
            rho = np.empty((3, len(z)))
            rho[0] = np.where(inner, s, 2 * np.sqrt(s) - 1) * scale ** 2
            rho[1] = np.where(inner, 1.0, 1 / np.sqrt(s))
            rho[2] = np.where(inner, 0.0, -0.5 * s ** -1.5) / scale ** 2
        rho[0, n_robust:], rho[1, n_robust:], rho[2, n_robust:] = z[n_robust:], 1.0, 0.0
        return rho
    return loss


def refine_mapping(calibration: Calibration, rows: np.ndarray, corners_xy: np.ndarray,
                   max_speed_m_s: float | None = None, fit: tuple[str, ...] = ("H", "dt"),
                   huber: float = 2.0, prior_sd: dict[str, float] | None = None) -> dict:
    """Refit the mapping (and the clock) to the arm's rows and the board's corners.

    Args:
        calibration: the trial's :class:`~stringcast.calibrate.mapping.Calibration` (with K, dist).
        rows: (K, 7) :func:`~stringcast.calibrate.arm_sweep.sweep_rows` table, measured under it.
        corners_xy: (C, 2) m, robot-frame points of the board corners the calibration used.
        max_speed_m_s: rows faster than this along their normal are left out (None: all; the
            moving rows are what measure the clock).
        fit: the parameter groups fitted (:data:`GROUPS`); default the homography and the clock.
            Freeing the distortion without a prior let it bend where the arm does not reach; the sweep
            frees k1 and the principal point under ``prior_sd`` (:func:`stringcast.sync.sweep.lens_fit`;
            docs/results.md, "the sweep refits the lens").
        huber: the Huber loss's scale, in units of the rows' own noise.
        prior_sd: {parameter name: standard deviation} of a zero-mean Gaussian prior on the
            change of a freed parameter (k1; cx, cy in px); a freed parameter not named has none.

    Returns:
        ``{"calibration" (refined), "theta" (13,), "covariance" (P, P) of the free parameters (the
        rows clustered by frame, module doc), "covariance_iid" (the rows taken as independent),
        "free" (P,) their indices in :data:`PARAMETERS`, "dt_s", "dt_standard_error_s" and
        "dt_standard_error_iid_s" (None unless fitted), "rows", "sigma_rows_mm", "rms_before_mm",
        "rms_after_mm"}``: the rms of the used rows' offsets before, and of their residuals after.

    Raises:
        ValueError: a calibration without intrinsics, or fewer than 4 rows per parameter.
    """
    if calibration.K is None:
        raise ValueError("refine_mapping: the calibration has no intrinsics (K, dist) to refine")
    use = rows if max_speed_m_s is None else rows[np.abs(rows[:, 6]) <= max_speed_m_s]
    free = np.array([PARAMETERS.index(n) for g in fit for n in GROUPS[g]])
    fit_dt = "dt" in fit
    if len(use) < 4 * len(free):
        raise ValueError(f"refine_mapping: {len(use)} rows, need >= {4 * len(free)}")
    u_rows = calibration.robot_to_pixel(use[:, 1:3] + use[:, 5:6] * use[:, 3:5])
    u_corners = calibration.robot_to_pixel(corners_xy)
    sigma_corners = max(calibration.reprojection_error_px, 0.1) * float(np.median(calibration.m_per_px(u_corners)))
    sd = np.array([(prior_sd or {}).get(PARAMETERS[i], np.inf) for i in free], float)
    if np.any(sd <= 0):
        raise ValueError(f"refine_mapping: prior standard deviations must be > 0, got {prior_sd}")
    # no prior: scipy's own Huber (the same numbers as before the prior existed)
    loss = _huber_then_quadratic(huber, len(use) + u_corners.size) if np.isfinite(sd).any() else "huber"
    undistorted = _Undistorted(np.concatenate([u_rows, u_corners]))
    x = np.zeros(len(free))
    sigma = _robust_sigma(use[:, 5])
    for _ in range(2):  # the rows' noise from the residuals of the previous fit
        used = sigma
        sol = least_squares(_residuals, x, loss=loss, f_scale=huber if loss == "huber" else 1.0, x_scale="jac",
                            args=(free, calibration, undistorted, use, corners_xy, used, sigma_corners, sd))
        x = sol.x
        r = sol.fun[:len(use)] * used
        sigma = _robust_sigma(r)
    J = sol.jac
    cov_iid = np.linalg.pinv(J.T @ J) * (sigma / used) ** 2
    args = (free, calibration, undistorted, use, corners_xy, used, sigma_corners, sd)
    cov = _clustered_covariance(x, args, sol.fun, use[:, 0], u_corners.size, huber)
    theta = np.zeros(len(PARAMETERS))
    theta[free] = x
    k = list(free).index(DT) if fit_dt else None
    return {"calibration": _calibration(calibration, theta), "theta": theta, "covariance": cov,
            "covariance_iid": cov_iid, "free": free, "dt_s": float(theta[DT]) if fit_dt else None,
            "dt_standard_error_s": float(np.sqrt(cov[k, k])) if fit_dt else None,
            "dt_standard_error_iid_s": float(np.sqrt(cov_iid[k, k])) if fit_dt else None,
            "rows": int(len(use)), "sigma_rows_mm": sigma * 1000,
            "rms_before_mm": float(np.sqrt(np.mean(use[:, 5] ** 2)) * 1000),
            "rms_after_mm": float(np.sqrt(np.mean(r ** 2)) * 1000)}


def _clustered_covariance(x: np.ndarray, args: tuple, f: np.ndarray, frames: np.ndarray, n_corner: int,
                          huber: float, step: float = 1e-7) -> np.ndarray:
    """(P, P): the fit's covariance with the rows clustered by frame (module doc, "Covariance").

    ``x`` the free parameters at the solution, ``args`` :func:`_residuals`' other arguments, ``f`` its
    residuals there (rows (R,), corners (n_corner,), prior), ``frames`` (R,) each row's frame, ``huber``
    the loss's scale (units of the residuals); the Jacobian by central differences of ``step`` x
    max(1, |x|)."""
    R = len(frames)
    J = np.empty((len(f), len(x)))
    for j in range(len(x)):
        h = step * max(1.0, abs(float(x[j])))
        hi, lo = x.copy(), x.copy()
        hi[j] += h
        lo[j] -= h
        J[:, j] = (_residuals(hi, *args) - _residuals(lo, *args)) / (2 * h)
    n_data = R + n_corner
    w = np.ones(len(f))
    w[:n_data] = np.minimum(1.0, huber / np.maximum(np.abs(f[:n_data]), 1e-12))
    B = J.T @ (J * w[:, None])
    score = (w * f)[:, None] * J
    _, cluster = np.unique(frames, return_inverse=True)
    G = int(cluster.max()) + 1
    per_frame = np.zeros((G, len(x)))
    np.add.at(per_frame, cluster, score[:R])
    M = per_frame.T @ per_frame + score[R:n_data].T @ score[R:n_data] + J[n_data:].T @ J[n_data:]
    B_inv = np.linalg.pinv(B)
    return B_inv @ M @ B_inv * (G / max(G - 1, 1))


def mapping_standard_error(calibration: Calibration, result: dict, points: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    """(N,) m: the standard error of where the refined mapping puts the swing-plane points (N, 2) m,
    from the fit's covariance (first order: the mapping's derivative by each free parameter, by
    finite differences of step ``eps``). ``calibration`` is the one :func:`refine_mapping` started from."""
    refined = result["calibration"]
    u = refined.robot_to_pixel(np.asarray(points, float).reshape(-1, 2))
    base = refined.pixel_to_robot(u)
    G = np.zeros((len(u), 2, len(result["free"])))
    for j, i in enumerate(result["free"]):
        if i == DT:
            continue
        theta = result["theta"].copy()
        theta[i] += eps
        G[:, :, j] = (_calibration(calibration, theta).pixel_to_robot(u) - base) / eps
    var = np.einsum("nap,pq,naq->n", G, result["covariance"], G)
    return np.sqrt(np.maximum(var, 0.0))


def board_corner_points(calibration: Calibration, board) -> np.ndarray:
    """(C, 2) m: robot-frame points of the board corners the calibration used (``corner_ids``)
    of the ``cv2.aruco.CharucoBoard`` ``board``, through ``board_to_robot``."""
    ids = np.asarray(calibration.corner_ids, int)
    xy = np.asarray(board.getChessboardCorners(), float)[ids, :2]
    return apply_homography(np.asarray(calibration.board_to_robot, float), xy)
