"""Tracking on harder lab footage, one short clip per difficulty, against the lab's ground truth.

Each clip: a 320 x 240 lab camera at 250 fps around the grasp, a short string, a wrist
motion of ~0.15 s; the whole chain (calibration from the trial's first frames, the exact
trigger time as sync, tracking) as in tests/test_tracking.py. Each test prints its numbers and checks
(a) the valid points' median / 95th-percentile error, (b) the valid share, and (c) that
ground-truth points the camera cannot see (behind the arm, outside the image) are never
marked valid. The presets of :func:`stringcast_lab.apply_preset` are checked to change
the footage (so they cannot be silently ignored).
"""
import copy
import math

import cv2
import numpy as np
import pandas as pd
import pytest

from stringcast.core.arm import hand_pose
from stringcast.core import settings_from_config
from stringcast.core import resolve_campaign
from stringcast.core.files import read_video_meta, write_json
from stringcast.core.joint_log import read_joint_table
from stringcast_lab import apply_preset, build_renderer, run_trial
from stringcast_lab.scene import arm_shapes

RATE = 500.0
Q0 = np.array([0.2, -0.4, -0.3])


def _setup(config, q0=Q0, preset=None, focal=1900.0, centre=(60.0, -90.0), board=(60.0, -80.0),
           string=(150.0, 5), lab_string=None, fps=250.0, camera=None, target=(150.0, 10.0)):
    """A tiny campaign + config around the grasp at q0; offsets in mm from the grasp."""
    cfg = copy.deepcopy(config)
    arm0 = resolve_campaign({"string": 1, "target": 1}, cfg, "t").arm
    g = hand_pose(arm0, q0)[:2] * 1000
    cfg["cameras"]["tiny"] = {"width_px": 320, "height_px": 240, "fps": fps, "bit_depth": 8, "mono": True}
    cfg["lab"] = dict(cfg.get("lab", {}), links_per_point=2, settle_s=0.1, trigger_error_s=0.0)
    cfg["lab"]["camera"] = dict(cfg["lab"].get("camera", {}), focal_px=focal,
                                center_mm=[g[0] + centre[0], g[1] + centre[1]], **(camera or {}))
    if lab_string:
        cfg["lab"]["strings"] = {"default": dict(cfg["lab"]["strings"]["default"], **lab_string)}
    if preset:
        cfg = apply_preset(cfg, preset)
    doc = {"string": {"length_mm": string[0], "n_points": string[1], "weights": [], "stiff_sections": []},
           "target": {"x_mm": g[0] + target[0], "y_mm": g[1] + target[1], "radius_mm": 20.0}, "allow_reachable": True,
           "setup": {"camera": "tiny", "board": {"squares_x": 5, "squares_y": 4, "square_mm": 40.0,
                                                 "marker_mm": 30.0, "dictionary": "DICT_4X4_50"},
                     "board_origin_mm": [g[0] + board[0], g[1] + board[1]], "board_angle_deg": 0.0,
                     "board_flip_y": True}}
    return resolve_campaign(doc, cfg, "tiny"), cfg


def _flick(q0=Q0, dq=(0.0, 0.0, -0.35), T=0.16, back=False, pre=60, post=60):
    """Hold q0, move by dq with a smooth cosine ramp in T s (and back again if ``back``), hold."""
    s = 0.5 * (1 - np.cos(np.pi * np.arange(0, T, 1 / RATE) / T))
    if back:
        s = np.concatenate([s, s[::-1]])
    q = q0 + np.outer(s, dq)
    q_cmd = np.concatenate([np.repeat(q0[None], pre, 0), q, np.repeat(q[-1:], post, 0)])
    return np.arange(len(q_cmd)) / RATE, q_cmd, pre / RATE


