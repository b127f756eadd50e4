"""Motion planning (paper Section V): parameter sets, hit search, motion files, stage entry points."""
from dataclasses import replace

import numpy as np
import pytest

from stringcast.plan import motion as mo
from stringcast.plan import next_motion as nm
from stringcast.plan import planning as pn
from stringcast.core.arm import check_limits
from stringcast.core import PARAM_NAMES, ConfigError, resolve_campaign
from stringcast.execute.executor import execute
from stringcast.core.files import DataError, read_json, write_json
from stringcast.core.joint_log import read_joint_table
from stringcast.model.string_model import closest_approach_batch


@pytest.fixture
def small(settings):
    """The paper's settings (``settings``) with a small search: 2048 candidates, 64 after the first hit,
    batches of 64, 8 start postures (here, not in a tests/plan/conftest.py: ``conftest`` is
    tests/conftest.py's module name for the tests that import from it; test_taut.py imports it)."""
    return _with(settings, max_candidates=2048, extra_after_hit=64, batch=64, posture_pool=8)


def _with(s, **motion):
    """Settings ``s`` with these motion settings changed."""
    return replace(s, motion=replace(s.motion, **motion))


def _first(s, string):
    return pn.first_parameters(model=s.model, motion=s.motion, string=string)


def test_first_parameters_carry_their_weight(settings, campaign):
    coeffs, mu = _first(settings, campaign.string)
    lo = np.array([settings.model.ranges[k][0] for k in PARAM_NAMES])
    np.testing.assert_array_equal(coeffs[1:], lo[1:])
    assert coeffs[0] > lo[0]
    top_stretch = 9.81 * mu.sum() / coeffs[0]
    assert top_stretch == pytest.approx(settings.motion.first_max_strain * campaign.string.l0)


def test_first_k_s_max_and_bad_mode(settings, campaign):
    """motion.first_k_s: max takes Table 2's largest k_s and leaves the rest of the set as it was;
    an unknown mode is a ConfigError naming the key."""
    cfg = _with(settings, first_k_s="max")
    carrying, mu_c = _first(settings, campaign.string)
    stiff, mu_s = _first(cfg, campaign.string)
    assert stiff[0] == settings.model.ranges["k_s"][1] > carrying[0]
    np.testing.assert_array_equal(stiff[1:], carrying[1:])
    np.testing.assert_array_equal(mu_s, mu_c)
    with pytest.raises(pn.ConfigError, match="motion.first_k_s"):   # refused as the settings are built
        _with(cfg, first_k_s="stiff")


def test_aim_radius_starts_the_count_at_a_pass_near_the_centre(tmp_path, campaign, small):
    """motion.aim_radius_mm: the count of extra_after_hit candidates starts at the first candidate
    within the aim radius, so with no extra candidates the plan passes within it (null: within the
    target's radius, the paper); a radius of 0 or below is refused naming the key."""
    cfg = _with(small, extra_after_hit=0)
    kw = dict(seed=0, model=cfg.model)
    edge = pn.run_first_plan(campaign, tmp_path / "a.csv", tmp_path / "a.json", motion=cfg.motion, **kw)
    aim_m = 0.5 * edge.d_min
    aimed = pn.run_first_plan(campaign, tmp_path / "b.csv", tmp_path / "b.json",
                              motion=replace(cfg.motion, aim_radius_mm=aim_m * 1000), **kw)
    assert edge.hit and aimed.hit, aimed.message
    assert aimed.d_min <= aim_m < edge.d_min and aimed.candidates > edge.candidates
    with pytest.raises(pn.ConfigError, match="motion.aim_radius_mm"):
        _with(small, aim_radius_mm=0.0)


