"""The lab as a family of set-ups (issue 25): draws, the config they make, and what the lab films
with them (colour, MJPEG, H.264, the trigger and joint-log options, the calibration set).

The filmed tests use one draw scaled to a quarter of its size (256 px wide) at 500 fps for
0.3 s, so each trial takes a few seconds.
"""
import copy
import dataclasses
import json

import cv2
import numpy as np
import pytest

from stringcast.core import ConfigError, resolve_campaign
from stringcast.core.config import validate
from stringcast.core.files import read_video_meta
from stringcast.core.joint_log import read_joint_table
from stringcast_lab import (CameraModel, apply_setup, build_renderer, draw_setup, h264_backend, run_trial,
                            write_calibration_clip)
from stringcast_lab.look import LUMA_BGR, ArmLook, scene_look
from stringcast_lab.scene import arm_shapes
from stringcast_lab.view import ARM_REST_ZONES_M, SWING_REGION_M, board_corners, region_outline
from stringcast.video import open_video

N_SEEDS = 200
MOTION_START = 0.1


@pytest.fixture(scope="module")
def draws():
    return [draw_setup(s) for s in range(N_SEEDS)]


# ---------------------------------------------------------------------------- the draw
def test_draw_is_reproducible_and_frozen():
    a, b = draw_setup(7), draw_setup(7)
    assert a == b and a.as_dict() == b.as_dict()
    assert draw_setup(8) != a
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.fps = 1.0
    json.dumps(a.as_dict())                                  # plain values, for a benchmark's records


def test_draws_cover_the_family(draws):
    seen = {k: {getattr(s, k) for s in draws} for k in
            ("colour", "codec", "background", "trigger", "joint_log", "calib_board", "joint_discs", "flicker_hz")}
    assert seen["colour"] == {True, False}
    assert seen["codec"] == {"ffv1", "mjpeg", "h264"}
    assert seen["background"] == {"plain", "blotchy", "clutter"}
    assert seen["trigger"] == {"exact", "jitter", "wrong", "absent"}
    assert seen["joint_log"] == {"before_motion", "at_motion_start"}
    assert seen["calib_board"] == {"large", "small"} and seen["joint_discs"] == {True, False}
    assert seen["flicker_hz"] == {100.0, 120.0}
    assert {(s.width_px, s.height_px) for s in draws} == {(1024, 768), (1024, 1024), (1280, 1024)}
    assert any(s.flicker == 0 for s in draws) and any(s.flicker > 0 for s in draws)
    assert any(s.calib_region == (0.0, 0.0, 1.0, 1.0) for s in draws)
    assert any(s.calib_region != (0.0, 0.0, 1.0, 1.0) for s in draws)


def test_draws_stay_within_their_ranges(draws):
    for s in draws:
        assert 500 <= s.fps <= 2000 and 0 < s.exposure_s < 1 / s.fps
        assert (s.mjpeg_quality is not None) == (s.codec == "mjpeg")
        assert (s.h264_crf is not None) == (s.codec == "h264")
        assert s.mjpeg_quality is None or 75 <= s.mjpeg_quality <= 95
        assert s.h264_crf is None or 18 <= s.h264_crf <= 28
        assert np.hypot(*s.tilt_deg) <= 10 + 1e-6
        assert abs(s.principal_offset_px[0]) <= 0.05 * s.width_px and abs(s.principal_offset_px[1]) <= 0.05 * s.height_px
        k1, k2, _, _, k3 = s.dist_coeffs
        assert -0.25 <= k1 <= 0.1 and abs(k2) <= 0.5 * abs(k1) + 1e-5 and k3 == 0
        assert 6 <= s.calib_shots <= 30 and s.calib_tilt_deg[0] == 10 and 20 <= s.calib_tilt_deg[1] <= 45
        assert 0.3 <= s.calib_board_span[0] <= s.calib_board_span[1] <= 0.85
        assert (s.calib_board == "small") == (s.calib_board_span[1] <= 0.45)
        err = {"exact": lambda e: e == 0, "jitter": lambda e: abs(e) <= 0.002,
               "wrong": lambda e: abs(abs(e) - 0.03) < 1e-12, "absent": lambda e: e is None}[s.trigger]
        assert err(s.trigger_error_s)
        for tint in (s.wall_tint, s.string_tint):
            assert float(LUMA_BGR @ np.asarray(tint)) == pytest.approx(1.0, abs=1e-3)


