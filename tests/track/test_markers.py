"""Marker mode: bands at the mass points found along the centreline (synthetic images and a lab render)."""
import dataclasses
import math

import cv2
import numpy as np
import pandas as pd
import pytest

from scipy.spatial import cKDTree

from stringcast.track.markers import assign_bands, centreline_profile, find_band_runs, find_bands
from stringcast.core import TrackingSettings, settings_from_config

from conftest import tiny_lab_trial

N, SPACING, BAND = 5, 40.0, 8.0        # points, their spacing and the bands' length, px
ST = TrackingSettings()  # the band settings (band_*) at their defaults


def _curve(n_fine=4000):
    """A bending curve (x, y) px, N * SPACING px long, from (30, 40): (n_fine, 2) and its arc (n_fine,)."""
    s = np.linspace(0, N * SPACING, n_fine)
    theta = 0.35 + 0.9 * np.sin(s / 70.0)
    d = np.column_stack([np.cos(theta), np.sin(theta)])
    xy = np.array([30.0, 40.0]) + np.concatenate([[[0, 0]], np.cumsum((d[1:] + d[:-1]) / 2 * np.diff(s)[:, None],
                                                                        axis=0)])
    return xy, s


def _render(string_grey, band_grey, bands, width=3.0, noise=1.5, seed=0, ss=4):
    """A (220, 170) uint8 image: background ~200 with a gradient and a darker patch, the string
    ``width`` px wide, bands of ``band_grey`` over arc ranges ``bands`` ((from, to) px) with flat
    ends; drawn at ``ss`` x, area-averaged, Gaussian blur 0.5 px, noise."""
    xy, s = _curve()
    H, W = 220, 170
    yy, xx = np.mgrid[0:H * ss, 0:W * ss]
    q = np.column_stack([(xx.ravel() + 0.5) / ss - 0.5, (yy.ravel() + 0.5) / ss - 0.5])
    dist, j = cKDTree(xy).query(q, distance_upper_bound=width)
    on = (dist <= width / 2) & (j > 0) & (j < len(s) - 1)  # flat ends: nothing past the curve's ends
    img = 200.0 - 0.1 * q[:, 0]
    img[(q[:, 0] > 85) & (q[:, 0] < 100)] -= 60.0        # a darker clutter patch behind part of the string
    img[on] = string_grey
    arc = s[np.minimum(j, len(s) - 1)]
    for a, b in bands:
        img[on & (arc >= a) & (arc <= b)] = band_grey
    img = cv2.resize(img.reshape(H * ss, W * ss).astype(np.float32), (W, H), interpolation=cv2.INTER_AREA)
    img = cv2.GaussianBlur(img, (0, 0), 0.5)
    img += np.random.default_rng(seed).normal(0, noise, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8), xy, s


def _bands(skip=(), extra=()):
    L = N * SPACING
    out = [(max(0, c - BAND / 2), min(L, c + BAND / 2)) for i, c in enumerate(np.arange(1, N + 1) * SPACING, 1)
           if i not in skip]
    return out + [(c - BAND / 2, c + BAND / 2) for c in extra]


def _path(xy, s, step=1.0, lateral=0.3):
    """A tracked centreline: vertices every ``step`` px of arc, ``lateral`` px off the true curve."""
    k = np.searchsorted(s, np.arange(0, s[-1] + 1e-9, step)).clip(0, len(s) - 1)
    k[-1] = len(s) - 1
    p = xy[k]
    t = np.gradient(p, axis=0)
    t /= np.hypot(*t.T)[:, None]
    return p + lateral * np.column_stack([-t[:, 1], t[:, 0]]), s[k]


@pytest.mark.parametrize("string_grey, band_grey", [(60.0, 140.0), (130.0, 40.0)], ids=["brighter", "darker"])
def test_band_centres_are_found_to_a_fraction_of_a_pixel(string_grey, band_grey):
    img, xy, s = _render(string_grey, band_grey, _bands())
    path, s_path = _path(xy, s)
    expected = np.arange(1, N + 1) * SPACING
    pos, valid = find_bands(img, path, np.ones(len(path) - 1, bool), s_path, expected, BAND,
                            abs(200 - string_grey), ST, free_end=True)
    assert valid.all(), valid
    arc = s[cKDTree(xy).query(pos[:-1])[1]]  # where on the string each band centre lies (0.05 px steps)
    err = np.abs(arc - expected[:-1])
    tip = float(np.hypot(*(pos[-1] - xy[-1])))
    print("band centre errors along the string, px:", np.round(err, 3), "tip", round(tip, 3))
    # the path lies 0.3 px beside the string; the error that matters is along it. Measured: 0.02-0.09 px
    # (both polarities); the tip (half a band past its band's near edge) 0.30 px darker, 0.39 px brighter
    # (0.3 px of it the path's lateral offset; a brighter tip band merges with the brighter background)
    assert np.all(err < 0.2) and tip < 0.6, (err, tip)
    assert np.all(np.diff(arc) > 0)  # in order from the grasp

