"""Residual correction of the plan (stringcast.plan.residual): delay, residual, and the planner aiming with it."""
from dataclasses import replace
import dataclasses

import numpy as np
import pandas as pd
import pytest

from stringcast.plan import motion as mo
from stringcast.plan import next_motion as nm
from stringcast.plan import planning as pn
from stringcast.execute.executor import build_command
from stringcast.core.files import DataError, write_json, write_parquet
from stringcast.core.joint_log import write_joint_table
from stringcast.model.string_model import closest_approach_batch, simulate
from stringcast.plan.residual import motion_delay, observed_miss, observed_tip, tip_residual

RATE = 500.0


def _motion(seed=0, T=0.5):
    cps = mo.sample_control_points(np.random.default_rng(seed), T, 3, 6, 40.0, 1)[0]
    dq, _ = mo.joint_paths(cps, T, RATE)
    return np.array([0.6, -0.3, 0.2]) + dq


def test_motion_delay_finds_pre_roll_and_servo_lag():
    q = _motion()
    t_cmd, q_cmd, t_move = build_command(q, RATE, 0.3, 0.4)
    lag = 0.0083                                     # not a multiple of the 2 ms period: sub-sample
    rng = np.random.default_rng(1)
    q_log = np.column_stack([np.interp(t_cmd - lag, t_cmd, q_cmd[:, j]) for j in range(3)])
    q_log += rng.normal(0, 2e-4, q_log.shape)
    t_log = t_cmd + 12.5                             # any controller clock
    assert motion_delay(t_log, q_log, q, RATE) == pytest.approx(12.5 + t_move + lag, abs=2e-4)
    with pytest.raises(DataError, match="joints.csv.*not a recording"):
        motion_delay(t_log, q_log, _motion(seed=7), RATE)


def test_tip_residual_is_tracked_minus_model():
    ft = np.arange(-0.05, 0.6, 1 / RATE)
    model = np.stack([np.column_stack([np.sin(ft), np.cos(ft)]), np.column_stack([ft, ft])])       # (2, F, 2)
    offset = np.column_stack([0.02 + 0.1 * ft, -0.01 * np.ones_like(ft)])
    tip = model[0] + offset
    valid = np.ones(len(ft), bool)
    valid[100:140] = False                           # a gap: interpolated, not used
    tip[~valid] = np.nan
    res, why = tip_residual(ft, tip, valid, model, horizon=0.4901, delay_s=0.31, dt=0.002)
    assert why == "" and res.delta.shape == (2, 246, 2) and res.delay_s == 0.31
    grid = np.arange(246) * 0.002
    np.testing.assert_allclose(res.delta[0, :, 0], 0.02 + 0.1 * grid, atol=1e-9)   # linear: exact in the gap too
    seen = (grid < ft[99]) | (grid > ft[140])        # set 1's residual is curved: compare outside the gap
    expect = np.column_stack([np.sin(grid) + 0.02 + 0.1 * grid - grid, np.cos(grid) - 0.01 - grid])
    np.testing.assert_allclose(res.delta[1][seen], expect[seen], atol=2e-6)
    np.testing.assert_allclose(res.targets(np.array([1.2, 0.3]))[0, 0], [1.18, 0.31], atol=1e-12)
    blown = model.copy()
    blown[1, 200:] = np.nan                          # set 1 blew up on the played motion: it takes set 0's residual
    res_b, _ = tip_residual(ft, tip, valid, blown, horizon=0.4901, delay_s=0.31, dt=0.002)
    np.testing.assert_array_equal(res_b.delta[1], res_b.delta[0])
    np.testing.assert_allclose(res_b.delta[0], res.delta[0])
    valid[:] = False
    valid[::3] = True                                # a third of the frames: not enough
    res, why = tip_residual(ft, np.where(valid[:, None], tip, np.nan), valid, model, 0.5, 0.31)
    assert res is None and "tracked in 28%" in why and "need 50%" in why


def test_observed_miss_is_the_tracked_closest_approach():
    """Only valid frames inside [0, horizon] count; a tip never tracked there gives NaN."""
    ft = np.linspace(-0.2, 1.0, 121)
    tip = np.column_stack([ft, np.zeros_like(ft)])        # along x, through (0.5, 0) at t = 0.5
    valid = np.ones(len(ft), bool)
    assert observed_miss(ft, tip, valid, np.array([0.5, 0.03]), 0.8) == pytest.approx(0.03)
    assert observed_miss(ft, tip, valid, np.array([0.9, 0.0]), 0.8) == pytest.approx(0.1, abs=1e-9)  # horizon
    valid[(ft > 0.4) & (ft < 0.6)] = False
    assert observed_miss(ft, tip, valid, np.array([0.5, 0.0]), 0.8) == pytest.approx(0.1, abs=1e-9)
    assert np.isnan(observed_miss(ft, tip, np.zeros(len(ft), bool), np.array([0.5, 0.0]), 0.8))


