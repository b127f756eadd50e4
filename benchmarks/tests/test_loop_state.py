"""The loop benchmark's state mode (benchmarks/loop_state.py): the lab's truth with the tracking's
measured error drawn on it, written where the workflow expects tracking's files, so that Snakemake
runs only the estimate and plan rules on them."""
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from benchmarks.loop_state import WORKFLOW_ARGS, ErrorModel, draw_tracks, error_model, synthesize_trial
from stringcast_lab.campaign import tracking_errors
from stringcast.core import (DataError, forward_kinematics, joints_at, load_campaign, load_yaml, read_json,
                             read_parquet, settings_from_config, write_joint_table, write_json, write_parquet,
                             write_yaml)

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests" / "workflow"))
from lab_project import make_project  # noqa: E402

MODEL = ErrorModel(0.35, 2.4, 0.75, (0.05, -0.27), {"test": True})


def _sources(d: Path) -> Path:
    d.mkdir()
    write_json(d / "tracking.json", {"median_mm": 0.3, "p95_mm": 1.5, "valid_share": 0.8, "git_commit": "abc",
                                     "per_string": {"1": {"median_mm": 0.35, "p95_mm": 2.4, "valid_share": 0.75}}})
    write_json(d / "generalization.json", {"per_setup": [{"sync_error_ms": 0.05}, {"sync_error_ms": None},
                                                         {"sync_error_ms": -0.27}]})
    return d


def test_error_model_reads_the_measured_figures(tmp_path):
    src = _sources(tmp_path / "bench")
    m1, m5 = error_model(1, src), error_model(5, src)
    assert (m1.median_mm, m1.p95_mm, m1.valid_share, m1.sync_errors_ms) == (0.35, 2.4, 0.75, (0.05, -0.27))
    assert (m5.median_mm, m5.p95_mm) == (0.3, 1.5) and m5.source["tracking"]["figures"] == "overall"
    assert m1.source["tracking"]["git_commit"] == "abc" and m1.as_dict()["sigma_log"] == pytest.approx(m1.sigma_log)
    assert m1.source["sync"]["file"].endswith("generalization.json")
    (src / "generalization.json").unlink()
    with pytest.raises(DataError, match=r"generalization\.json.*benchmarks\.generalization"):
        error_model(1, src)
    # without the setup family's figures: the sync benchmark's, per case (the default camera)
    write_json(src / "sync.json", {"cases": {"1": {"swept_offset_error_ms": 0.02}, "5": {"swept_offset_error_ms": -0.1},
                                             "7": {"swept_offset_error_ms": None}}, "git_commit": "def"})
    m = error_model(1, src)
    assert m.sync_errors_ms == (0.02, -0.1) and m.source["sync"]["figures"] == "cases.*.swept_offset_error_ms"
    (src / "tracking.json").unlink()
    with pytest.raises(DataError, match=r"tracking\.json.*benchmarks\.tracking"):
        error_model(1, src)


def _trial(campaign, d: Path, frames: int = 4000, fps: float = 500.0):
    """A lab-like trial: joints.csv (the arm still, then its first joint turning), ground_truth.parquet
    (the string hanging straight down from the grasp at the true frame times) and ground_truth.json."""
    arm, n, L = campaign.arm, campaign.string.n_points, campaign.string.length
    t_j = np.arange(0, frames / fps + 0.1, 1 / arm.controller_rate)
    q = np.tile([1.0, -0.8, -0.5], (len(t_j), 1))
    q[:, 0] += 0.3 * np.clip(t_j - 1.0, 0, 1)
    d.mkdir(parents=True, exist_ok=True)
    write_joint_table(d / "joints.csv", t_j, q)
    t = 0.05 + np.arange(frames) / fps
    grasp = forward_kinematics(arm, joints_at(t, t_j, q))[:, -1]
    xy = grasp[:, None] - np.arange(n + 1)[None, :, None] * np.array([0.0, L / n])
    write_parquet(d / "ground_truth.parquet", pd.DataFrame({
        "frame": np.repeat(np.arange(frames), n + 1), "t_s": np.repeat(t, n + 1),
        "point": np.tile(np.arange(n + 1), frames), "x_m": xy[..., 0].ravel(), "y_m": xy[..., 1].ravel()}))
    write_json(d / "ground_truth.json", {"fps": fps, "hit": False})
    return t_j, q