def test_a_hidden_band_a_cut_band_and_two_candidates_make_exactly_those_points_invalid():
    """Band 2 not there, band 3 under an occluder, a second band 11 px past point 4: 1 and 5 stay valid."""
    img, xy, s = _render(60.0, 140.0, _bands(skip=(2,), extra=(4 * SPACING + 11,)))
    path, s_path = _path(xy, s)
    seen = np.ones(len(path) - 1, bool)
    seen[(s_path[:-1] > 3 * SPACING - 2) & (s_path[:-1] < 3 * SPACING + 10)] = False  # cuts band 3's far half
    expected = np.arange(1, N + 1) * SPACING
    pos, valid = find_bands(img, path, seen, s_path, expected, BAND, 140.0, ST, free_end=True)
    assert valid.tolist() == [True, False, False, False, True], valid
    assert np.all(np.isnan(pos[~valid])) and not np.any(np.isnan(pos[valid]))
    # without a free end the tip's band (cut by the path's end) is not trusted either
    _, valid = find_bands(img, path, seen, s_path, expected, BAND, 140.0, ST, free_end=False)
    assert valid.tolist() == [True, False, False, False, False], valid


def test_the_pieces_on_plain_arrays():
    v = np.full(200, 50.0)
    v[40:60] = 90.0                    # a brighter run of 20 samples (5 px at 0.25 px)
    v[120:130] = 10.0                  # a darker one
    runs = find_band_runs(v, np.ones(200, bool), 0.25, 81, 20.0)
    assert runs[1].shape == (1, 5) and runs[-1].shape == (1, 5)
    left, right = runs[1][0, :2]
    assert abs(0.5 * (left + right) - 0.25 * 49.5) < 0.2 and abs(right - left - 5.0) < 0.3
    assert find_band_runs(v, np.ones(200, bool), 0.25, 81, 20.0, "darker").keys() == {-1}
    seen = np.ones(200, bool)
    seen[55:] = False                  # an occluder from sample 55: the run is cut at its right
    assert find_band_runs(v, seen, 0.25, 81, 20.0, "brighter")[1][0, 4] == 1
    assert assign_bands([10, 21, 30, 52], [True] * 4, [10, 20, 30, 40, 50], 3).tolist() == [0, 1, 2, -1, 3]
    assert assign_bands([10, 12], [True, True], [10, 20], 3).tolist() == [-1, -1]      # two candidates
    assert assign_bands([10, 20], [False, True], [10, 20], 3).tolist() == [-1, 1]     # a malformed run
    t, val, seg = centreline_profile(np.tile(np.arange(20.0), (10, 1)), np.array([[2.0, 5.0], [12.0, 5.0]]), 0.5)
    assert len(t) == 21 and np.allclose(val, 2 + t) and seg.max() == 0
    with pytest.raises(ValueError, match="band_polarity"):
        find_band_runs(v, np.ones(200, bool), 0.25, 81, 20.0, "pale")
    with pytest.raises(ValueError, match="at most half"):
        find_bands(v[None].repeat(5, 0), np.array([[0.0, 0], [9, 0]]), [True], np.array([0.0, 9]), [4.0, 8.0],
                   3.0, 10.0, ST)


def test_mode_and_bands_are_checked(config):
    import copy

    from stringcast.core import ConfigError, validate

    cfg = copy.deepcopy(config)
    assert settings_from_config(cfg).tracking.mode == "markerless"
    cfg["tracking"] = dict(cfg.get("tracking", {}), mode="bands")
    with pytest.raises(ConfigError, match="mode"):
        settings_from_config(cfg)
    with pytest.raises(ConfigError, match="tracking"):
        validate(cfg, "config.schema.json", "cfg")
    cfg["tracking"] = {"mode": "markers", "band_widht_mm": 8.0}
    with pytest.raises(ConfigError, match="band_widht_mm"):
        validate(cfg, "config.schema.json", "cfg")
    cfg["tracking"] = {"mode": "markers", "band_width_mm": 8.0}
    cfg["lab"] = dict(cfg["lab"], string_bands={"width_mm": 8.0, "reflectance": 0.45})
    validate(cfg, "config.schema.json", "cfg")
    cfg["lab"]["string_bands"] = {"width_mm": 8.0, "shade": 0.45}
    with pytest.raises(ConfigError, match="shade"):
        validate(cfg, "config.schema.json", "cfg")


