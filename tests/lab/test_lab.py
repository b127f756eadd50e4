"""The virtual lab: physics sanity, camera/renderer consistency, and the data contract.

Small and fast: a 150 mm string of 10 links filmed by a 320 x 240 camera at
200 fps for ~0.3 s (about 50 frames), looking at the grasp and a small ChArUco
board beside it, while the wrist flicks.
"""
import copy
import math
import dataclasses
import json
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from stringcast.core.arm import hand_pose
from stringcast.core import ConfigError, resolve_campaign
from stringcast.core.files import read_parquet, read_video_meta
from stringcast.core.joint_log import read_joint_table
from stringcast_lab import (CameraModel, ChainSim, IdealCanvas, StringPhysics, build_renderer, run_trial,
                            servo_lag, write_calibration_clip)
from stringcast_lab.scene import StringLook

Q0 = np.array([0.2, -0.4, -0.3])


# ---------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def tiny(config):
    """A tiny campaign + config: inline string, a 320 x 240 camera seeing 0.4 x 0.3 m
    around the grasp, and a small ChArUco board beside the hanging string."""
    return _tiny(config)


def _tiny(config, string: dict | None = None):
    cfg = copy.deepcopy(config)
    from stringcast.core import ArmSpec

    arm = ArmSpec.from_config("a", cfg["arms"]["ur5e_planar"])
    g = hand_pose(arm, Q0)[:2] * 1000
    cfg["cameras"]["tiny"] = {"width_px": 320, "height_px": 240, "fps": 200.0, "bit_depth": 8, "mono": True}
    cfg["lab"] = dict(cfg.get("lab", {}), links_per_point=2, settle_s=0.1)
    cfg["lab"]["strings"] = {"default": {"density_g_per_m": 20.0, "diameter_mm": 3.0}}
    cfg["lab"]["camera"] = dict(cfg["lab"].get("camera", {}), focal_px=2000.0, center_mm=[g[0] + 90, g[1] - 110])
    doc = {
        "string": string or {"length_mm": 150.0, "n_points": 5, "weights": [{"at_mm": 150.0, "mass_g": 5.0}],
                             "stiff_sections": []},
        "target": {"x_mm": g[0] + 150, "y_mm": g[1] + 10, "radius_mm": 20.0},
        "allow_reachable": True,
        "setup": {"camera": "tiny", "board": {"squares_x": 5, "squares_y": 4, "square_mm": 40.0,
                                              "marker_mm": 30.0, "dictionary": "DICT_4X4_50"},
                  "board_origin_mm": [g[0] + 60, g[1] - 70], "board_angle_deg": 0.0, "board_flip_y": True},
    }
    return resolve_campaign(doc, cfg, "tiny"), cfg


def _wrist_flick(rate=500.0):
    """Hold Q0 0.1 s, turn the wrist by -0.3 rad in 0.12 s (smooth), hold 0.1 s."""
    T = 0.12
    t = np.arange(0, T, 1 / rate)
    s = 0.5 * (1 - np.cos(np.pi * t / T))
    q = np.repeat(Q0[None], len(t), 0)
    q[:, 2] -= 0.3 * s
    pre, post = np.repeat(Q0[None], 50, 0), np.repeat(q[-1:], 50, 0)
    q_cmd = np.concatenate([pre, q, post])
    return np.arange(len(q_cmd)) / rate, q_cmd, 0.1


@pytest.fixture(scope="module")
def trial(tiny, tmp_path_factory):
    campaign, cfg = tiny
    out = tmp_path_factory.mktemp("trial")
    t_cmd, q_cmd, t0 = _wrist_flick()
    truth = run_trial(t_cmd, q_cmd, campaign, cfg, out, seed=5, motion_start_s=t0)
    return out, truth, t_cmd, q_cmd


def _decode(path: Path) -> list[np.ndarray]:
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, f = cap.read()
        if not ok:
            break
        frames.append(f if f.ndim == 2 else f[..., 0])
    return frames


