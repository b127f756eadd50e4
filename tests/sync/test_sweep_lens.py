"""The sweep's verdict on a lens the calibration got wrong: synthetic link rows, no video."""
import dataclasses

import cv2
import numpy as np
import pytest

from stringcast.calibrate import Calibration, refine_mapping
from stringcast.core import SweepSettings, Verdict
from stringcast.sync.sweep import _refined_docs, lens_fit

K = np.array([[1200.0, 0, 639.5], [0, 1200.0, 511.5], [0, 0, 1]])
DIST = np.array([-0.24, 0.08, 0.0, 0.0, 0.0])
CORNERS = np.stack(np.meshgrid(np.linspace(0.75, 1.15, 5), np.linspace(-0.35, -0.2, 3)), -1).reshape(-1, 2)


def _camera() -> Calibration:
    """A 1280 x 1024 camera 2.6 m from the swing plane (robot x, y in m), k1 -0.24."""
    R = cv2.Rodrigues(np.array([np.pi + 0.05, 0.03, 0.0]))[0]
    H = np.linalg.inv(K @ np.column_stack([R[:, 0], R[:, 1], [-0.45, -0.1, 2.6]]))
    return Calibration(H / H[2, 2], (1280, 1024), K, DIST, reprojection_error_px=0.1)


def _calibrated(true: Calibration, dcx_px: float) -> Calibration:
    """What a calibration set dcx_px off in the principal point gives: its homography fitted to the board."""
    Kc = true.K.copy()
    Kc[0, 2] += dcx_px
    probe = Calibration(np.eye(3), true.image_size, Kc, true.dist)
    H = cv2.findHomography(probe.undistort(true.robot_to_pixel(CORNERS)), CORNERS, 0)[0]
    return Calibration(H / H[2, 2], true.image_size, Kc, true.dist, reprojection_error_px=0.1,
                       verdict=Verdict("warn", ("intrinsics: the views cover 58 % of the image",)))


def _rows(true: Calibration, seen_by: Calibration, rng) -> np.ndarray:
    """(K, 7) link rows over the part of the plane the arm sweeps, as seen through ``seen_by``."""
    p = rng.uniform([0.2, -0.6], [0.9, 0.3], (2400, 2))
    ang = rng.uniform(0, np.pi, len(p))
    n = np.c_[np.cos(ang), np.sin(ang)]
    off = np.sum((seen_by.pixel_to_robot(true.robot_to_pixel(p)) - p) * n, 1) + rng.normal(0, 3e-4, len(p))
    return np.c_[np.arange(len(p)) // 60, p, n, off, rng.uniform(-2, 2, len(p))]


def _judged(dcx_px: float, sweep: SweepSettings) -> dict:
    """geometry.json's document for a calibration dcx_px off, from rows of the arm's reach, judged over it and
    beyond it; with ``true_p95_mm``, the refined mapping's p95 error there against the true camera."""
    rng = np.random.default_rng(5)
    true = _camera()
    cal = _calibrated(true, dcx_px)
    rows = _rows(true, cal, rng)
    points = np.r_[rng.uniform([0.2, -0.6], [0.9, 0.3], (600, 2)), rng.uniform([-0.3, 0.3], [0.4, 0.7], (300, 2))]
    fit = refine_mapping(cal, rows, CORNERS, **lens_fit(cal, sweep))
    sync_doc = {"offset_s": 0.1, "verdict": {"status": "ok", "reasons": []}}
    geo, _ = _refined_docs(cal, sync_doc, fit, rows, points, CORNERS, sweep)
    uv = true.robot_to_pixel(points)
    geo["true_p95_mm"] = float(np.percentile(np.linalg.norm(fit["calibration"].pixel_to_robot(uv) - points,
                                                             axis=1), 95) * 1000)
    return geo


def test_a_principal_point_off_is_refitted_and_the_verdict_names_the_lens():
    """The principal point 2 % of the width off: the lens fit moves cx back by about that (the mapping then
    0.09 mm off where the string can be, against the truth). The mapping beyond the arm's reach hangs on
    the lens, so the geometry verdict warns and names it. With the calibration's own principal point right,
    the lens fit agrees with the homography and the verdict is ok."""
    off = _judged(25.6, SweepSettings())
    lens = off["sweep"]["lens"]
    print(lens, off["verdict"])
    assert lens["principal_point_change_px"][0] == pytest.approx(-25.6, abs=5.0)
    assert lens["disagreement_p95_mm"] > SweepSettings().tolerance_mm
    assert off["sweep"]["uncertainty_p95_mm"] >= lens["disagreement_p95_mm"]
    assert off["verdict"]["status"] == "warn" and "lens model" in off["verdict"]["reasons"][-1]
    assert off["K"][0][2] == pytest.approx(639.5, abs=5.0)          # geometry.json carries the refit lens
    assert off["true_p95_mm"] < 0.3                                  # and is right (0.09 mm measured)
    right = _judged(0.0, SweepSettings())
    assert right["sweep"]["lens"]["disagreement_p95_mm"] < 0.5 and right["verdict"]["status"] == "ok"


def test_without_the_lens_fit_the_sweep_cannot_see_the_lens():
    """``sweep.fit_lens: false`` (the homography and the clock only): no lens block, the calibration's K kept,
    and the same principal point 2 % off passes as ok: the blind spot the lens fit closes."""
    geo = _judged(25.6, dataclasses.replace(SweepSettings(), fit_lens=False))
    assert geo["sweep"]["lens"] is None and geo["K"][0][2] == pytest.approx(639.5 + 25.6)
    assert geo["verdict"]["status"] == "ok" and geo["true_p95_mm"] > SweepSettings().tolerance_mm   # 1.55 mm off
