"""The next-motion prediction error (stringcast.estimate.prediction): an estimate driven by another
trial's measured joints, its tip against that trial's tracked tip. Small synthetic trials made by
the model itself (test_estimation.make_trial), so the true error is known."""
import json

import numpy as np
import pandas as pd
import pytest

from stringcast.cli import main
from stringcast.core import PARAM_NAMES, DataError, motion_start, motion_window, read_joint_table, write_json
from stringcast.estimate.prediction import prediction_verdict, run_prediction
from stringcast.model import parameters as prm
from test_estimation import CHI_TRUE, make_trial


@pytest.fixture
def truth(settings, campaign):
    """The true set (coeffs (10,), mu (n,)) the synthetic trials are made with."""
    chi = CHI_TRUE[:len(PARAM_NAMES) + campaign.string.mass_groups().max() + 1]
    return prm.decode(chi, settings.model, campaign.string.mass_groups())


@pytest.fixture
def next_trial(campaign, truth, tmp_path):
    """params.json of the true set (trial k's estimate, perfect) and trial k + 1: another motion
    (slower), filmed by the model. Returns (params.json, folder, tracks table)."""
    c, mu = truth
    write_json(tmp_path / "params.json", {"coefficients": dict(zip(PARAM_NAMES, c)), "mu": mu})
    df, _, _, _ = make_trial(campaign, c, mu, tmp_path, speed=0.6, t0=20.0)
    return tmp_path / "params.json", tmp_path, df


def _predict(settings, campaign, params, d, out="prediction.json"):
    return run_prediction(params, d / "tracks.parquet", d / "joints.csv", campaign, d / out, model=settings.model,
                          tracking=settings.tracking, motion=settings.motion)


def test_the_true_set_predicts_its_own_motion(settings, campaign, next_trial):
    """The model that made the trial predicts it to within its own sampling error; the window runs from
    the joint log's motion start to the tracked tip's closest approach to the target."""
    params, d, df = next_trial
    doc = _predict(settings, campaign, params, d)
    assert doc["median_mm"] < 0.2 and doc["p95_mm"] < 0.5 and not doc["blew_up"]
    assert doc["valid_share"] == 1.0 and doc["valid_frames"] == doc["frames"] > 50
    assert doc["verdict"] == {"status": "ok", "reasons": []}
    t, q = read_joint_table(d / "joints.csv")
    tip = df[df["point"] == campaign.string.n_points]
    live = tip[(tip["t_s"] >= motion_start(t, q)) & (tip["t_s"] <= motion_window(t, q)[1] + settings.motion.flight_window_s)
               & (tip["t_s"] <= t[-1])]
    d_target = np.hypot(live["x_m"] - campaign.target.x, live["y_m"] - campaign.target.y)
    assert doc["window_s"][0] == pytest.approx(motion_start(t, q))
    assert doc["window_s"][1] == pytest.approx(live["t_s"].to_numpy()[np.argmin(d_target)])
    assert doc["tracked_closest_approach_mm"] == pytest.approx(d_target.min() * 1000)
    assert json.loads((d / "prediction.json").read_text())["median_mm"] == doc["median_mm"]


def test_a_shifted_tip_gives_the_shift(settings, campaign, next_trial):
    """The tracked tip moved 6 mm along x from the motion's start on (the rest state, and so the model,
    unchanged): the error is the shift, at every frame."""
    params, d, df = next_trial
    t, q = read_joint_table(d / "joints.csv")
    moved = (df["point"] == campaign.string.n_points) & (df["t_s"] >= motion_start(t, q) - 0.01)
    df.loc[moved, "x_m"] += 0.006
    df.to_parquet(d / "tracks.parquet")
    doc = _predict(settings, campaign, params, d)
    assert doc["median_mm"] == pytest.approx(6.0, abs=0.2) and doc["p95_mm"] == pytest.approx(6.0, abs=0.5)


def test_another_set_predicts_worse(settings, campaign, truth, next_trial):
    """A set fitted elsewhere (every coefficient doubled) predicts the motion worse than the true one."""
    params, d, _ = next_trial
    c, mu = truth
    write_json(d / "other.json", {"coefficients": dict(zip(PARAM_NAMES, 2 * c)), "mu": 1.5 * mu})
    good, bad = _predict(settings, campaign, params, d), _predict(settings, campaign, d / "other.json", d, "o.json")
    assert bad["median_mm"] > 10 * max(good["median_mm"], 0.05)


def test_few_tracked_tips_warn_and_none_is_an_error(settings, campaign, next_trial):
    params, d, df = next_trial
    n = campaign.string.n_points
    tip = df["point"] == n
    rows = np.flatnonzero(tip)
    df.loc[df.index[rows[np.arange(len(rows)) % 3 != 0]], "valid"] = False   # two in three tips lost
    df.to_parquet(d / "tracks.parquet")
    doc = _predict(settings, campaign, params, d)
    assert doc["verdict"]["status"] == "warn" and "tracked in" in doc["verdict"]["reasons"][0]
    assert 0.2 < doc["valid_share"] < 0.45 and doc["median_mm"] < 0.2
    df.loc[tip, "valid"] = False
    df.to_parquet(d / "tracks.parquet")
    with pytest.raises(DataError, match=r"tracks\.parquet: no tracked tip"):
        _predict(settings, campaign, params, d)
    assert prediction_verdict({"blew_up": True, "valid_frames": 0, "valid_share": 0.0, "frames": 9}).status == "warn"


def test_a_params_file_without_masses_is_named(settings, campaign, next_trial):
    params, d, _ = next_trial
    write_json(d / "bad.json", {"coefficients": json.loads(params.read_text())["coefficients"]})
    with pytest.raises(DataError, match=r"bad\.json.*mu"):
        _predict(settings, campaign, d / "bad.json", d)


def test_predict_command(config, campaign, next_trial, tmp_path, capsys):
    """``stringcast predict`` (the workflow's predict rule) writes prediction.json and says its figure."""
    params, d, _ = next_trial
    camp = tmp_path / "campaign.yaml"
    camp.write_text("string: 1\ntarget: 1\n")
    rc = main(["--config", str(config["_path"]), "predict", "--params", str(params), "--tracks",
               str(d / "tracks.parquet"), "--joints", str(d / "joints.csv"), "--campaign", str(camp), "--out",
               str(tmp_path / "p.json")])
    assert rc == 0 and "next-motion prediction: ok: median" in capsys.readouterr().out
    assert pd.notna(json.loads((tmp_path / "p.json").read_text())["median_mm"])