def _bilinear(img, xy):
    m = cv2.remap(img.astype(np.float32), xy[:, None, 0].astype(np.float32), xy[:, None, 1].astype(np.float32),
                  cv2.INTER_LINEAR)
    return m.ravel()


# ---------------------------------------------------------------------------- physics
def test_string_physics_from_config(config):
    for sid, n_w in (("1", 1), ("4", 2), ("6", 0)):
        camp = resolve_campaign({"string": int(sid), "target": 3}, config)
        phys = StringPhysics.from_campaign(camp, config)
        assert phys.n_links == config["lab"]["links_per_point"] * camp.string.n_points
        assert len(phys.weights) == n_w
        pipe = sum((b - a) * rho for a, b, rho, _ in phys.pipes)
        assert phys.mass == pytest.approx(phys.density * phys.length + 0.01 * n_w + pipe)
    # a pipe makes its span rigid: fewer hinges than a plain string of the same cut
    p4 = StringPhysics.from_campaign(resolve_campaign({"string": 4, "target": 3}, config), config)
    p6 = StringPhysics.from_campaign(resolve_campaign({"string": 6, "target": 3}, config), config)
    assert ChainSim(p6, 5e-5).model.nv < ChainSim(p4, 5e-5).model.nv == p4.n_links + 3
    bad = copy.deepcopy(config)
    bad["lab"]["strings"] = {"default": {"densty_g_per_m": 20.0}}
    with pytest.raises(ConfigError, match="densty"):
        StringPhysics.from_campaign(resolve_campaign({"string": 1, "target": 1}, bad), bad)


def test_chain_hangs_still(campaign, config):
    phys = StringPhysics.from_campaign(campaign, config)
    sim = ChainSim(phys, 5e-5)
    pose = np.array([0.6, 0.1, -0.3])
    assert sim.settle(pose) < 1e-4
    before = sim.sites()
    for _ in range(4000):                                # 0.2 s more, hand held still
        sim.step(pose, np.zeros(3), np.zeros(3))
    after = sim.sites()
    assert np.abs(after - before).max() < 1e-5
    assert after[0] == pytest.approx(pose[:2], abs=1e-5)  # grasp at the hand
    assert after[-1, 1] < pose[1] - 0.9 * phys.length    # hangs nearly straight down
    assert np.argmin(after[:, 1]) == len(after) - 1       # the weighted tip is lowest


def test_the_hanging_chain_does_not_depend_on_the_hands_turn_count(campaign, config):
    """phi_h is the arm's joint sum, unwrapped: the chain hangs alike from phi_h and phi_h + 2 pi, and
    without a loop (each site below the one before, past the first link; at 4.32 rad the start once
    wound the chain by -338 deg and the equilibrium kept it)."""
    phys = StringPhysics.from_campaign(campaign, config)
    shapes = []
    for phi in (-math.pi / 2 - 0.4, 3 * math.pi / 2 - 0.4, 1.2 - math.pi / 2, 1.2 - 5 * math.pi / 2):
        sim = ChainSim(phys, 5e-5)
        sim.equilibrium(np.array([0.6, 0.1, phi]))
        sites = sim.sites()
        assert np.all(np.diff(sites[1:, 1]) < 0)
        shapes.append(sites)
    assert np.abs(shapes[0] - shapes[1]).max() < 1e-6
    assert np.abs(shapes[2] - shapes[3]).max() < 1e-6


def _release_horizontal(phys):
    import mujoco

    sim = ChainSim(phys, 5e-5)
    pose = np.array([0.5, 0.2, 0.0])
    sim.reset_hanging(pose)
    sim.data.qpos[3] = 0.0                                # string straight out along +x
    mujoco.mj_forward(sim.model, sim.data)
    energy, tips, seg = [], [], []
    for i in range(16000):                               # 0.8 s
        sim.step(pose, np.zeros(3), np.zeros(3))
        if i % 200 == 0:
            energy.append(sum(sim.energy()))
            s = sim.sites()
            tips.append(s[-1])
            seg.append(np.linalg.norm(np.diff(s, axis=0), axis=1))
    return np.array(energy), np.array(tips), np.array(seg)


