"""Calibration: intrinsics on real data, plane homography on synthetic renders, files."""
from pathlib import Path

import cv2
import numpy as np
import pytest

from stringcast.calibrate.calibration import (Calibration, calibrate_intrinsics, detect_charuco, detect_plane_board,
                                             plane_homography, run_calibration)
from stringcast.calibrate.charuco import select_views
from stringcast.core.files import DataError, read_json
from stringcast.video.container import open_video

from conftest import SHARED_REAL

PHOTOS = SHARED_REAL / "charuco_photos"
CLIP = SHARED_REAL / "charuco_clip"


def _needs(path: Path):
    if not path.exists():
        pytest.skip(f"real data absent: {path} (set STRINGCAST_REAL_DATA or put it at ../shared/real beside the repo)")


def _rel(a, b):
    return abs(a - b) / abs(b)


def test_intrinsics_real_photos():
    _needs(PHOTOS)
    board = cv2.aruco.CharucoBoard((5, 7), 0.04, 0.02, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_6X6_250))
    frames = [cv2.imread(str(PHOTOS / f"img_0{i}.jpg"), cv2.IMREAD_GRAYSCALE) for i in range(4)]
    intr = calibrate_intrinsics(frames, board, str(PHOTOS))
    ref = dict(fx=452.5, fy=456.8, cx=317.7, cy=277.8)  # tutorial_camera_charuco.yml
    K = intr.K
    for got, want in [(K[0, 0], ref["fx"]), (K[1, 1], ref["fy"]), (K[0, 2], ref["cx"]), (K[1, 2], ref["cy"])]:
        assert _rel(got, want) < 0.03, (got, want)
    assert intr.n_views == 4 and intr.rms_px < 0.25  # reference 0.182 px
    occluded = cv2.imread(str(PHOTOS / "chocclusion_original.jpg"), cv2.IMREAD_GRAYSCALE)
    assert len(detect_charuco(occluded, board)[1]) >= 10