def test_observed_tip_reads_the_tip_on_motion_time(tmp_path):
    q = _motion()
    t_cmd, q_cmd, t_move = build_command(q, RATE, 0.3, 0.4)
    frames = np.arange(0, 300)
    t = 0.1 + frames / 250.0
    n = 3
    rows = [(f, tf, p, 0.1 * p + tf, -0.1 * p, p != n or f % 2 == 0) for f, tf in zip(frames, t) for p in range(n + 1)]
    df = pd.DataFrame(rows, columns=["frame", "t_s", "point", "x_m", "y_m", "valid"])
    ft, tip, valid, delay = observed_tip(df, t_cmd, q_cmd, q, n, RATE)
    assert delay == pytest.approx(t_move, abs=1e-6)
    np.testing.assert_allclose(ft, t - t_move)
    np.testing.assert_allclose(tip[:, 0], 0.3 + t)
    assert valid.tolist() == (frames % 2 == 0).tolist()


def test_planner_aims_the_model_at_the_corrected_target(tmp_path, settings, campaign):
    """The played motion's tip was seen 40 mm further out than the model said: the next plan
    hits the target with the model aimed at target - offset, and run_plan records the correction."""
    model = settings.model
    motion = replace(settings.motion, max_candidates=2048, extra_after_hit=64, batch=64, posture_pool=8)
    coeffs, mu = pn.first_parameters(model=model, motion=motion, string=campaign.string)
    first = pn.search(campaign, model, motion, coeffs, mu, np.random.default_rng(5))
    pn.write_motion(first, campaign, motion, coeffs, mu, 0, tmp_path / "m1.csv", tmp_path / "m1.json", "first")
    pl = pn.Predictor(campaign, model, motion, coeffs, mu)
    m1, p0 = first.motion, pl.equilibrium(first.motion.q0)
    # the "trial": joints as commanded (pre-roll 0.3 s, 6 ms lag), tracks = model tip + offset
    t_cmd, q_cmd, t_move = build_command(m1.q, RATE, 0.3, 0.6)
    q_log = np.column_stack([np.interp(t_cmd - 0.006, t_cmd, q_cmd[:, j]) for j in range(3)])
    write_joint_table(tmp_path / "joints.csv", t_cmd, q_log)
    ft = np.arange(0.0, t_cmd[-1], 1 / RATE)
    hand_t, hand = pl.hand_trajectory(m1.q)
    pos, _ = simulate(coeffs, mu, hand_t, hand, p0, pl.l0, pl.psi0, pl.dt,
                      np.concatenate([[0.0], np.clip(ft - t_move - 0.006, 0, None)]))
    offset = np.array([0.04, -0.01])
    n = campaign.string.n_points
    grasp = np.repeat(hand[:1, None, :2], len(ft), axis=0)
    xy = np.concatenate([grasp, pos[1:, :n - 1], pos[1:, -1:] + offset], axis=1)     # (F, n + 1, 2): tip moved
    write_parquet(tmp_path / "tracks.parquet", pd.DataFrame({
        "frame": np.repeat(np.arange(len(ft)), n + 1), "t_s": np.repeat(ft, n + 1),
        "point": np.tile(np.arange(n + 1), len(ft)), "x_m": xy[..., 0].ravel(), "y_m": xy[..., 1].ravel(),
        "valid": np.ones(len(ft) * (n + 1), bool)}))
    write_json(tmp_path / "params.json", {"coefficients": dict(zip(pn.PARAM_NAMES, coeffs)), "mu": mu})
    res = nm.run_plan(tmp_path / "params.json", tmp_path / "m1.json", campaign, tmp_path / "m2.csv",
                      tmp_path / "m2.json", seed=1, tracks_parquet=tmp_path / "tracks.parquet",
                      joints_csv=tmp_path / "joints.csv", model=model,
                      motion=(motion := replace(motion, residual_correction=True)))
    assert res.hit and res.residual["delay_s"] == pytest.approx(t_move + 0.006, abs=2e-4)
    assert res.residual["median_mm"] == pytest.approx(np.hypot(*offset) * 1000, abs=0.5)
    # an independent run: the chosen motion's model tip, moved by the offset, passes where the plan says
    hand_t, hand = pl.hand_trajectory(res.motion.q)
    d, *_ = closest_approach_batch(coeffs, mu, hand_t, hand[None], [0], p0[None], pl.l0, pl.psi0, pl.dt, 0.0,
                                   res.motion.T + pl.flight, campaign.target.xy - offset)
    assert d[0] == pytest.approx(res.d_min, abs=2e-3) and d[0] <= campaign.target.radius
    doc = nm.read_json(tmp_path / "m2.json")
    assert doc["played_observed_miss_mm"] > 0 and doc["residual_correction"]["sets"] == 1
    # a tracked miss beyond replan_miss_mm: a new motion from scratch (a new posture or T), no correction
    motion = replace(motion, replan_miss_mm=1.0)
    res = nm.run_plan(tmp_path / "params.json", tmp_path / "m1.json", campaign, tmp_path / "m4.csv",
                      tmp_path / "m4.json", seed=1, tracks_parquet=tmp_path / "tracks.parquet",
                      joints_csv=tmp_path / "joints.csv", model=model, motion=motion)
    assert "replan_miss_mm" in res.message and res.residual is None
    assert res.motion.T != m1.T or not np.allclose(res.motion.q0, m1.q0)
    # replan_perturb_rad_s: first a wider, corrected perturbation of the played motion (its posture and T)
    motion = replace(motion, replan_perturb_rad_s=1.0)
    res = nm.run_plan(tmp_path / "params.json", tmp_path / "m1.json", campaign, tmp_path / "m5.csv",
                      tmp_path / "m5.json", seed=1, tracks_parquet=tmp_path / "tracks.parquet",
                      joints_csv=tmp_path / "joints.csv", model=model, motion=motion)
    assert res.hit and "perturbed by +-1 rad/s" in res.message and res.residual is not None
    assert res.motion.T == m1.T and np.allclose(res.motion.q0, m1.q0)
    assert [nm.read_json(tmp_path / f"m{k}.json")["origin"] for k in (2, 4, 5)] == \
        ["perturbation", "new", "wide_perturbation"]
    # ... but not twice in a row: a played wide perturbation that missed so gets the new motion
    write_json(tmp_path / "m1w.json", {**nm.read_json(tmp_path / "m1.json"), "origin": "wide_perturbation"})
    res = nm.run_plan(tmp_path / "params.json", tmp_path / "m1w.json", campaign, tmp_path / "m5w.csv",
                      tmp_path / "m5w.json", seed=1, tracks_parquet=tmp_path / "tracks.parquet",
                      joints_csv=tmp_path / "joints.csv", model=model, motion=motion)
    assert "after a wide perturbation: a new motion" in res.message and res.origin == "new"
    assert res.residual is None and (res.motion.T != m1.T or not np.allclose(res.motion.q0, m1.q0))
    # ... and the new motion when that perturbation cannot hit (too small to bridge the tracked 17 mm
    # to a 5 mm target)
    motion = replace(motion, replan_perturb_rad_s=1e-6, max_candidates=256)
    small_target = dataclasses.replace(campaign, target=dataclasses.replace(campaign.target, radius=0.005))
    res = nm.run_plan(tmp_path / "params.json", tmp_path / "m1.json", small_target, tmp_path / "m6.csv",
                      tmp_path / "m6.json", seed=1, tracks_parquet=tmp_path / "tracks.parquet",
                      joints_csv=tmp_path / "joints.csv", model=model, motion=motion)
    assert "hits under 0% of the sets (< 90%)" in res.message and "a new motion" in res.message
    assert res.residual is None and (res.motion.T != m1.T or not np.allclose(res.motion.q0, m1.q0))
    # a model further off the played tip (41 mm) than replan_residual_mm: no perturbation, a new motion
    motion = replace(motion, replan_miss_mm=0.0, replan_residual_mm=30.0)
    res = nm.run_plan(tmp_path / "params.json", tmp_path / "m1.json", campaign, tmp_path / "m7.csv",
                      tmp_path / "m7.json", seed=1, tracks_parquet=tmp_path / "tracks.parquet",
                      joints_csv=tmp_path / "joints.csv", model=model, motion=motion)
    assert "relies on a model 41 mm off" in res.message and "a new motion" in res.message
    assert res.residual is None and (res.motion.T != m1.T or not np.allclose(res.motion.q0, m1.q0))
    # without the trial's files the correction cannot be made, and says so
    with pytest.raises(pn.ConfigError, match="residual_correction"):
        nm.run_plan(tmp_path / "params.json", tmp_path / "m1.json", campaign, tmp_path / "m3.csv",
                    tmp_path / "m3.json", seed=1, model=model, motion=motion)