def test_swing_energy_and_length(campaign, config):
    phys = StringPhysics.from_campaign(campaign, config)
    scale = phys.mass * 9.81 * phys.length
    # no damping, no air: energy is conserved (semi-implicit Euler oscillates a little)
    e, tips, seg = _release_horizontal(dataclasses.replace(phys, bending_damping=0.0, grasp_damping=0.0,
                                                           air_density=0.0))
    assert np.ptp(e) < 0.03 * scale
    assert np.ptp(tips[:, 0]) > 0.2 and np.ptp(tips[:, 1]) > 0.2   # the tip swung
    assert seg == pytest.approx(phys.link_length, rel=1e-6)       # inextensible
    # with damping and air drag: energy only ever goes down, and more than without
    e2, _, _ = _release_horizontal(phys)
    assert np.all(np.diff(e2) <= 1e-7)
    assert e2[-1] < e[-1] - 0.02 * scale


def test_air_drag_broadside_and_along(campaign, config):
    import mujoco

    from stringcast_lab.air import cylinder_cd

    phys = dataclasses.replace(StringPhysics.from_campaign(campaign, config), weights=())
    sim = ChainSim(phys, 5e-5)
    sim.reset_hanging(np.zeros(3))
    sim.data.qpos[3] = 0.0                                # straight along x
    v = 4.0
    forces = []
    for axis in (1, 0):                                   # broadside (y), then along the string (x)
        sim.data.qvel[:] = 0.0
        sim.data.qvel[axis] = v
        mujoco.mj_forward(sim.model, sim.data)
        sim.apply_drag()
        forces.append(sim.data.xfrc_applied[:, :3].sum(axis=0))
    re = v * phys.diameter * phys.air_density / phys.air_viscosity
    expect = 0.5 * phys.air_density * cylinder_cd(re) * phys.diameter * phys.length * v * v
    assert -forces[0][1] == pytest.approx(expect, rel=1e-6)
    assert abs(forces[0][0]) < 1e-12
    assert 0 < -forces[1][0] < 0.1 * expect              # skin friction only along the cord


def test_servo_lag_is_critically_damped():
    rate, lag = 500.0, 0.008
    t_cmd = np.arange(0, 0.4, 1 / rate)
    ramp = np.clip(t_cmd - 0.1, 0, None)[:, None] * np.array([[1.0, -2.0]])
    t = np.arange(0, 0.39, 5e-5)
    q, qd, qdd = servo_lag(t_cmd, ramp, lag, t)
    # a ramp is followed with a constant delay of lag_s
    late = t > 0.3
    delay = (np.interp(t[late], t_cmd, ramp[:, 0]) - q[late, 0]) / 1.0
    assert delay == pytest.approx(lag, rel=0.02)
    assert qd[late, 1] == pytest.approx(-2.0, rel=1e-3)
    # a step is approached without overshoot
    step = np.where(t_cmd >= 0.1, 1.0, 0.0)[:, None]
    qs, _, _ = servo_lag(t_cmd, step, lag, t)
    assert qs.max() <= 1.0 + 1e-9 and qs[-1, 0] == pytest.approx(1.0, abs=1e-6)


# ---------------------------------------------------------------------------- camera
def test_render_path_is_opencv_projection(tiny):
    campaign, cfg = tiny
    cam = CameraModel.from_config(campaign.setup.camera, cfg)
    canvas = IdealCanvas.for_camera(cam)
    rng = np.random.default_rng(0)
    # swing-plane points through the canvas homography and the distortion = cv2.projectPoints
    c = np.asarray(cfg["lab"]["camera"]["center_mm"]) / 1000
    world = c + rng.uniform(-0.08, 0.08, (200, 2))
    from stringcast_lab.camera import apply_homography

    via_canvas = canvas.to_image(apply_homography(cam.plane_homography(canvas.K), world))
    assert via_canvas == pytest.approx(cam.project(world), abs=1e-6)
    # the remap tables invert the distortion: map(pixel) -> canvas -> back to the same pixel
    uv = rng.integers(0, [cam.width, cam.height], (300, 2))
    src = np.stack([canvas.map_x[uv[:, 1], uv[:, 0]], canvas.map_y[uv[:, 1], uv[:, 0]]], 1).astype(float)
    assert canvas.to_image(src) == pytest.approx(uv, abs=2e-3)