def test_intrinsics_real_clip_inverted_board():
    _needs(CLIP)
    board = cv2.aruco.CharucoBoard((4, 5), 0.054, 0.054 * 0.75, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    video = open_video(CLIP / "cam_0.mp4")
    intr = calibrate_intrinsics((f for _, f in video), board, str(video.path))  # polarity found automatically
    ref = dict(fx=894.5, fy=896.9, cx=624.0, cy=361.3)  # reference_cam_0.toml
    K = intr.K
    for got, want in [(K[0, 0], ref["fx"]), (K[1, 1], ref["fy"]), (K[0, 2], ref["cx"]), (K[1, 2], ref["cy"])]:
        assert _rel(got, want) < 0.03, (got, want)
    assert intr.rms_px < 0.25 and intr.n_views >= 30  # reference 0.19 px
    assert intr.dist[0] < -0.25  # strong barrel distortion (reference k1 = -0.338)


def test_view_selection_for_pose_diversity_on_real_clip():
    """Ten views chosen for pose diversity calibrate the real lens; the first ten (one pose) cannot."""
    _needs(CLIP)
    board = cv2.aruco.CharucoBoard((4, 5), 0.054, 0.054 * 0.75, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    frames = [f for _, f in open_video(CLIP / "cam_0.mp4")]
    diverse = calibrate_intrinsics(frames, board, "clip", max_views=10)
    first = calibrate_intrinsics(frames[:10], board, "clip", max_views=10)
    assert diverse.views_found >= 40 and diverse.n_views <= 10
    assert _rel(diverse.K[0, 0], 894.5) < 0.03 and _rel(diverse.K[1, 1], 896.9) < 0.03  # reference_cam_0.toml
    assert _rel(first.K[0, 0], 894.5) > 0.2  # consecutive frames: nearly one pose, fx badly determined


def test_select_views_spreads_over_pose_space():
    rng = np.random.default_rng(3)
    cluster = rng.normal(0, 0.01, (50, 5))               # 50 near-identical views
    distinct = np.eye(5)                                 # 5 clearly different poses
    desc = np.vstack([cluster, distinct, np.full((1, 5), np.nan)])
    corners = np.r_[np.full(50, 20), np.full(5, 10), 30]
    pick = select_views(desc, corners, 6)
    assert len(pick) == 6 and set(range(50, 55)) <= set(pick.tolist())   # every distinct pose kept
    assert 55 not in pick                                # the NaN descriptor never
    assert np.array_equal(select_views(desc, corners, 100), np.arange(55))


# ---------------------------------------------------------------- synthetic board renders

SIZE = (480, 400)
K_TRUE = np.array([[420.0, 0, 243.0], [0, 421.0, 197.0], [0, 0, 1]])
DIST_TRUE = np.array([-0.12, 0.05, 0.0008, -0.0005, 0.0])


def _board():
    return cv2.aruco.CharucoBoard((9, 6), 0.060, 0.045, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_100))


def _render_plane(board, H_board_to_px, K=None, dist=None, size=SIZE, px_per_m=800.0):
    """Render the board lying in a plane seen through H (board m -> undistorted px), then distort."""
    bw, bh = board.getChessboardSize()
    sq = board.getSquareLength()
    art = board.generateImage((round(bw * sq * px_per_m), round(bh * sq * px_per_m)), marginSize=0)
    u, v = np.meshgrid(np.arange(size[0], dtype=float), np.arange(size[1], dtype=float))
    uv = np.column_stack([u.ravel(), v.ravel()])
    if K is not None:
        uv = cv2.undistortPoints(uv.reshape(-1, 1, 2), K, dist, P=K).reshape(-1, 2)
    bxy = cv2.perspectiveTransform(uv.reshape(-1, 1, 2), np.linalg.inv(H_board_to_px)).reshape(-1, 2)
    mx = (bxy[:, 0] * px_per_m - 0.5).reshape(size[1], size[0]).astype(np.float32)
    my = (bxy[:, 1] * px_per_m - 0.5).reshape(size[1], size[0]).astype(np.float32)
    img = cv2.remap(art, mx, my, cv2.INTER_LINEAR, borderValue=200)
    return img


def _h_board_to_px():
    # board (0.54 x 0.36 m) seen slightly in perspective in the middle of the image
    src = np.array([[0, 0], [0.54, 0], [0.54, 0.36], [0, 0.36]])
    dst = np.array([[70, 80], [410, 95], [400, 320], [60, 300]], float)
    return cv2.getPerspectiveTransform(src.astype(np.float32), dst.astype(np.float32)).astype(float)


def _pose_h(rvec, tvec):
    """Board m -> undistorted px homography K_TRUE [r1 r2 t] of a real board pose (what a camera with
    K_TRUE can see; the arbitrary map of :func:`_h_board_to_px` is not one)."""
    R = cv2.Rodrigues(np.asarray(rvec, float))[0]
    H = K_TRUE @ np.c_[R[:, :2], np.asarray(tvec, float)]
    return H / H[2, 2]


B2R = np.array([[1.0, 0, 0.78], [0, -1.0, -0.34], [0, 0, 1]])  # board flipped, origin at (0.78, -0.34) m


@pytest.mark.parametrize("with_intrinsics", [False, True])
def test_plane_homography_maps_board_to_robot(with_intrinsics):
    board = _board()
    # the board in the middle of the image, seen slightly in perspective
    Hb = _pose_h([0.05, -0.07, 0.03], [-0.275, -0.185, 0.667]) if with_intrinsics else _h_board_to_px()
    K, dist = (K_TRUE, DIST_TRUE) if with_intrinsics else (None, None)
    img = _render_plane(board, Hb, K, dist)
    from stringcast.calibrate.calibration import Intrinsics
    intr = Intrinsics(K_TRUE, DIST_TRUE, 0.1, 10, SIZE) if with_intrinsics else None
    cal = plane_homography(img, board, B2R, intr, "synthetic")
    assert cal.n_corners >= 30
    assert cal.reprojection_error_px < 0.3
    # points of the plane (inside the board) -> pixels by the true model -> back to robot
    rng = np.random.default_rng(1)
    bxy = rng.uniform([0.02, 0.02], [0.52, 0.34], (50, 2))
    und = cv2.perspectiveTransform(bxy.reshape(-1, 1, 2), Hb).reshape(-1, 2)
    uv = Calibration(np.eye(3), SIZE, K, dist).distort(und)
    robot_true = cv2.perspectiveTransform(bxy.reshape(-1, 1, 2), B2R).reshape(-1, 2)
    err = np.linalg.norm(cal.pixel_to_robot(uv) - robot_true, axis=1)
    scale = float(np.median(cal.m_per_px(uv)))
    assert 1.2e-3 < scale < 1.8e-3  # 0.54 m over ~345 px
    assert np.max(err) < 0.25 * scale  # a quarter of a pixel anywhere on the board
    # round trip robot -> pixel -> robot
    assert np.max(np.abs(cal.robot_to_pixel(robot_true) - uv)) < 0.25
    assert np.allclose(cal.pixel_to_robot(cal.robot_to_pixel(robot_true)), robot_true, atol=1e-9)


def test_plane_homography_from_the_board_pose_holds_far_from_the_board():
    """With intrinsics the homography is the board's pose (K [r1 r2 t]): a board in one corner of
    the image still maps the far side of the swing plane within a pixel, where a free
    8-DOF homography of the same noisy corners extrapolates its perspective terms (Calibration
    module doc). The render is a real pose of K_TRUE, the frame carries sensor noise."""
    from stringcast.calibrate.calibration import Intrinsics

    board = _board()
    Hb = _pose_h([0.06, -0.09, 0.02], [-0.55, -0.41, 1.05])   # board origin near the top-left corner
    img = _render_plane(board, Hb, K_TRUE, DIST_TRUE, px_per_m=1600.0).astype(float)
    img = np.clip(img + np.random.default_rng(4).normal(0, 6.0, img.shape), 0, 255).astype(np.uint8)
    cal = plane_homography(img, board, B2R, Intrinsics(K_TRUE, DIST_TRUE, 0.1, 10, SIZE), "synthetic")
    corners = cv2.perspectiveTransform(np.array([[[0, 0]], [[0.54, 0.36]]], float), Hb).reshape(-1, 2)
    assert corners[1, 0] < 0.6 * SIZE[0] and corners[1, 1] < 0.7 * SIZE[1]   # the board covers one corner
    # the whole image: pixel -> plane by the true pose, then back through the calibration
    u, v = np.meshgrid(np.linspace(10, SIZE[0] - 10, 12), np.linspace(10, SIZE[1] - 10, 10))
    uv = np.c_[u.ravel(), v.ravel()]
    und = Calibration(np.eye(3), SIZE, K_TRUE, DIST_TRUE).undistort(uv)
    plane = cv2.perspectiveTransform(und.reshape(-1, 1, 2), np.linalg.inv(Hb)).reshape(-1, 2)
    truth = cv2.perspectiveTransform(plane.reshape(-1, 1, 2), B2R).reshape(-1, 2)
    scale = float(np.median(cal.m_per_px(uv)))
    err_pose = np.linalg.norm(cal.pixel_to_robot(uv) - truth, axis=1) / scale
    # the free 8-DOF fit of the same detected corners, for comparison
    found, ids = detect_charuco(img, board)
    bxy = np.asarray(board.getChessboardCorners(), float)[ids, :2]
    H_free = cv2.findHomography(bxy, cal.undistort(found), 0)[0]
    free = cv2.perspectiveTransform(cv2.perspectiveTransform(und.reshape(-1, 1, 2), np.linalg.inv(H_free)), B2R)
    err_free = np.linalg.norm(free.reshape(-1, 2) - truth, axis=1) / scale
    assert np.max(err_pose) < 1.0 and np.mean(err_pose) < 0.3, err_pose    # measured 0.68 / 0.20 px
    assert np.max(err_pose) < 0.7 * np.max(err_free), (np.max(err_pose), np.max(err_free))  # free: 1.33 px


def test_distortion_round_trip_is_exact():
    cal = Calibration(np.eye(3), SIZE, K_TRUE, DIST_TRUE)
    uv = np.random.default_rng(0).uniform([0, 0], SIZE, (200, 2))
    assert np.max(np.abs(cal.distort(cal.undistort(uv)) - uv)) < 1e-6


def test_distort_matches_opencv_projectpoints():
    cal = Calibration(np.eye(3), SIZE, K_TRUE, DIST_TRUE)
    uv = np.random.default_rng(1).uniform([-50, -50], np.add(SIZE, 50), (500, 2))
    rays = np.column_stack([(uv - K_TRUE[:2, 2]) / np.diag(K_TRUE)[:2], np.ones(len(uv))])
    ref, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), K_TRUE, DIST_TRUE)
    assert np.max(np.abs(cal.distort(uv) - ref.reshape(-1, 2))) < 1e-6