def _clip(tmp_path, campaign, cfg, motion, seed=3):
    """Render, calibrate, sync (the exact trigger time) and track; return (truth merged with tracks, ground_truth.json, trial dir)."""
    from stringcast.calibrate.calibration import run_calibration
    from stringcast.track.tracking import run_tracking

    t_cmd, q_cmd, t0 = motion
    trial, res = tmp_path / "trial", tmp_path / "res"
    truth = run_trial(t_cmd, q_cmd, campaign, cfg, trial, seed=seed, motion_start_s=t0)
    st = settings_from_config(cfg)  # the config's settings
    run_calibration(trial, None, campaign, res / "calibration.json", board_check=st.board_check)
    meta = read_video_meta(trial / "video.yaml")  # exact trigger (trigger_error_s = 0): tracking alone is tested
    write_json(res / "sync.json", {"offset_s": meta["trigger_time_s"], "fps": meta["fps"], "frames": meta["frames"],
                                   "method": "test: exact trigger", "residual_mm": None})
    df = run_tracking(trial, res / "calibration.json", res / "sync.json", campaign, res / "tracks.parquet",
                      tracking=st.tracking)
    gt = pd.read_parquet(trial / "ground_truth.parquet")
    m = gt.merge(df, on=["frame", "point"], suffixes=("_true", ""))
    m["err_mm"] = np.hypot(m["x_m"] - m["x_m_true"], m["y_m"] - m["y_m_true"]) * 1000
    return m.sort_values(["frame", "point"]).reset_index(drop=True), truth, trial


def _pixels(m, truth):
    """Ground-truth points projected with the lab's camera truth: (N, 2) px."""
    c = truth["camera"]
    xyz = np.column_stack([m["x_m_true"], m["y_m_true"], np.zeros(len(m))])
    return cv2.projectPoints(xyz, np.array(c["rvec"]), np.array(c["tvec"]), np.array(c["K"]),
                             np.array(c["dist"]))[0].reshape(-1, 2)


def _outside(m, truth, beyond_px=2.0):
    """Truth points more than ``beyond_px`` outside the image (a 3 mm cord is ~2 px wide here:
    nearer the edge part of it is still seen)."""
    px = _pixels(m, truth)
    w, h = truth["camera"]["width_px"], truth["camera"]["height_px"]
    return ((px[:, 0] < -0.5 - beyond_px) | (px[:, 1] < -0.5 - beyond_px) | (px[:, 0] > w - 0.5 + beyond_px)
            | (px[:, 1] > h - 0.5 + beyond_px))


def _behind_arm(m, trial, arm, depth_mm=3.0):
    """Truth points at least ``depth_mm`` inside the arm's drawn outline (the arm is in front)."""
    t_j, q_j = read_joint_table(trial / "joints.csv")
    hidden = np.zeros(len(m), bool)
    for idx in m.groupby("frame").indices.values():
        t = float(m["t_s_true"].iloc[idx[0]])
        q = np.array([np.interp(t, t_j, q_j[:, j]) for j in range(q_j.shape[1])])
        p = m[["x_m_true", "y_m_true"]].to_numpy()[idx] * 1000
        for poly, _ in arm_shapes(arm, q):
            c = (poly * 1000).astype(np.float32).reshape(-1, 1, 2)
            d = np.array([cv2.pointPolygonTest(c, (float(x), float(y)), True) for x, y in p])
            hidden[idx] |= d >= depth_mm
    return hidden


def _report(name, m, unseen=None):
    """Print and return (median, p95, valid share) over points 1..n; valid share over seen points."""
    pts = m["point"].to_numpy() > 0
    valid = m["valid"].to_numpy()
    e = m["err_mm"].to_numpy()[pts & valid]
    seen = pts if unseen is None else pts & ~unseen
    share = float(valid[seen].mean())
    med, p95 = (float(np.median(e)), float(np.percentile(e, 95))) if len(e) else (math.nan, math.nan)
    extra = "" if unseen is None else f", unseen {int((pts & unseen).sum())} pts, valid among unseen " \
                                      f"{int((pts & unseen & valid).sum())}"
    print(f"\n{name}: {m.frame.nunique()} frames, median {med:.2f} mm, p95 {p95:.2f} mm, "
          f"valid {float(valid[pts].mean()):.3f} (of seen {share:.3f}){extra}")
    return med, p95, share