def test_string_drawn_where_physics_puts_it(tiny):
    """A static string: the dark profile's centroid across it is the projected centreline (< 0.15 px)."""
    campaign, cfg = tiny
    phys = StringPhysics.from_campaign(campaign, cfg)
    r = build_renderer(campaign, cfg, phys)
    g = hand_pose(campaign.arm, Q0)[:2]
    ang = np.radians(-70)                               # straight string, steep, not axis-aligned
    sites = g + np.outer(StringLook.from_physics(phys).arc, [np.cos(ang), np.sin(ang)])
    dn = r.dynamic_dn(sites[None], Q0[None])
    dark = r.bg_dn - dn
    pts = sites[2:-3:2]                                 # clear of the gripper and the clay at the tip
    px = r.cam.project(pts)
    d_img = r.cam.project(pts + 1e-3 * np.array([np.cos(ang), np.sin(ang)])) - px
    n = np.stack([-d_img[:, 1], d_img[:, 0]], 1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    s = np.linspace(-4, 4, 81)
    for p, nn in zip(px, n):
        prof = _bilinear(dark, p + s[:, None] * nn)
        assert prof.max() > 40                          # clearly darker than the background
        assert abs(np.sum(prof * s) / np.sum(prof)) < 0.15


@pytest.mark.parametrize("pipe", [False, True])
def test_string_ends_where_its_ground_truth_ends(config, pipe):
    """The cord's or pipe's end is flat: the contrast along the axis falls to half within 0.5 px
    of the projected tip, 0.8 px/mm here (cv2.polylines' round caps drew d/2 = 1.5 or 4 mm, 1.3 or 3.2 px past it)."""
    string = {"length_mm": 150.0, "n_points": 5, "weights": [],
              "stiff_sections": [{"from_mm": 100.0, "to_mm": 150.0}] if pipe else []}
    campaign, cfg = _tiny(config, string)
    phys = StringPhysics.from_campaign(campaign, cfg)
    r = build_renderer(campaign, cfg, phys)
    g = hand_pose(campaign.arm, Q0)[:2]
    u = np.array([np.cos(np.radians(-70)), np.sin(np.radians(-70))])
    look = StringLook.from_physics(phys)
    assert (len(look.pipes) == 1) == pipe
    sites = g + np.outer(look.arc, u)
    dark = r.bg_dn - r.dynamic_dn(sites[None], Q0[None])
    tip = r.cam.project(sites[-1:])[0]
    step = r.cam.project(sites[-1:] + 1e-3 * u)[0] - tip      # 1 mm along the axis, px
    s = np.linspace(-3, 3, 601)                             # px along the axis, 0 at the tip
    prof = _bilinear(dark, tip + s[:, None] * step / np.linalg.norm(step))
    inside = prof[s < -1.5].max()
    edge = s[np.nonzero(prof >= 0.5 * inside)[0][-1]]
    assert abs(edge) < 0.5, edge


# ---------------------------------------------------------------------------- trial files
def test_trial_files_match_contract(trial, tiny):
    out, truth, t_cmd, q_cmd = trial
    campaign, cfg = tiny
    t, q = read_joint_table(out / "joints.csv")
    df = pd.read_csv(out / "joints.csv")
    assert list(df.columns) == ["t_s", "q1_rad", "q2_rad", "q3_rad", "q1_cmd_rad", "q2_cmd_rad", "q3_cmd_rad"]
    assert t == pytest.approx(t_cmd)
    assert df[["q1_cmd_rad", "q2_cmd_rad", "q3_cmd_rad"]].to_numpy() == pytest.approx(q_cmd)
    noise = q - q_cmd
    assert 0 < np.std(noise[:40]) < 5e-4                # at rest: only the encoder noise
    meta = read_video_meta(out / "video.yaml")
    assert set(meta) == {"file", "fps", "frames", "trigger_time_s", "width_px", "height_px", "bit_depth"}
    assert (meta["fps"], meta["width_px"], meta["height_px"], meta["bit_depth"]) == (200.0, 320, 240, 8)
    frames = _decode(out / "video.mkv")
    assert len(frames) == meta["frames"] == truth["frames"] >= 40
    assert frames[0].shape == (240, 320) and frames[0].dtype == np.uint8
    assert 0.02 <= truth["trigger_time_s"] <= 0.08
    assert abs(meta["trigger_time_s"] - truth["trigger_time_s"]) <= cfg["lab"]["trigger_error_s"] + 1e-9
    last_centre = truth["trigger_time_s"] + (meta["frames"] - 1) / meta["fps"]
    assert last_centre + truth["exposure_s"] / 2 <= t_cmd[-1] + 1e-9
    gt = read_parquet(out / "ground_truth.parquet", ["frame", "t_s", "point", "x_m", "y_m"])
    n = campaign.string.n_points
    assert len(gt) == meta["frames"] * (n + 1)
    assert gt.groupby("frame")["point"].apply(list).map(lambda p: p == list(range(n + 1))).all()
    first = gt[gt.frame == 1].iloc[0]
    assert first.t_s == pytest.approx(truth["trigger_time_s"] + 1 / meta["fps"])
    # point 0 is the grasp: the lagged arm's hand, near the commanded one at rest
    g0 = gt[(gt.frame == 0) & (gt.point == 0)][["x_m", "y_m"]].to_numpy()[0]
    assert g0 == pytest.approx(hand_pose(campaign.arm, Q0)[:2], abs=1e-4)
    on_disk = json.loads((out / "ground_truth.json").read_text())
    for key in ("hit", "closest_approach_mm", "closest_approach_t_s", "camera", "frames", "wall_s",
                "trigger_time_s"):
        assert key in on_disk
    assert isinstance(on_disk["hit"], bool) and on_disk["closest_approach_mm"] > 0
    assert on_disk["hit"] == (on_disk["closest_approach_mm"] <= 20.0 and on_disk["floor_clearance_mm"] >= 0)
    assert not list(out.glob(".*"))                     # no temporary files left


def test_a_trial_not_filmed_keeps_the_cameras_clock_and_truth(trial, tiny, tmp_path):
    """lab.render: false (the loop benchmark's state mode) writes no video, but the same joints,
    video.yaml (without file) and ground truth as the filmed trial of the same seed."""
    out, truth, t_cmd, q_cmd = trial
    campaign, cfg = tiny
    cfg = dict(cfg, lab=dict(cfg["lab"], render=False))
    bare = run_trial(t_cmd, q_cmd, campaign, cfg, tmp_path, seed=5, motion_start_s=0.1)
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith("video.") and p.suffix != ".yaml"]
    assert bare["video"]["rendered"] is False and bare["video"]["file"] is None and bare["video_mb"] == 0
    filmed = read_video_meta(out / "video.yaml")
    meta = read_video_meta(tmp_path / "video.yaml")
    assert "file" not in meta and meta == {k: v for k, v in filmed.items() if k != "file"}
    cols = ["frame", "t_s", "point", "x_m", "y_m"]
    pd.testing.assert_frame_equal(read_parquet(tmp_path / "ground_truth.parquet", cols),
                                  read_parquet(out / "ground_truth.parquet", cols))
    assert (tmp_path / "joints.csv").read_text() == (out / "joints.csv").read_text()
    assert bare["closest_approach_mm"] == truth["closest_approach_mm"]
    with pytest.raises(ConfigError, match="lab.render"):
        run_trial(t_cmd, q_cmd, campaign, dict(cfg, lab=dict(cfg["lab"], render="no")), tmp_path / "x", seed=5,
                  motion_start_s=0.1)