def test_drawn_tracks_have_the_measured_error(campaign, tmp_path):
    """Median and p95 of the drawn points' error, their valid share and the sync shift are the model's;
    point 0 is the grasp's forward kinematics at the shifted times; the draw is seeded."""
    t_j, q = _trial(campaign, tmp_path)
    truth = read_parquet(tmp_path / "ground_truth.parquet", ["frame", "t_s", "point", "x_m", "y_m"])
    n = campaign.string.n_points
    df, sync = draw_tracks(truth, t_j, q, campaign.arm, n, MODEL, np.random.default_rng(1))
    e, share = tracking_errors(df, truth)
    assert np.median(e) == pytest.approx(0.35, rel=0.03) and np.percentile(e, 95) == pytest.approx(2.4, rel=0.05)
    assert share == pytest.approx(0.75, abs=0.01) and sync * 1000 in MODEL.sync_errors_ms
    assert list(df.columns) == ["frame", "t_s", "point", "x_m", "y_m", "valid"]
    np.testing.assert_allclose(df["t_s"].to_numpy(), truth["t_s"].to_numpy() + sync)
    g = df[df["point"] == 0]
    np.testing.assert_allclose(g[["x_m", "y_m"]].to_numpy(),
                               forward_kinematics(campaign.arm, joints_at(g["t_s"].to_numpy(), t_j, q))[:, -1])
    assert df.loc[~df["valid"], "x_m"].isna().all()
    again, _ = draw_tracks(truth, t_j, q, campaign.arm, n, MODEL, np.random.default_rng(1))
    pd.testing.assert_frame_equal(df, again)


def test_state_files_feed_only_the_estimate_and_plan_rules(config, tmp_path):
    """synthesize_trial writes tracking's and the sweep's files with the state mode's note; Snakemake,
    with WORKFLOW_ARGS, then plans trial 1's motion with the estimate and plan rules alone (no video,
    calibration, sync or tracking); a second call reuses the files as they are."""
    root = make_project(tmp_path / "p", config)
    data = root / "data" / "c"
    write_yaml(data / "campaign.yaml", {"string": 1, "target": 1, "setup": "default", "seed": 0})
    cfg = load_yaml(root / "config" / "config.yaml")
    campaign = load_campaign(data / "campaign.yaml", cfg)
    t_j, q = _trial(campaign, data / "trial_1", frames=300, fps=250.0)
    write_joint_table(data / "trial_1" / "motion.csv", t_j, np.repeat(q[:1], len(t_j), 0))   # a played (still) motion
    write_json(data / "trial_1" / "motion.json", {"q0_rad": list(q[0]), "T_s": float(t_j[-1]),
                                                  "control_points_rad_s": [[0.0]] * 3})
    res = root / "results" / "c" / "trial_1"
    rec = synthesize_trial(1, data / "trial_1", res, campaign, MODEL, 0, settings_from_config(cfg).tracking)
    assert not rec["reused"] and rec["sync_error_ms"] in MODEL.sync_errors_ms
    for name in ("geometry.json", "clock.json", "tracking.json"):
        doc = read_json(res / name)
        assert doc["state_mode"]["mode"] == "state" and doc["verdict"]["status"] in ("ok", "warn"), name
    assert "not calibrated, synced or tracked" in read_json(res / "geometry.json")["verdict"]["reasons"][0]
    assert read_json(res / "tracking.json")["valid_share"] is not None
    assert json.loads((root / "state_mode" / "trial_1.json").read_text())["trial"] == 1
    proc = subprocess.run([sys.executable, "-m", "snakemake", "-n", "results/c/trial_1/motion.csv", "--cores", "1",
                           "--directory", str(root), *WORKFLOW_ARGS], cwd=root, capture_output=True, text=True)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert set(re.findall(r"^rule (\w+):", out, flags=re.M)) == {"estimate", "plan"}, out
    mtime = (res / "tracks.parquet").stat().st_mtime_ns
    assert synthesize_trial(1, data / "trial_1", res, campaign, MODEL, 0, settings_from_config(cfg).tracking)["reused"]
    assert (res / "tracks.parquet").stat().st_mtime_ns == mtime