# ---------------------------------------------------------------------------- virtual lab
def test_the_lab_draws_bands_at_the_models_points(config):
    """lab.string_bands: a band of the set shade centred at each i L / n (the tip's ending at the tip),
    seen in a noise-free frame along the true projection of a still string."""
    import copy

    pytest.importorskip("stringcast_lab")
    from stringcast.core.arm import forward_kinematics
    from stringcast.core import ConfigError, resolve_campaign
    from stringcast_lab import build_renderer

    cfg = copy.deepcopy(config)
    cfg["cameras"]["tiny"] = {"width_px": 320, "height_px": 240, "fps": 250.0, "bit_depth": 8, "mono": True}
    q0 = np.array([0.2, -0.4, -0.3])
    campaign = resolve_campaign({"string": 1, "target": 1}, cfg, "t")
    grasp = forward_kinematics(campaign.arm, q0[None])[0, -1]
    cfg["lab"] = dict(cfg["lab"], links_per_point=2, string_bands={"width_mm": 8.0, "reflectance": 0.45},
                      camera=dict(cfg["lab"]["camera"], focal_px=1900.0, center_mm=list(grasp * 1000 + [0, -80])))
    doc = {"string": {"length_mm": 150.0, "n_points": 5, "weights": [], "stiff_sections": []},
           "target": {"x_mm": 1200.0, "y_mm": 300.0, "radius_mm": 20.0},
           "setup": {"camera": "tiny", "board": {"squares_x": 5, "squares_y": 4, "square_mm": 40.0,
                                                 "marker_mm": 30.0, "dictionary": "DICT_4X4_50"},
                     "board_origin_mm": [780.0, -340.0], "board_flip_y": True}}
    campaign = resolve_campaign(doc, cfg, "tiny")
    r = build_renderer(campaign, cfg)
    look = r.look
    assert np.allclose([0.5 * (a + b) for a, b in look.bands[:-1]], [0.03, 0.06, 0.09, 0.12])
    assert np.allclose(look.bands[-1], [0.146, 0.15]) and look.band_reflectance == 0.45
    down = np.array([math.cos(math.radians(-70)), math.sin(math.radians(-70))])  # hanging straight, still
    sites = grasp + np.outer(look.arc, down)
    path = r.cam.project(sites)
    img = r.dynamic_dn(sites[None], q0[None])
    seen = look.arc[1:] > 0.02                      # the gripper covers the first few mm
    pos, valid = find_bands(img, path, seen, look.arc, np.arange(1, 6) * 0.03, 0.008, 100.0, ST, free_end=True)
    assert valid.all(), valid
    err = np.hypot(*(pos - r.cam.project(grasp + np.outer(np.arange(1, 6) * 0.03, down))).T)
    print("lab bands against the true projection, px:", np.round(err, 3))
    # measured 0.01-0.05 px at 1.3 mm per px, the tip 0.08 px
    assert np.all(err < 0.15), err
    cfg["lab"]["string_bands"] = {"width_mm": 8.0, "shade": 0.45}
    with pytest.raises(ConfigError, match="string_bands"):
        build_renderer(campaign, cfg)


def _track(trial, res, campaign, tracking, mode):
    """Track in ``mode``; errors of the valid points 1..n: in the robot frame (mm), and in the image
    against the lab camera's true projection (px: the detection's own error, without the
    calibration's; tracked positions go back to px through the calibration they came from)."""
    from stringcast.calibrate.calibration import Calibration
    from stringcast.core.files import read_json
    from stringcast.track.tracking import run_tracking

    df = run_tracking(trial, res / "calibration.json", res / "sync.json", campaign, res / f"{mode}.parquet",
                      tracking=dataclasses.replace(tracking, mode=mode))
    m = df.merge(pd.read_parquet(trial / "ground_truth.parquet"), on=["frame", "point"], suffixes=("", "_true"))
    pts = m[m["point"] > 0]
    assert pts.loc[~pts["valid"], ["x_m", "y_m"]].isna().all().all()  # never a position for an invalid point
    ok = pts[pts["valid"]]
    e_mm = np.hypot(ok["x_m"] - ok["x_m_true"], ok["y_m"] - ok["y_m_true"]).to_numpy() * 1000
    if len(ok) == 0:
        return e_mm, e_mm, float(pts["valid"].mean()), {}
    cam = read_json(trial / "ground_truth.json")["camera"]
    tp, _ = cv2.projectPoints(np.column_stack([ok["x_m_true"], ok["y_m_true"], np.zeros(len(ok))]),
                              np.array(cam["rvec"]), np.array(cam["tvec"]), np.array(cam["K"]), np.array(cam["dist"]))
    cal = Calibration.from_json(res / "calibration.json")
    e_px = np.hypot(*(cal.robot_to_pixel(ok[["x_m", "y_m"]].to_numpy()) - tp.reshape(-1, 2)).T)
    return e_mm, e_px, float(pts["valid"].mean()), ok.groupby("point").size().to_dict()