def test_first_plan_hits_and_is_consistent(tmp_path, campaign, small):
    res = pn.run_first_plan(campaign, tmp_path / "motion.csv", tmp_path / "motion.json", seed=0, model=small.model, motion=small.motion)
    m = res.motion
    rate = campaign.arm.controller_rate
    assert check_limits(campaign.arm, m.q, 1 / rate).ok
    assert mo.posture_ok(campaign, m.q0, 0.0)
    np.testing.assert_allclose(m.q[0], m.q0)
    qd = np.gradient(m.q, 1 / rate, axis=0)
    assert np.abs(qd[-1]).max() < 0.05  # the arm stops at T
    assert res.hit, res.message
    assert res.d_min <= campaign.target.radius and res.min_y >= campaign.arm.floor_y
    # the written file holds the motion, and an independent re-run of the model on it gives the same
    # closest approach (in-memory values: the model string is chaotic, 1e-9 rad moves the tip by mm)
    t, q = read_joint_table(tmp_path / "motion.csv")
    np.testing.assert_allclose(q, m.q, atol=1e-8)
    np.testing.assert_allclose(t, m.t, atol=1e-12)
    doc = read_json(tmp_path / "motion.json")
    pl = pn.Predictor(campaign, small.model, small.motion, np.array([doc["params"][k] for k in PARAM_NAMES]), np.array(doc["mu"]))
    hand_t, hand = pl.hand_trajectory(m.q)
    d, tm, my, ok = closest_approach_batch(pl.coeffs, pl.mu, hand_t, hand[None], np.zeros(1, np.int64),
                                           pl.equilibrium(m.q0)[None], pl.l0, pl.psi0, pl.dt, 0.0,
                                           doc["T_s"] + doc["flight_window_s"], campaign.target.xy)
    assert ok[0] and d[0] == pytest.approx(res.d_min, abs=1e-9)
    assert doc["hit_predicted"] and doc["closest_approach_mm"] == pytest.approx(res.d_min * 1000)
    chord = doc["chord_share_at_closest_approach"]     # the first plan's hit: how taut its string is then
    assert 0 < chord < 1.1 and doc["slack_at_predicted_hit"] == (chord < small.motion.slack_warn_chord_share)
    tip = np.array(doc["predicted_tip_path"])
    assert tip.shape[1] == 3 and np.min(np.hypot(*(tip[:, 1:] - campaign.target.xy).T)) < 0.03
    # the executor accepts the planned file
    info = execute(tmp_path / "motion.csv", "virtual", tmp_path / "trial", campaign, small.executor, {}, dry_run=True)
    assert info["dry_run"]


def test_next_plan_keeps_posture_and_T(tmp_path, campaign, small):
    rng = np.random.default_rng(5)
    coeffs, mu = _first(small, campaign.string)
    first = pn.search(campaign, small.model, small.motion, coeffs, mu, rng)
    pn.write_motion(first, campaign, small.motion, coeffs, mu, 0, tmp_path / "m1.csv", tmp_path / "m1.json", "first")
    write_json(tmp_path / "params.json", {"coefficients": dict(zip(PARAM_NAMES, coeffs * 2)), "mu": mu * 3})
    nxt = nm.run_plan(tmp_path / "params.json", tmp_path / "m1.json", campaign, tmp_path / "m2.csv", tmp_path / "m2.json", seed=1, model=small.model, motion=small.motion)
    a, b = first.motion, nxt.motion
    assert b.T == a.T and np.allclose(b.q0, a.q0)
    diff = b.control_points - a.control_points
    assert np.all(np.abs(diff) <= small.motion.perturb_rad_s + 1e-9) and np.abs(diff).max() > 0
    assert np.all(b.control_points[:, -1] == 0)
    assert check_limits(campaign.arm, b.q, 1 / campaign.arm.controller_rate).ok
    assert read_json(tmp_path / "m2.json")["params"]["k_s"] == pytest.approx(coeffs[0] * 2)


def test_unreachable_target_returns_closest(config, small):
    camp = resolve_campaign({"string": 1, "target": {"x_mm": 3000, "y_mm": 300, "radius_mm": 20}}, config, "far")
    cfg = _with(small, max_candidates=128)
    coeffs, mu = _first(cfg, camp.string)
    res = pn.search(camp, cfg.model, cfg.motion, coeffs, mu, np.random.default_rng(0))
    assert not res.hit and res.candidates == 128
    assert "no candidate hit" in res.message
    assert 1.0 < res.d_min < 2.5  # the closest approach, not a made-up number