def _crossing_frames(m):
    """Frames whose ground-truth polyline (points 0..n) crosses itself (proper segment intersection)."""
    def ccw(a, b, c):
        return (c[..., 1] - a[..., 1]) * (b[..., 0] - a[..., 0]) - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])

    out = []
    for k, g in m.groupby("frame"):
        p = g.sort_values("point")[["x_m_true", "y_m_true"]].to_numpy()
        i, j = np.triu_indices(len(p) - 1, 2)
        a, b, c, d = p[i], p[i + 1], p[j], p[j + 1]
        if np.any((np.sign(ccw(a, b, c)) * np.sign(ccw(a, b, d)) < 0) & (np.sign(ccw(c, d, a)) * np.sign(ccw(c, d, b)) < 0)):
            out.append(int(k))
    return np.array(out, int)


def _check(m, unseen, name, median_mm, p95_mm, share_min):
    med, p95, share = _report(name, m, unseen)
    pts = m["point"].to_numpy() > 0
    assert not m["valid"].to_numpy()[pts & unseen].any(), "a point the camera cannot see is marked valid"
    assert np.isnan(m.loc[~m["valid"], ["x_m", "y_m"]].to_numpy()).all()  # never an invented position
    assert share >= share_min, (name, share)
    assert med <= median_mm and p95 <= p95_mm, (name, med, p95)
    return med, p95, share


# ---------------------------------------------------------------------------- one clip per difficulty
def test_motion_blur(tmp_path, config):
    """Shutter open 95 % of the frame, optics blur 1 px, a fast flick (tip ~4 m/s: ~6 px of blur)."""
    campaign, cfg = _setup(config, preset="blur")
    m, truth, _ = _clip(tmp_path, campaign, cfg, _flick(dq=(0.0, 0.0, -0.45), T=0.12))
    assert truth["exposure_s"] == pytest.approx(0.0019)
    _check(m, _outside(m, truth), "blur", 1.5, 4.0, 0.85)


def test_dim_light(tmp_path, config):
    """A quarter of the light at slightly higher read noise: contrast-to-noise ~4x lower."""
    campaign, cfg = _setup(config, preset="dim")
    m, truth, _ = _clip(tmp_path, campaign, cfg, _flick())
    _check(m, _outside(m, truth), "dim", 1.5, 4.0, 0.7)


def test_arm_occludes_the_string(tmp_path, config):
    """The gripper points up; the string curls over it; the flick sweeps the gripper across the string.
    (phi_h = 1.5 rad: the string turns over the arm's side. At 1.6 rad it turns over the other, away
    from the arm; the labs kept it on the arm's side only while their start state was looped.)"""
    q0 = np.array([0.2, -0.4, 1.7])
    campaign, cfg = _setup(config, q0=q0, centre=(50.0, -80.0), board=(45.0, -65.0))
    m, truth, trial = _clip(tmp_path, campaign, cfg, _flick(q0, dq=(0.0, 0.0, -0.5)))
    behind = _behind_arm(m, trial, campaign.arm)
    assert behind[m["point"].to_numpy() > 0].sum() >= 8  # the clip really hides part of the string
    _check(m, behind | _outside(m, truth), "occlusion", 1.5, 4.0, 0.75)


def test_string_leaves_the_frame(tmp_path, config):
    """The image's bottom edge cuts the hanging string; the flick swings the tip in and out."""
    campaign, cfg = _setup(config, centre=(60.0, 50.0), board=(60.0, 190.0))
    m, truth, _ = _clip(tmp_path, campaign, cfg, _flick())
    out = _outside(m, truth)
    pts = m["point"].to_numpy() > 0
    assert out[pts].mean() > 0.3  # much of the string is out of the picture
    _check(m, out, "leaving the frame", 1.5, 4.0, 0.7)
    # beyond the first point out of the picture (along the string), nothing is valid either
    valid = m["valid"].to_numpy().reshape(-1, campaign.string.n_points + 1)[:, 1:]
    gone = np.maximum.accumulate(out.reshape(valid.shape[0], -1)[:, 1:], axis=1)
    assert not valid[gone].any()