def test_far_board_found_in_enlarged_image():
    """A board 170 px wide (markers of ~2.5 px per bit, blurred, noisy) is not decoded at scale 1;
    the plane board's 2x search finds it, its corners mapped back to within 0.5 px."""
    board = cv2.aruco.CharucoBoard((9, 6), 0.06, 0.045, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_100))
    s = 170 / 900
    small = cv2.resize(board.generateImage((900, 600), marginSize=0), None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
    img = np.full((400, 500), 110, np.float32)
    img[100:100 + small.shape[0], 150:150 + small.shape[1]] = 40 + 0.6 * small
    img = cv2.GaussianBlur(img, (0, 0), 0.9)
    img = np.clip(img + np.random.default_rng(0).normal(0, 1.2, img.shape), 0, 255).astype(np.uint8)
    assert len(detect_charuco(img, board)[1]) < 8
    corners, ids = detect_plane_board(img, board)
    assert len(ids) >= 8
    true = (np.asarray(board.getChessboardCorners())[ids, :2] / 0.06 * 100 + 0.5) * s - 0.5 + [150, 100]
    assert np.max(np.abs(corners - true)) < 0.5


def test_no_board_raises_naming_source():
    img = np.full((200, 300), 128, np.uint8)
    cv2.circle(img, (150, 100), 40, 30, -1)
    with pytest.raises(DataError, match="frame_x.*no ChArUco board"):
        plane_homography(img, _board(), B2R, None, "frame_x")


def test_calibrate_intrinsics_too_few_views():
    with pytest.raises(DataError, match="calib_here.*0 views"):
        calibrate_intrinsics([np.zeros((50, 60), np.uint8)] * 3, _board(), "calib_here")


def test_calibration_json_round_trip(tmp_path):
    cal = Calibration(np.array([[1e-3, 0, 0.2], [0, -1e-3, 0.5], [1e-6, 0, 1]]), (640, 480), K_TRUE, DIST_TRUE,
                      0.12, 40, B2R, 0.2, 12, ("a warning",), (1, 2, 3))
    cal.to_json(tmp_path / "c.json")
    back = Calibration.from_json(tmp_path / "c.json")
    assert np.allclose(back.H_pixel_to_robot, cal.H_pixel_to_robot) and np.allclose(back.K, cal.K)
    assert back.warnings == ("a warning",) and back.corner_ids == (1, 2, 3) and back.image_size == (640, 480)
    (tmp_path / "bad.json").write_text('{"K": null}')
    with pytest.raises(DataError, match="bad.json"):
        Calibration.from_json(tmp_path / "bad.json")


def test_run_calibration_on_trial_folder(tmp_path, campaign, settings):
    board = campaign.setup.board.make()
    Hb = _pose_h([0.05, -0.07, 0.03], [-0.275, -0.185, 0.667])
    img = _render_plane(board, Hb, K_TRUE, DIST_TRUE)
    trial = tmp_path / "trial_1"
    trial.mkdir()
    rng = np.random.default_rng(0)
    vw = cv2.VideoWriter(str(trial / "video.mkv"), cv2.VideoWriter_fourcc(*"FFV1"), 500.0, SIZE, isColor=False)
    for _ in range(5):
        vw.write(np.clip(img + rng.normal(0, 2, img.shape), 0, 255).astype(np.uint8))
    vw.release()
    calib = tmp_path / "calib"
    calib.mkdir()
    for k, (a, b) in enumerate([(-0.35, 0.1), (0.3, -0.2), (0.1, 0.4), (-0.2, -0.35), (0.4, 0.3), (0.0, 0.0)]):
        R, _ = cv2.Rodrigues(np.array([a, b, 0.05 * k]))
        t = np.array([-0.27 + 0.03 * k, -0.18, 0.75 + 0.05 * k])
        Hk = K_TRUE @ np.column_stack([R[:, 0], R[:, 1], t])
        cv2.imwrite(str(calib / f"board_{k:02d}.png"), _render_plane(board, Hk / Hk[2, 2], K_TRUE, DIST_TRUE))
    st = {"board_check": settings.board_check}
    cal = run_calibration(trial, calib, campaign, tmp_path / "out" / "calibration.json", **st)
    doc = read_json(tmp_path / "out" / "calibration.json")
    assert doc["n_corners"] == cal.n_corners >= 30 and doc["K"] is not None
    assert abs(cal.K[0, 0] - K_TRUE[0, 0]) / K_TRUE[0, 0] < 0.02
    assert cal.reprojection_error_px < 0.5
    assert np.allclose(doc["board_to_robot"], campaign.setup.board_to_robot)
    # board origin corner (board (0.06, 0.06) m) lands where the config says
    b = np.array([[0.06, 0.06]])
    px = cv2.perspectiveTransform(b.reshape(-1, 1, 2), Hb).reshape(-1, 2)
    px = Calibration(np.eye(3), SIZE, K_TRUE, DIST_TRUE).distort(px)
    want = cv2.perspectiveTransform(b.reshape(-1, 1, 2), campaign.setup.board_to_robot).reshape(-1, 2)
    assert np.linalg.norm(cal.pixel_to_robot(px) - want) < 1e-3
    # reproducible: the same files give the same bytes (OpenCV's threads once made the 9th digit vary)
    threads = cv2.getNumThreads()
    for i in range(3):
        run_calibration(trial, calib, campaign, tmp_path / "out" / f"again_{i}.json", **st)
        assert (tmp_path / "out" / f"again_{i}.json").read_bytes() == (tmp_path / "out" / "calibration.json").read_bytes()
    assert cv2.getNumThreads() == threads   # restored after the stage
    # six views of the image's middle half: judged weak (coverage), the trial's board one more view
    assert doc["verdict"]["status"] in ("warn", "fail") and doc["intrinsics"]["n_views"] == 7
    assert any("cover" in r and "upper and lower thirds" in r for r in doc["verdict"]["reasons"])
    # homography only (no calib/) still works but warns
    cal2 = run_calibration(trial, None, campaign, tmp_path / "out2.json", **st)
    assert cal2.K is None and any("homography only" in w for w in cal2.warnings)
    assert cal2.verdict.status == "warn" and read_json(tmp_path / "out2.json")["verdict"]["status"] == "warn"


def test_run_calibration_without_board(tmp_path, campaign, settings):
    trial = tmp_path / "trial_1"
    trial.mkdir()
    vw = cv2.VideoWriter(str(trial / "video.mkv"), cv2.VideoWriter_fourcc(*"FFV1"), 500.0, (64, 64), isColor=False)
    for _ in range(3):
        vw.write(np.full((64, 64), 90, np.uint8))
    vw.release()
    with pytest.raises(DataError, match="video.mkv.*no ChArUco board"):
        run_calibration(trial, None, campaign, tmp_path / "c.json", board_check=settings.board_check)
    assert not (tmp_path / "c.json").exists()


def test_fix_k3_holds_k3_at_zero_on_the_real_clip():
    """cv2.CALIB_FIX_K3 (config: cameras.<name>.fix_k3): k3 stays 0 and the real clip still calibrates."""
    _needs(CLIP)
    board = cv2.aruco.CharucoBoard((4, 5), 0.054, 0.054 * 0.75, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    frames = [f for _, f in open_video(CLIP / "cam_0.mp4")]
    fixed = calibrate_intrinsics(frames, board, "clip", flags=cv2.CALIB_FIX_K3)
    assert fixed.dist[4] == 0.0
    assert _rel(fixed.K[0, 0], 894.5) < 0.03 and fixed.rms_px < 0.25   # reference_cam_0.toml (k1, k2 only)