def test_each_view_sees_the_swing_region_and_the_board(draws, config):
    """Through the lab's own camera (from apply_setup's config): the swing region and the whole
    board inside the image, the board above the table and clear of the arm's rest zone."""
    for s in draws[:60]:
        cfg = apply_setup(config, s)
        cam = CameraModel.from_config(cfg["cameras"]["lab_drawn"], cfg)
        for pts in (region_outline(), board_corners(np.asarray(s.board_origin_mm) / 1000, s.board_angle_deg,
                                                    (0.54, 0.36), 0.03)):
            px = cam.project(pts)
            assert np.all(px >= 0) and np.all(px <= [s.width_px - 1, s.height_px - 1]), s.seed
        poly = board_corners(np.asarray(s.board_origin_mm) / 1000, s.board_angle_deg, (0.54, 0.36), 0.03)
        assert poly[:, 1].min() > -0.75
        for (x0, x1), (y0, y1) in ARM_REST_ZONES_M:
            inside = (poly[:, 0] > x0) & (poly[:, 0] < x1) & (poly[:, 1] > y0) & (poly[:, 1] < y1)
            assert not inside.any(), s.seed
    (x0, x1), (y0, y1) = SWING_REGION_M
    assert x1 - x0 >= 1.2 and y1 - y0 >= 1.0


def test_apply_setup_splits_the_users_view_from_the_truth(config):
    s = draw_setup(4)
    cfg = apply_setup(config, s)
    validate({k: v for k, v in cfg.items() if k != "_path"}, "config.schema.json", "apply_setup")
    assert config["setups"]["default"]["camera"] == "highspeed_1024"          # the input is left alone
    cam = cfg["cameras"]["lab_drawn"]
    assert (cam["width_px"], cam["height_px"], cam["fps"], cam["mono"]) == (s.width_px, s.height_px, s.fps, not s.colour)
    camp = resolve_campaign({"string": 1, "target": 1}, cfg, "t")
    assert camp.setup.camera["name"] == "lab_drawn"
    origin = camp.setup.board_to_robot @ np.array([0.0, 0.0, 1.0])
    assert origin[:2] * 1000 == pytest.approx(s.board_origin_mm)
    arm = cfg["arms"]["ur5e_planar"]                                           # as a user measures it
    assert arm["link_widths_mm"] == pytest.approx(np.asarray(s.link_widths_mm) + 10)
    assert arm["joint_radii_mm"] == pytest.approx(np.asarray(s.joint_radii_mm) + 5)
    truth = cfg["lab"]
    assert truth["camera"]["focal_px"] == s.focal_px and truth["camera"]["dist_coeffs"] == list(s.dist_coeffs)
    assert truth["video"]["codec"] == s.codec and truth["look"]["arm"]["joint_discs"] == s.joint_discs
    assert truth["trigger_written"] == (s.trigger != "absent")
    assert "focal_px" not in str(cfg["cameras"]) + str(cfg["setups"])     # the pipeline's part holds no truth


def test_arm_without_discs_has_round_caps_in_the_links_shade(config):
    arm = resolve_campaign({"string": 1, "target": 1}, config, "t").arm
    q = np.array([0.9, 1.2, 1.1])
    with_discs = [n for _, n in arm_shapes(arm, q)]
    assert with_discs.count("joint") == arm.n_joints + 1
    caps = arm_shapes(arm, q, ArmLook(link_widths=(0.12, 0.1, 0.08), joint_discs=False))
    assert [n for _, n in caps].count("joint") == 0
    radius = np.linalg.norm(caps[-3][0] - caps[-3][0].mean(axis=0), axis=1)   # the elbow's cap
    assert radius == pytest.approx(0.06, rel=1e-6)