def test_marker_mode_on_a_tiny_lab_render_with_bands(tmp_path, config, settings):
    """Light bands (tape of reflectance 0.45 on a 0.10 cord, 8 mm) at the 5 points: marker mode finds
    them all, to a tenth of a pixel in the image; markerless still works on the same footage."""
    from stringcast.calibrate.calibration import Calibration
    from stringcast.core.files import read_json

    trial, res, campaign, cfg = tiny_lab_trial(tmp_path, config, {"width_mm": 8.0, "reflectance": 0.45})
    stats = {}
    for mode in ("markers", "markerless"):
        e_mm, e_px, share, per_point = stats[mode] = _track(trial, res, campaign, settings.tracking, mode)
        print(f"lab tiny with bands, {mode}: median {np.median(e_mm):.2f} mm, p95 {np.percentile(e_mm, 95):.2f} mm, "
              f"valid {share:.3f}, valid frames per point {per_point}; in the image against the true camera: "
              f"median {np.median(e_px):.2f} px, p95 {np.percentile(e_px, 95):.2f} px")
    truth = pd.read_parquet(trial / "ground_truth.parquet").query("point > 0")
    cam = read_json(trial / "ground_truth.json")["camera"]
    tp, _ = cv2.projectPoints(np.column_stack([truth["x_m"], truth["y_m"], np.zeros(len(truth))]),
                              np.array(cam["rvec"]), np.array(cam["tvec"]), np.array(cam["K"]), np.array(cam["dist"]))
    e_cal = np.hypot(*(Calibration.from_json(res / "calibration.json").robot_to_pixel(
        truth[["x_m", "y_m"]].to_numpy()) - tp.reshape(-1, 2)).T)
    print(f"the calibration at the true points: median {np.median(e_cal):.2f} px off the true camera")
    # measured: markers 0.94 mm median, p95 1.49 mm, valid 0.952 (the tip in 67 of 87 frames); in the image
    # 0.10 px median, p95 0.31 px (the detection's own error). Markerless 0.75 mm, p95 1.49 mm, valid 0.959.
    # The calibration puts the true points 0.67 px (0.9 mm) median off the true camera here: a band's
    # position carries that offset whole, while the markerless arc, anchored at the grasp from the forward
    # kinematics, cancels it along the string; so in the robot frame marker mode is not better on this clip.
    # (Its image-space error, 0.37 px, is not comparable: it holds the calibration's offset.)
    e_mm, e_px, share, per_point = stats["markers"]
    assert share > 0.85 and set(per_point) == {1, 2, 3, 4, 5}, stats["markers"][2:]
    assert np.median(e_px) < 0.2 and np.percentile(e_px, 95) < 0.6, (np.median(e_px), np.percentile(e_px, 95))
    assert np.median(e_mm) < 1.3 and np.percentile(e_mm, 95) < 2.5, (np.median(e_mm), np.percentile(e_mm, 95))
    assert np.median(e_mm) < 1.3 * np.median(e_cal) + 0.3, (np.median(e_mm), np.median(e_cal))  # 1.3 mm per px
    e_mm, _, share, _ = stats["markerless"]
    assert share > 0.85 and np.median(e_mm) < 1.2 and np.percentile(e_mm, 95) < 2.5, (share, np.median(e_mm))


def test_marker_mode_invents_nothing_on_a_plain_string(tmp_path, config, settings):
    """The same clip without bands: marker mode must leave (almost) every point invalid."""
    trial, res, campaign, cfg = tiny_lab_trial(tmp_path, config, None)
    e_mm, e_px, share, per_point = _track(trial, res, campaign, settings.tracking, "markers")
    print(f"lab tiny without bands, markers: valid {share:.3f}, per point {per_point}")
    # measured: valid 0.000 (no point in any of the 87 frames)
    assert share < 0.02, (share, per_point)