def test_ground_truth_lands_on_dark_string_pixels(trial, tiny):
    out, truth, _, _ = trial
    campaign, cfg = tiny
    r = build_renderer(campaign, cfg)
    K, dist = np.array(truth["camera"]["K"]), np.array(truth["camera"]["dist"])
    rvec, tvec = np.array(truth["camera"]["rvec"]), np.array(truth["camera"]["tvec"])
    gt = pd.read_parquet(out / "ground_truth.parquet")
    frames = _decode(out / "video.mkv")
    moved = []
    darker = []
    for k in range(len(frames)):
        g = gt[(gt.frame == k) & (gt.point >= 1)]
        xyz = np.column_stack([g.x_m, g.y_m, np.zeros(len(g))])
        px = cv2.projectPoints(xyz, rvec, tvec, K, dist)[0].reshape(-1, 2)
        inside = (px[:, 0] > 2) & (px[:, 0] < 317) & (px[:, 1] > 2) & (px[:, 1] < 237)
        if not inside.any():
            continue
        d = _bilinear(r.bg_dn, px[inside]) - _bilinear(frames[k], px[inside])
        darker.extend(d)
        moved.append(px[-1])
    darker = np.array(darker)
    assert len(darker) > 100
    assert np.mean(darker > 25) > 0.9                   # on the string: much darker than the background
    tip = np.array(moved)
    assert np.ptp(tip[:, 0]) > 5                         # and the string moved in the video