def test_bad_lab_look_and_video_are_refused(config):
    from stringcast_lab.encode import video_settings

    for lab, match in (({"look": {"backgrund": "plain"}}, "backgrund"), ({"look": {"background": "brick"}}, "brick"),
                       ({"look": {"tint": {"sky": [1, 1, 1]}}}, "sky"), ({"video": {"codec": "vp9"}}, "vp9")):
        cfg = copy.deepcopy(config)
        cfg["lab"] = {**cfg["lab"], **lab}
        with pytest.raises(ConfigError, match=match):
            scene_look(cfg), video_settings(cfg)


def test_colour_scene_has_the_mono_scenes_grey_levels(config):
    """Tints have luma 1: the noise-free colour frame, converted to grey (BT.601), is the mono frame."""
    s = dataclasses.replace(draw_setup(4).scaled(0.25), background="clutter")
    frames = {}
    for colour in (False, True):
        cfg = apply_setup(config, dataclasses.replace(s, colour=colour))
        camp = resolve_campaign({"string": 1, "target": 1}, cfg, "t")
        r = build_renderer(camp, cfg)
        frames[colour] = r.bg_dn
    assert frames[True].shape == frames[False].shape + (3,)
    grey = cv2.cvtColor(frames[True], cv2.COLOR_BGR2GRAY)
    assert np.abs(grey - frames[False]).max() < 0.05                          # DN
    assert np.abs(frames[True][..., 0] - frames[True][..., 2]).mean() > 1.0   # and it is coloured


# ---------------------------------------------------------------------------- filmed
def _small(config, **change) -> tuple:
    """A quarter-size draw (seed 4) at 500 fps with ``change``, and its config (a faster lab)."""
    s = dataclasses.replace(draw_setup(4).scaled(0.25), fps=500.0, exposure_s=0.0008, **change)
    cfg = apply_setup(config, s)
    cfg["lab"].update(links_per_point=2, settle_s=0.1)
    return s, cfg


def _film(config, out, **change):
    s, cfg = _small(config, **change)
    camp = resolve_campaign({"string": 1, "target": 1}, cfg, "t")
    rate, q0 = 500.0, np.array([0.9, 1.2, 1.1])
    w = 0.5 * (1 - np.cos(np.pi * np.arange(0, 0.15, 1 / rate) / 0.15))
    q = np.repeat(q0[None], len(w), 0)
    q[:, 2] -= 0.8 * w
    q_cmd = np.concatenate([np.repeat(q0[None], int(MOTION_START * rate), 0), q, np.repeat(q[-1:], 25, 0)])
    truth = run_trial(np.arange(len(q_cmd)) / rate, q_cmd, camp, cfg, out, seed=9, motion_start_s=MOTION_START)
    return s, truth


@pytest.fixture(scope="module")
def filmed(config, tmp_path_factory):
    """The same colour scene written lossless (FFV1), as MJPEG (at_motion_start log, no trigger) and
    as H.264 (or the fallback; trigger 30 ms late)."""
    root = tmp_path_factory.mktemp("family")
    out = {}
    for name, change in (("ffv1", {"codec": "ffv1"}),
                         ("mjpeg", {"codec": "mjpeg", "mjpeg_quality": 80, "joint_log": "at_motion_start",
                                    "trigger": "absent", "trigger_error_s": None}),
                         ("h264", {"codec": "h264", "h264_crf": 28, "trigger": "wrong", "trigger_error_s": 0.03})):
        out[name] = (root / name, *_film(config, root / name, colour=True, **change))
    return out


def _grey_frames(path):
    with open_video(path) as v:
        return v, np.stack([f for _, f in v]).astype(np.float32)