def test_search_keeps_looking_after_first_hit(monkeypatch, campaign, small):
    """First hit at candidate 70, a closer one at 150, an even closer one beyond the extra window."""
    special = {70: 0.015, 150: 0.004, 300: 0.001}
    state = {"k": 0}

    def fake_evaluate(self, q, T, p_init):
        b = len(q)
        ids = np.arange(state["k"], state["k"] + b)
        state["k"] += b
        d = np.array([special.get(int(i), 1.0) for i in ids])
        return d, np.zeros(b), np.zeros(b), np.ones(b, bool)

    monkeypatch.setattr(pn.Predictor, "evaluate", fake_evaluate)
    monkeypatch.setattr(pn.Predictor, "tip_path", lambda self, m, p: np.zeros((0, 3)))
    cfg = _with(small, max_candidates=1000, extra_after_hit=100, batch=50)
    coeffs, mu = _first(cfg, campaign.string)
    res = pn.search(campaign, cfg.model, cfg.motion, coeffs, mu, np.random.default_rng(0))
    assert res.hit and res.d_min == pytest.approx(0.004)
    assert res.candidates == 200  # first hit in the batch ending at 100, then 100 more


def test_played_motion_without_control_points_is_refused(tmp_path, campaign, small):
    write_json(tmp_path / "played.json", {"q0_rad": [0.5, 0.0, 0.0], "T_s": 0.5, "control_points_rad_s": [[], [], []]})
    coeffs, mu = _first(small, campaign.string)
    write_json(tmp_path / "params.json", {"coefficients": dict(zip(PARAM_NAMES, coeffs)), "mu": mu})
    with pytest.raises(DataError, match="played.json"):
        nm.run_plan(tmp_path / "params.json", tmp_path / "played.json", campaign, tmp_path / "m.csv", tmp_path / "m.json", model=small.model, motion=small.motion)
    write_json(tmp_path / "bad_params.json", {"coefficients": {"k_s": 1.0}, "mu": mu})
    with pytest.raises(DataError, match="bad_params.json"):
        nm.run_plan(tmp_path / "bad_params.json", tmp_path / "played.json", campaign, tmp_path / "m.csv", tmp_path / "m.json", model=small.model, motion=small.motion)
    assert not (tmp_path / "m.csv").exists()


# ---------------------------------------------------------------------------
# Robust planner (motion.planner: robust): candidates scored under an ensemble of parameter sets
# ---------------------------------------------------------------------------
def _ensemble(s, campaign, k=4):
    coeffs, mu = _first(s, campaign.string)
    scale = np.linspace(1.0, 3.0, k)
    return np.stack([coeffs * np.r_[1.0, [s] * 9] for s in scale]), np.stack([mu * s ** 0.5 for s in scale])


def _params_doc(coeffs, mu, campaign):
    groups = campaign.string.mass_groups()
    top = [{"E_mm": 1.0 + i, "coefficients": dict(zip(PARAM_NAMES, c)),
            "mu_groups": [float(m[groups == g][0]) for g in range(groups.max() + 1)]} for i, (c, m) in enumerate(zip(coeffs, mu))]
    return {"coefficients": dict(zip(PARAM_NAMES, coeffs[0])), "mu": mu[0], "mass_groups": groups, "top": top}


def test_robust_plan_scores_the_ensemble(tmp_path, campaign, small):
    """The chosen motion's ensemble d_min is what an independent run of each member gives."""
    coeffs, mu = _first(small, campaign.string)
    first = pn.search(campaign, small.model, small.motion, coeffs, mu, np.random.default_rng(5))
    pn.write_motion(first, campaign, small.motion, coeffs, mu, 0, tmp_path / "m1.csv", tmp_path / "m1.json", "first")
    ens_c, ens_mu = _ensemble(small, campaign)
    write_json(tmp_path / "params.json", _params_doc(ens_c, ens_mu, campaign))
    cfg = _with(small, planner="robust", max_candidates=256, extra_after_hit=64, robust_screen_mm=200.0)
    res = nm.run_plan(tmp_path / "params.json", tmp_path / "m1.json", campaign, tmp_path / "m2.csv", tmp_path / "m2.json", seed=1, model=cfg.model, motion=cfg.motion)
    assert res.planner == "robust" and res.ensemble_d_min.shape == (4,)
    pl = pn.Predictor(campaign, cfg.model, cfg.motion, ens_c[0], ens_mu[0])
    hand_t, hand = pl.hand_trajectory(res.motion.q)
    r = campaign.target.radius
    for k in range(4):
        p0 = pl.equilibrium(res.motion.q0, ens_c[k], ens_mu[k])
        d, _, my, ok = closest_approach_batch(ens_c[k], ens_mu[k], hand_t, hand[None], np.zeros(1, np.int64), p0[None],
                                              pl.l0, pl.psi0, pl.dt, 0.0, res.motion.T + pl.flight, campaign.target.xy)
        assert d[0] == pytest.approx(res.ensemble_d_min[k], abs=1e-9)
        assert ok[0] and my[0] >= campaign.arm.floor_y  # so a hit is d_min <= radius
    assert res.hit_share == pytest.approx(np.mean(res.ensemble_d_min <= r))
    assert res.margin == pytest.approx(r - np.median(res.ensemble_d_min))
    doc = read_json(tmp_path / "m2.json")
    assert doc["planner"] == "robust" and doc["ensemble_size"] == 4
    assert doc["ensemble_hit_share"] == pytest.approx(res.hit_share)
    assert doc["ensemble_margin_mm"] == pytest.approx(res.margin * 1000)
    # the paper's planner (default) ignores the ensemble and writes no ensemble figures
    res_p = nm.run_plan(tmp_path / "params.json", tmp_path / "m1.json", campaign, tmp_path / "m3.csv", tmp_path / "m3.json", seed=1, model=small.model, motion=small.motion)
    assert res_p.planner == "paper" and res_p.hit_share is None
    assert read_json(tmp_path / "m3.json")["ensemble_hit_share"] is None