def test_board_detected_in_frame(trial, tiny):
    out, truth, _, _ = trial
    campaign, cfg = tiny
    frame = _decode(out / "video.mkv")[0]
    board = campaign.setup.board.make()
    cc, ids, _, _ = cv2.aruco.CharucoDetector(board).detectBoard(frame)
    assert ids is not None and len(ids) >= 8             # of 12 inner corners
    # the detected corners are where the camera truth puts the board's corners
    obj = board.getChessboardCorners()[ids.ravel()][:, :2]
    world = obj @ campaign.setup.board_to_robot[:2, :2].T + campaign.setup.board_to_robot[:2, 2]
    cam = build_renderer(campaign, cfg).cam
    err = np.linalg.norm(cam.project(world) - cc.reshape(-1, 2), axis=1)
    assert np.median(err) < 0.2 and err.max() < 0.5


def test_calibration_clip_matches_camera_truth(tiny, tmp_path):
    campaign, cfg = tiny
    out = write_calibration_clip(campaign, cfg, tmp_path / "calib", seed=3, n_frames=3)
    files = sorted(out.glob("board_*.png"))
    assert [f.name for f in files] == ["board_00.png", "board_01.png", "board_02.png"]
    truth = json.loads((out / "ground_truth.json").read_text())
    K, dist = np.array(truth["camera"]["K"]), np.array(truth["camera"]["dist"])
    board = campaign.setup.board.make()
    det = cv2.aruco.CharucoDetector(board)
    for f, view in zip(files, truth["views"]):
        img = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
        assert img.shape == (240, 320) and img.dtype == np.uint8
        cc, ids, _, _ = det.detectBoard(img)
        assert ids is not None and len(ids) >= 8
        obj = board.getChessboardCorners()[ids.ravel()]
        px = cv2.projectPoints(obj, np.array(view["rvec"]), np.array(view["tvec"]), K, dist)[0].reshape(-1, 2)
        assert np.median(np.linalg.norm(px - cc.reshape(-1, 2), axis=1)) < 0.25