@pytest.mark.parametrize("codec", ["mjpeg", "h264"])
def test_lossy_colour_video_reads_back_close_to_the_lossless_one(filmed, codec):
    d, s, truth = filmed[codec]
    ref_dir, _, ref_truth = filmed["ffv1"]
    meta = read_video_meta(d / "video.yaml")
    v, grey = _grey_frames(d / meta["file"])
    _, ref = _grey_frames(ref_dir / "video.mkv")
    assert meta["file"] == {"mjpeg": "video.avi", "h264": "video.mp4"}[codec]
    assert h264_backend() == "pyav"                      # av is a dependency: real H.264 at the drawn CRF
    assert truth["video"]["codec_written"] == codec
    assert (v.n_frames, v.width, v.height) == (meta["frames"], s.width_px, s.height_px) == \
        (ref_truth["frames"], s.width_px, s.height_px)
    # the same frames before encoding (same seed): the difference is the codec's loss, small
    # against the scene's dynamic range (1st to 99th percentile of the lossless frames)
    span = np.percentile(ref, 99) - np.percentile(ref, 1)
    assert span > 60
    assert np.abs(grey - ref).mean() < 0.04 * span
    assert np.abs(grey.mean(axis=(1, 2)) - ref.mean(axis=(1, 2))).max() < 0.02 * span   # no level shift
    # frame k is frame k: where the arm moves most, the lossy frame matches its own lossless frame
    # far better than the one 10 frames (20 ms) earlier
    moved = np.abs(ref[10:] - ref[:-10])
    k = int(np.argmax((moved > 0.2 * span).sum(axis=(1, 2))))
    mask = moved[k] > 0.2 * span
    assert mask.sum() > 20
    assert np.abs(grey[k + 10] - ref[k + 10])[mask].mean() < 0.3 * np.abs(grey[k + 10] - ref[k])[mask].mean()


def test_joint_log_at_motion_start_and_absent_trigger(filmed):
    d, s, truth = filmed["mjpeg"]
    t, _ = read_joint_table(d / "joints.csv", "joints.csv", n_joints=3)
    assert t[0] == pytest.approx(MOTION_START, abs=1e-9) and truth["joint_log_start_s"] == t[0]
    assert truth["trigger_time_s"] < MOTION_START - 0.015           # the camera rolls before the log starts
    assert "trigger_time_s" not in read_video_meta(d / "video.yaml")
    assert truth["trigger_time_written_s"] is None
    t_full, _ = read_joint_table(filmed["ffv1"][0] / "joints.csv", "joints.csv", n_joints=3)
    assert t_full[0] == 0.0 and t_full[-1] == t[-1]


def test_wrong_trigger_is_written_30_ms_off(filmed):
    d, _, truth = filmed["h264"]
    assert read_video_meta(d / "video.yaml")["trigger_time_s"] == pytest.approx(truth["trigger_time_s"] + 0.03, abs=1e-8)


@pytest.mark.parametrize("region", [(0.0, 0.0, 1.0, 1.0), (0.0, 0.55, 1.0, 1.0)])
def test_calibration_set_follows_the_draw(config, tmp_path, region):
    s, cfg = _small(config, calib_shots=7, calib_region=region, calib_tilt_deg=(10.0, 25.0), colour=True)
    camp = resolve_campaign({"string": 1, "target": 1}, cfg, "t")
    out = write_calibration_clip(camp, cfg, tmp_path / "calib", seed=3)
    pngs = sorted(out.glob("board_*.png"))
    assert len(pngs) == 7
    assert cv2.imread(str(pngs[0]), cv2.IMREAD_UNCHANGED).shape == (s.height_px, s.width_px, 3)
    gt = json.loads((out / "ground_truth.json").read_text())
    K, dist = np.asarray(gt["camera"]["K"]), np.asarray(gt["camera"]["dist"])
    board = camp.setup.board
    w, h = board.squares_x * board.square, board.squares_y * board.square
    corners = np.array([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0]], float)
    lo = np.array(region[:2]) * [s.width_px, s.height_px]
    hi = np.array(region[2:]) * [s.width_px, s.height_px]
    tilts = []
    for view in gt["views"]:
        px, _ = cv2.projectPoints(corners, np.asarray(view["rvec"]), np.asarray(view["tvec"]), K, dist)
        assert np.all(px.reshape(-1, 2) >= lo - 1e-6) and np.all(px.reshape(-1, 2) <= hi)
        normal = cv2.Rodrigues(np.asarray(view["rvec"]))[0][:, 2]
        tilts.append(np.degrees(np.arccos(abs(normal[2]))))
    assert 9 < min(tilts) and max(tilts) < 26      # 10-25 deg about an in-plane axis (the roll keeps it)