def _fake_model(monkeypatch, d_best: dict, members: dict, screened: int | None = None) -> dict:
    """Fake Predictor: candidate i (counted over the search's batches) passes d_best[i] m from the
    target under the planning set (1 m if absent) and members[i] under the 4 ensemble members;
    ``screened``: how many candidates each call must hand the ensemble. Every model string is taut
    (chord share 1) at its closest approach. Returns the counter (set state["k"] = 0 to search again)
    and state["id_of"], each candidate's number by its joint trajectory's bytes."""
    state = {"k": 0, "id_of": {}}

    def fake_evaluate(self, q, T, p_init):
        b = len(q)
        state["ids"] = np.arange(state["k"], state["k"] + b)
        state["id_of"].update({qi.tobytes(): int(i) for qi, i in zip(q, state["ids"])})
        state["k"] += b
        return np.array([d_best.get(int(i), 1.0) for i in state["ids"]]), np.zeros(b), np.zeros(b), np.ones(b, bool)

    def fake_ensemble(self, q, T, p_init, coeffs, mu):
        assert screened is None or (len(q) == screened and p_init.shape[:2] == (screened, 4))
        d = np.array([members[int(i)] for i in state["ids"] if int(i) in members])
        return d, np.zeros_like(d), np.ones(d.shape, bool)

    monkeypatch.setattr(pn.Predictor, "evaluate", fake_evaluate)
    monkeypatch.setattr(pn.Predictor, "evaluate_ensemble", fake_ensemble)
    monkeypatch.setattr(pn.Predictor, "equilibrium", lambda self, q0, c=None, m=None: np.zeros((self.n, 2)))
    monkeypatch.setattr(pn.Predictor, "tip_path", lambda self, m, p: np.zeros((0, 3)))
    monkeypatch.setattr(pn.Predictor, "chord_share", lambda self, q, p, t: np.ones(len(q)))
    return state


def test_robust_prefers_hit_share_then_margin(monkeypatch, campaign, small):
    """Fake model: candidate 3 hits under every member, 7 under most with a larger margin, 5 only under the best."""
    d_best = {3: 0.015, 5: 0.001, 7: 0.010}
    members = {3: [0.015, 0.019, 0.018, 0.017], 5: [0.001, 0.5, 0.5, 0.5], 7: [0.010, 0.001, 0.002, 0.5]}
    state = _fake_model(monkeypatch, d_best, members, screened=3)   # only the screened ones go to the ensemble
    cfg = _with(small, max_candidates=20, extra_after_hit=100, batch=20)
    coeffs, mu = _first(cfg, campaign.string)
    res = pn.search(campaign, cfg.model, cfg.motion, coeffs, mu, np.random.default_rng(0), ensemble=_ensemble(cfg, campaign))
    assert res.hit_share == 1.0 and res.d_min == pytest.approx(0.015)          # candidate 3
    members[3] = [0.015, 0.019, 0.018, 0.5]                                    # now 3 and 7 both hit 3 of 4
    state["k"] = 0
    res = pn.search(campaign, cfg.model, cfg.motion, coeffs, mu, np.random.default_rng(0), ensemble=_ensemble(cfg, campaign))
    assert res.hit_share == 0.75 and res.d_min == pytest.approx(0.010)         # 7: median 6 mm beats 18.5 mm
    assert res.margin == pytest.approx(0.020 - 0.006)
    # a motion that misses under the planning set (30 mm) but hits under 3 of 4 members with the larger
    # margin is chosen, and the message says why rather than "no candidate hit"
    d_best[7], members[7] = 0.030, [0.030, 0.001, 0.002, 0.003]
    state["k"] = 0
    res = pn.search(campaign, cfg.model, cfg.motion, coeffs, mu, np.random.default_rng(0), ensemble=_ensemble(cfg, campaign))
    assert not res.hit and res.d_min == pytest.approx(0.030) and res.hit_share == 0.75
    assert "chosen for the ensemble (hits under 75% of its 4 sets)" in res.message
    assert "no candidate hit" not in res.message