def test_string_crossing_itself(tmp_path, config):
    """A fast downward wrist flick makes a 150 mm string of 10 points whip into a loop."""
    campaign, cfg = _setup(config, focal=1500.0, centre=(-40.0, -80.0), board=(10.0, 110.0), target=(-200.0, 60.0),
                           string=(150.0, 10))
    m, truth, trial = _clip(tmp_path, campaign, cfg, _flick(dq=(0.0, 0.0, -0.8), T=0.1))
    cross = _crossing_frames(m)
    assert len(cross) >= 8, cross  # the loop is really there, in the picture
    unseen = _outside(m, truth) | _behind_arm(m, trial, campaign.arm)
    mc = m[m["frame"].isin(cross)]
    _check(mc, unseen[m["frame"].isin(cross).to_numpy()], "crossing frames", 1.5, 4.0, 0.5)
    _check(m, unseen, "crossing clip", 1.5, 4.0, 0.79)   # 0.803 before ends within w + 4 px of the arm were cut (3 points)


# ---------------------------------------------------------------------------- the presets change the footage
def _frames(path):
    cap = cv2.VideoCapture(str(path))
    out = []
    while True:
        ok, f = cap.read()
        if not ok:
            return out
        out.append((f if f.ndim == 2 else f[..., 0]).astype(np.float32))


def test_presets_change_the_footage(tmp_path, config):
    """dim lowers the mean level by its light_level; blur widens the moving string and arm;
    fast films at 2000 fps; flicker makes frame brightness vary at 100 Hz."""
    motion = _flick(dq=(0.0, 0.0, -0.8), T=0.1, pre=25, post=5)
    runs = {}
    for name in ("default", "dim", "blur", "fast", "flicker"):
        campaign, cfg = _setup(config, preset=None if name == "default" else name)
        out = tmp_path / name
        truth = run_trial(*motion[:2], campaign, cfg, out, seed=4, motion_start_s=motion[2])
        r = build_renderer(campaign, cfg)
        runs[name] = (_frames(out / "video.mkv"), truth, read_video_meta(out / "video.yaml"), r.bg_dn, r.sensor)
    base, dim = runs["default"][0], runs["dim"][0]
    ratio = np.mean(dim[0]) / np.mean(base[0])
    assert ratio == pytest.approx(0.25, abs=0.02), ratio

    def contrast(name):  # darkening at the string's true points 2..n per frame, DN (mean over points)
        frames, truth, _, bg, _ = runs[name]
        gt = pd.read_parquet(tmp_path / name / "ground_truth.parquet")
        gt = gt[gt["point"] >= 2].rename(columns={"x_m": "x_m_true", "y_m": "y_m_true"})
        px = _pixels(gt, truth).astype(np.float32)
        d = [cv2.remap(bg - f, px[i, None, 0], px[i, None, 1], cv2.INTER_LINEAR).ravel()
             for f, i in zip(frames, gt.groupby("frame").indices.values())]
        return np.array([np.mean(x) for x in d])

    c0, cb = contrast("default"), contrast("blur")
    gt = pd.read_parquet(tmp_path / "default" / "ground_truth.parquet")
    xy = gt[["x_m", "y_m"]].to_numpy().reshape(len(c0), -1, 2)
    speed = np.r_[0, np.linalg.norm(np.diff(xy, axis=0), axis=2).mean(axis=1)]  # m per frame
    fastest = np.argsort(speed)[-8:]
    rest, moving = cb[:5].mean() / c0[:5].mean(), cb[fastest].mean() / c0[fastest].mean()
    print(f"\npresets: dim mean ratio {ratio:.3f}; string contrast blur / default: at rest {rest:.2f}, "
          f"8 fastest frames {moving:.2f} ({speed[fastest].mean() * 250:.1f} m/s)")
    assert rest > 0.7                 # at rest only the optics blur differs
    assert moving < 0.9 * rest        # moving: the string is smeared along its path (measured 0.80)
    fast = runs["fast"][2]
    assert fast["fps"] == 2000.0 and fast["frames"] >= 7 * runs["default"][2]["frames"]
    frames, truth, meta, _, sensor = runs["flicker"]
    rel = np.array([f.mean() for f in frames]) / np.array([f.mean() for f in base])
    t = truth["trigger_time_s"] + np.arange(len(frames)) / meta["fps"]
    expected = np.array([sensor.light(tk, truth["exposure_s"]) for tk in t])
    print(f"flicker: frame brightness / default {rel.min():.3f}..{rel.max():.3f}, "
          f"|error| vs drift x flicker <= {np.abs(rel - expected).max():.4f}")
    assert np.ptp(expected) > 0.1 and np.abs(rel - expected).max() < 0.01