def test_lab_shares_no_code_with_the_model():
    import ast

    import stringcast_lab as lab

    banned = {"model", "model_kernels", "model_reference", "estimation", "tracking", "calibration", "sync"}
    for f in Path(lab.__file__).parent.rglob("*.py"):           # the rod package (lab/rod/) too
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ImportFrom):
                mods = [node.module or ""] + [f"{node.module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                mods = [a.name for a in node.names]
            else:
                continue
            for mod in mods:
                parts = set(mod.replace("stringcast.", "").split("."))
                assert not (parts & banned), f"{f.name} imports {mod}"


def test_pipeline_never_reads_the_lab_truth():
    """No pipeline module, workflow rule or report names the lab's truth files: only the lab (which
    writes them) and its campaign driver (the experimenter's stand-in) do. (That the pipeline never
    imports the lab: tests/test_imports.py.)"""
    import stringcast
    import stringcast_lab

    pkg = Path(stringcast.__file__).parent
    root = pkg.parents[1]
    sources = sorted(pkg.rglob("*.py")) + sorted((root / "workflow").rglob("*.smk")) + [root / "Snakefile"]
    assert len(sources) > 60
    assert [f.name for f in sources if "ground_truth" in f.read_text()] == []
    lab = Path(stringcast_lab.__file__).parent
    assert {"campaign.py", "trial.py"} <= {f.name for f in lab.rglob("*.py") if "ground_truth" in f.read_text()}


# ---------------------------------------------------------------------------- harder footage
def test_apply_preset(config):
    from stringcast_lab import PRESETS, apply_preset

    before = copy.deepcopy(config)
    cfg = apply_preset(config, "dim+fast")
    assert config == before                                # a copy: the input is untouched
    assert cfg["lab"]["camera"]["light_level"] == PRESETS["fast"]["camera"]["light_level"]  # later one wins
    assert cfg["lab"]["camera"]["noise_sigma"] == PRESETS["dim"]["camera"]["noise_sigma"]
    assert all(c["fps"] == 2000.0 for c in cfg["cameras"].values())
    own = copy.deepcopy(config)
    own["lab"]["presets"] = {"dim": {"camera": {"light_level": 0.5}}, "hot": {"cameras": {"fps": 1000.0}}}
    assert apply_preset(own, "dim")["lab"]["camera"]["light_level"] == 0.5
    assert apply_preset(own, "hot")["cameras"]["highspeed_1024"]["fps"] == 1000.0
    with pytest.raises(ConfigError, match="unknown.*known"):
        apply_preset(config, "foggy")
    own["lab"]["presets"]["bad"] = {"camera": {"lite_level": 0.5}}
    with pytest.raises(ConfigError, match="lite_level"):
        apply_preset(own, "bad")


def test_oblique_camera_pose(tiny):
    """tilt_deg (pitch, yaw) turns the optical axis off the plane's normal, roll_deg turns the
    image about it; the axis still meets the plane at center_mm; too much tilt is refused."""
    campaign, cfg = tiny
    obl = copy.deepcopy(cfg)
    obl["lab"]["camera"].update(tilt_deg=[15.0, -30.0], roll_deg=4.0)
    cam = CameraModel.from_config(campaign.setup.camera, obl)
    axis = cam.R.T @ np.array([0, 0, 1.0])
    assert np.degrees(np.arccos(-axis[2])) == pytest.approx(np.degrees(np.arccos(np.cos(np.radians(15))
                                                                                    * np.cos(np.radians(30)))))
    hit = cam.center + axis * (-cam.center[2] / axis[2])
    assert hit[:2] == pytest.approx(np.asarray(obl["lab"]["camera"]["center_mm"]) / 1000, abs=1e-9)
    # the plane's x axis is no longer the image's: the roll and the yaw show
    d = cam.project(np.array([hit[:2] + [0.05, 0], hit[:2]]))
    assert abs(np.degrees(np.arctan2(*(d[0] - d[1])[::-1]))) > 2.0
    r = build_renderer(campaign, obl)                      # the scene renders through the oblique view
    assert r.bg_dn.shape == (240, 320) and np.ptp(r.bg_dn) > 100
    obl["lab"]["camera"]["tilt_deg"] = [88.0, 0.0]       # the image top sees past the horizon
    with pytest.raises(ConfigError, match="horizon"):
        CameraModel.from_config(campaign.setup.camera, obl)