def test_robust_min_share_keeps_searching_until_the_sets_agree(monkeypatch, campaign, small):
    """motion.robust_min_share: a hit under the planning set that only 1 of 4 members shares does not
    start the count of extra candidates; the search goes on to one they all share (candidate 130)."""
    state = _fake_model(monkeypatch, {5: 0.001, 130: 0.010},
                        {5: [0.001, 0.5, 0.5, 0.5], 130: [0.010, 0.012, 0.008, 0.011]})
    cfg = _with(small, max_candidates=400, extra_after_hit=20, batch=50)
    coeffs, mu = _first(cfg, campaign.string)
    res = pn.search(campaign, cfg.model, cfg.motion, coeffs, mu, np.random.default_rng(0), ensemble=_ensemble(cfg, campaign))
    assert res.hit_share == 0.25 and res.candidates == 100          # first hit in 0-49, then 20 more: 50-99
    cfg = _with(cfg, robust_min_share=0.9)
    state["k"] = 0
    res = pn.search(campaign, cfg.model, cfg.motion, coeffs, mu, np.random.default_rng(0), ensemble=_ensemble(cfg, campaign))
    assert res.hit_share == 1.0 and res.d_min == pytest.approx(0.010) and res.candidates == 200


def test_robust_all_miss_and_all_blown_up(monkeypatch, config, small):
    """No candidate near the target, or every simulation blowing up: the closest found, a message, no crash."""
    camp = resolve_campaign({"string": 1, "target": {"x_mm": 3000, "y_mm": 300, "radius_mm": 20}}, config, "far")
    cfg = _with(small, max_candidates=64)
    coeffs, mu = _first(cfg, camp.string)
    res = pn.search(camp, cfg.model, cfg.motion, coeffs, mu, np.random.default_rng(0), ensemble=_ensemble(cfg, camp))
    assert not res.hit and res.hit_share == 0.0 and res.candidates == 64
    assert "no candidate hit" in res.message and "ensemble" in res.message and np.isfinite(res.d_min)

    def blown(self, q, T, p_init):
        b = len(q)
        return np.full(b, np.inf), np.full(b, np.nan), np.full(b, -np.inf), np.zeros(b, bool)

    monkeypatch.setattr(pn.Predictor, "evaluate", blown)
    for ens in (None, _ensemble(cfg, camp)):
        res = pn.search(camp, cfg.model, cfg.motion, coeffs, mu, np.random.default_rng(1), ensemble=ens)
        assert not res.hit and res.d_min == np.inf and "no candidate hit" in res.message
        assert res.motion.q.shape[1] == 3


def test_robust_needs_the_ensemble(tmp_path, campaign, small):
    coeffs, mu = _first(small, campaign.string)
    write_json(tmp_path / "played.json", {"q0_rad": [0.5, 0.0, 0.0], "T_s": 0.5,
                                          "control_points_rad_s": [[1.0, 0.0]] * 3})
    write_json(tmp_path / "params.json", {"coefficients": dict(zip(PARAM_NAMES, coeffs)), "mu": mu})
    cfg = _with(small, planner="robust")
    with pytest.raises(DataError, match="params.json.*top"):
        nm.run_plan(tmp_path / "params.json", tmp_path / "played.json", campaign, tmp_path / "m.csv", tmp_path / "m.json", model=cfg.model, motion=cfg.motion)
    with pytest.raises(ConfigError, match="motion.planner"):   # refused as the settings are built
        cfg = _with(cfg, planner="magic")
        nm.run_plan(tmp_path / "params.json", tmp_path / "played.json", campaign, tmp_path / "m.csv", tmp_path / "m.json", model=cfg.model, motion=cfg.motion)
