"""Parameter estimation (eqs. 2-3): problem building, the paper's random search, other optimizers, files."""
import dataclasses

import numpy as np
import pandas as pd
import pytest

from stringcast.estimate import estimation as es
from stringcast.estimate.problem import build_problem
from stringcast.model import parameters as prm
from stringcast.core.arm import hand_pose, motion_start
from stringcast.core import PARAM_NAMES, ConfigError, model_ranges
from stringcast.core.files import DataError, read_json, read_parquet, write_json, write_parquet
from stringcast.core.joint_log import write_joint_table
from stringcast.model import hanging_equilibrium, simulate
from stringcast.plan.motion import joint_paths
from stringcast.model.parameters import first_parameters

CHI_TRUE = np.array([0.6, 0.3, 0.3, 0.4, 0.4, 0.3, 0.2, 0.2, 0.5, 0.5, 0.35, 0.3])


def make_trial(campaign, coeffs, mu, out, fps=500.0, offset=0.0013, drop=(), t0=10.0, speed=1.0):
    """A synthetic trial made by the model itself: joints.csv and tracks.parquet (frames offset from the log).

    speed scales the motion's control points (another motion of the same string)."""
    arm, rate, n = campaign.arm, campaign.arm.controller_rate, campaign.string.n_points
    q0 = np.array([1.0, -0.8, -0.5])
    cp = np.zeros((3, 6))
    cp[0, :5], cp[1, :5], cp[2, :5] = [2, 2.5, 1, -1, -0.5], [-1, 1, 2, 1, 0], [1, -1, 1, 0, 0]
    dq, _ = joint_paths(speed * cp, 0.5, rate)
    q = np.vstack([np.repeat(q0[None], int(0.3 * rate), 0), q0 + dq, np.repeat((q0 + dq[-1])[None], int(0.3 * rate), 0)])
    t = t0 + np.arange(len(q)) / rate
    write_joint_table(out / "joints.csv", t, q)
    hand = hand_pose(arm, q)
    p0 = hanging_equilibrium(coeffs, mu, hand[0], campaign.string.l0, 0.0, n)
    ft = np.arange(t[0] + offset, t[-1] + 0.05, 1 / fps)  # the video runs a little past the log
    pos, ok = simulate(coeffs, mu, t, hand, p0, campaign.string.l0, 0.0, 1e-4, ft)
    assert ok
    grasp = np.stack([np.interp(ft, t, hand[:, 0]), np.interp(ft, t, hand[:, 1])], -1)
    xy = np.concatenate([grasp[:, None], pos], 1)
    f = len(ft)
    valid = np.ones((f, n + 1), bool)
    valid[:, list(drop)] = False
    df = pd.DataFrame({"frame": np.repeat(np.arange(f), n + 1), "t_s": np.repeat(ft, n + 1),
                       "point": np.tile(np.arange(n + 1), f), "x_m": xy[..., 0].ravel(),
                       "y_m": xy[..., 1].ravel(), "valid": valid.ravel()})
    df.loc[~df["valid"], ["x_m", "y_m"]] = np.nan
    write_parquet(out / "tracks.parquet", df)
    return df, t, q, p0


@pytest.fixture
def chi_true(campaign):
    return CHI_TRUE[:len(PARAM_NAMES) + campaign.string.mass_groups().max() + 1]


def test_eq2_decode_encode(settings, campaign):
    lo, hi, (mlo, mhi) = model_ranges(settings.model)
    groups = campaign.string.mass_groups()
    d = len(PARAM_NAMES) + groups.max() + 1
    c0, m0 = prm.decode(np.zeros(d), settings.model, groups)
    c1, m1 = prm.decode(np.ones(d), settings.model, groups)
    np.testing.assert_allclose(c0, lo)
    np.testing.assert_allclose(c1, hi)
    assert np.allclose(m0, mlo) and np.allclose(m1, mhi) and m0.shape == (campaign.string.n_points,)
    chi = np.random.default_rng(0).uniform(size=d)
    c, m = prm.decode(chi, settings.model, groups)
    np.testing.assert_allclose(c, lo * (hi / lo) ** chi[:10])  # eq. (2)
    tip = campaign.string.special_points()[0] - 1
    assert m[tip] == pytest.approx(mlo * (mhi / mlo) ** chi[11])
    mu_groups = np.array([m[groups == g][0] for g in range(groups.max() + 1)])
    np.testing.assert_allclose(prm.encode(c, mu_groups, settings.model), chi, atol=1e-12)


def test_start_chi(settings, campaign, chi_true):
    c_first, _ = first_parameters(settings.model, settings.motion, campaign.string)
    chi = prm.start_chi(None, campaign.string, settings.model, settings.motion)
    assert chi[0] > 0 and np.all(chi[1:10] == 0)  # Table 2 minima, k_s lifted
    np.testing.assert_allclose(prm.decode(chi, settings.model, campaign.string.mass_groups())[0], c_first)
    assert chi[10] == pytest.approx(np.log(1.0 / 0.1) / np.log(1000))  # first_mu = 1
    first = (settings.model, settings.motion)
    np.testing.assert_allclose(prm.start_chi({"chi": chi_true.tolist()}, campaign.string, *first), chi_true)
    c, mu = prm.decode(chi_true, settings.model, np.arange(2))
    prev = {"coefficients": dict(zip(PARAM_NAMES, c)), "mu_groups": mu.tolist()}
    np.testing.assert_allclose(prm.start_chi(prev, campaign.string, *first), chi_true, atol=1e-12)
    with pytest.raises(DataError, match="mu_groups"):
        prm.start_chi({"coefficients": prev["coefficients"]}, campaign.string, *first)


def _est(settings, **kw):
    """The estimation settings with ``kw`` changed."""
    return dataclasses.replace(settings.estimation, **kw)


def _problem_settings(settings, **estimation):
    """The settings :func:`build_problem` takes, the estimation settings with ``estimation`` changed."""
    return dict(model=settings.model, evaluation=settings.evaluation, estimation=_est(settings, **estimation),
                tracking=settings.tracking)


def _stage_settings(settings, **estimation):
    """The settings :func:`run_estimation` takes, the estimation settings with ``estimation`` changed."""
    return dict(_problem_settings(settings, **estimation), motion=settings.motion)


class Recording:
    def __init__(self, f):
        self.f, self.calls = f, []

    def __call__(self, chi):
        self.calls.append(np.array(chi))
        return self.f(chi)


def _problem_stub(n=10, groups=2):
    mg = np.zeros(n, np.int64)
    mg[-1] = groups - 1
    f = 3
    return es.EstimationProblem(hand_t=np.arange(2.0), hand=np.zeros((2, 3)), p_init=np.zeros((n, 2)),
                                frame_t=np.arange(f) / 500, frames=np.arange(f), tracked=np.zeros((f, n, 2)),
                                valid=np.ones((f, n), bool), l0=0.03, psi0=0.0, dt=1e-4, mass_groups=mg, w=0.1)


def test_random_search_eq3_steps_shrink(settings):
    """Constant E keeps chi_best at the start, so every candidate lies within chi0/M beta^m of it."""
    start = np.full(12, 0.5)
    for M in (1, 4):
        estimation = _est(settings, iterations=640, batch=64, chi0=1.0, beta=0.995)
        rec = Recording(lambda c: np.ones(len(c)))
        est = es.estimate(_problem_stub(), settings.model, estimation, start, M, seed=3, objective=rec)
        cand = np.concatenate(rec.calls)
        assert cand.shape == (640, 12) and np.all((cand >= 0) & (cand <= 1))
        np.testing.assert_array_equal(cand[0], start)  # m = 0 is chi_best itself
        bound = (1.0 / M) * 0.995 ** np.arange(640)
        assert np.all(np.abs(cand - start).max(axis=1) <= bound + 1e-12)
        assert np.abs(cand[1:64] - start).max() > 0.6 * bound[63]  # the whole range is used
        assert est.n_evaluations == 640 and est.history["evaluations"][-1] == 640


def test_random_search_finds_minimum_reproducibly(settings):
    target = np.linspace(0.2, 0.8, 12)

    def f(c):
        return np.sum((c - target) ** 2, axis=1)

    estimation = _est(settings, iterations=1500, batch=50, chi0=1.0, beta=0.997)
    a = es.estimate(_problem_stub(), settings.model, estimation, np.full(12, 0.5), 1, seed=1, objective=f)
    b = es.estimate(_problem_stub(), settings.model, estimation, np.full(12, 0.5), 1, seed=1, objective=f)
    c = es.estimate(_problem_stub(), settings.model, estimation, np.full(12, 0.5), 1, seed=2, objective=f)
    assert a.E_m < 0.02 * f(np.full((1, 12), 0.5))[0]
    np.testing.assert_array_equal(a.chi, b.chi)
    assert not np.array_equal(a.chi, c.chi)
    assert np.all(np.diff(a.history["best_E_m"]) <= 0)
    assert a.top_E[0] == a.E_m and np.all(np.diff(a.top_E) >= 0) and a.top_chi.shape == (20, 12)  # estimation.top_k
    assert a.E_evaluated.shape == (1500,) and a.chi_evaluated.shape == (1500, 12)
    np.testing.assert_array_equal(np.sort(a.E_evaluated)[:20], a.top_E)


@pytest.mark.parametrize("name", ["cmaes", "de"])
def test_other_optimizers_improve(settings, name):
    target = np.linspace(0.2, 0.8, 12)

    def f(c):
        return np.sum((c - target) ** 2, axis=1)

    estimation = _est(settings, optimizer=name, iterations=2000, batch=32)
    est = es.estimate(_problem_stub(), settings.model, estimation, np.full(12, 0.5), 1, seed=0, objective=f)
    assert est.optimizer == name and est.n_evaluations <= 2000
    assert est.E_m < 0.1 * f(np.full((1, 12), 0.5))[0]


def test_cmaes_reaches_a_corner_optimum(settings):
    """Table 2's bounds often hold the optimum: CMA-ES evaluates clipped points, so it lands on them exactly."""
    corner = np.r_[np.ones(6), np.zeros(6)]
    rec = Recording(lambda c: np.sum((c - corner) ** 2, axis=1))
    est = es.estimate(_problem_stub(), settings.model, _est(settings, optimizer="cmaes", iterations=1500, batch=32),
                      np.full(12, 0.2), 1, seed=0, objective=rec)
    assert est.E_m < 1e-12 and est.n_evaluations == 1500
    cand = np.concatenate(rec.calls)
    np.testing.assert_array_equal(cand[0], np.full(12, 0.2))  # chi_best is evaluated first (M = 1: then the centre)
    assert np.all((cand >= 0) & (cand <= 1))


def test_cmaes_runs_share_the_budget(settings):
    """cmaes_runs = 2: at M = 1 both runs start at the centre; at M = 2 the first refines chi_best
    with sigma0 / 2 and the second starts at the centre again with sigma0. The runs step side by
    side (each generation both populations in one batch), each converges on its half of the budget,
    and the best of both is the estimate."""
    corner = np.r_[np.ones(6), np.zeros(6)]
    estimation = _est(settings, optimizer="cmaes", iterations=1200, batch=32, cmaes_runs=2, cmaes_first_look=0,
                      cmaes_grasp_flip=0.0)
    pop = 4 + int(3 * np.log(12))
    for M, start, n_first in ((1, np.full(12, 0.5), 1), (2, np.full(12, 0.2), 0)):
        rec = Recording(lambda c: np.sum((c - corner) ** 2, axis=1))
        est = es.estimate(_problem_stub(), settings.model, estimation, np.full(12, 0.2), M, seed=0, objective=rec)
        cand = np.concatenate(rec.calls)
        assert len(cand) == 1200 and est.E_m < 1e-6
        rounds = (1200 - n_first) // 2 // pop                       # generations of each run
        calls = [len(c) for c in rec.calls]
        assert calls[int(n_first > 0):][:rounds] == [2 * pop] * rounds   # both populations in each batch
        steps = cand[n_first:n_first + 2 * pop * rounds].reshape(rounds, 2, pop, 12)
        run1, run2 = steps[:, 0], steps[:, 1]
        E1, E2 = (np.sum((r - corner) ** 2, axis=2) for r in (run1, run2))
        assert E1.min() < 1e-6 and E2.min() < 1e-6                                 # each run converged
        assert np.abs(run1[0].mean(axis=0) - start).mean() < 0.15, M                 # run 1's start
        assert np.abs(run2[0].mean(axis=0) - 0.5).mean() < 0.15, M                   # run 2: the centre
        spread = np.abs(run1[0] - start).mean()
        assert spread < (0.3 / M) and spread > 0.3 / M / 4, (M, spread)              # step sigma0 / M
        spread2 = np.abs(run2[0] - 0.5).mean()
        assert spread2 > 0.3 / 4, (M, spread2)                                       # run 2: the full step


def test_cmaes_grasp_flip_tries_the_other_hand_spring_basin(settings):
    """E with a weak- and a stiff-hand-spring basin (k_ph's chi 0.05: E = 1; chi 0.95: E = 0.5, everything
    else the same): one run from the weak basin stays there; ``cmaes_grasp_flip`` adds evaluations for a
    last run from the best set with k_ph at the other end of its range, which finds the stiff one.
    Without the flip nothing moves the search across, and the flip leaves the runs before it as they were."""
    from stringcast.estimate.optimizers import K_PH, flipped_grasp

    weak, stiff = np.full(12, 0.3), np.full(12, 0.3)
    weak[K_PH], stiff[K_PH] = 0.05, 0.95

    def two_basins(c):
        return np.minimum(1.0 + np.sum((c - weak) ** 2, axis=1), 0.5 + np.sum((c - stiff) ** 2, axis=1))

    np.testing.assert_array_equal(flipped_grasp(weak)[K_PH], 1.0)
    np.testing.assert_array_equal(flipped_grasp(stiff)[K_PH], 0.0)
    found = {}
    for flip in (0.0, 0.3):
        estimation = _est(settings, optimizer="cmaes", iterations=1500, batch=32, cmaes_runs=1, cmaes_first_look=0,
                          cmaes_grasp_flip=flip)
        est = es.estimate(_problem_stub(), settings.model, estimation, weak, 4, seed=0, objective=two_basins)
        assert est.n_evaluations == 1500 + int(flip * 1500)                        # added, not taken
        found[flip] = est
    np.testing.assert_array_equal(found[0.3].chi_evaluated[:1500], found[0.0].chi_evaluated)
    assert found[0.0].E_m > 0.99 and abs(found[0.0].chi[K_PH] - 0.05) < 0.05     # stayed in the weak basin
    assert found[0.3].E_m < 0.51 and abs(found[0.3].chi[K_PH] - 0.95) < 0.05     # the flip found the stiff one
    # top_grasp_basins: the ensemble holds the weak basin's best sets too, but only when near-tied with the best
    assert np.all(found[0.3].top_chi[:, K_PH] >= 0.5)                           # best_k: all in the stiff basin
    for tol, weak_sets in ((1.5, 10), (0.5, 0)):                                 # weak basin's E is ~2x the best
        estimation = _est(settings, optimizer="cmaes", iterations=1500, batch=32, cmaes_runs=1, cmaes_first_look=0,
                          cmaes_grasp_flip=0.3, top_k=20, near_best_tol=tol, top_grasp_basins=True)
        est = es.estimate(_problem_stub(), settings.model, estimation, weak, 4, seed=0, objective=two_basins)
        np.testing.assert_array_equal(est.chi, found[0.3].chi)                    # the estimate itself is unchanged
        assert np.sum(est.top_chi[:, K_PH] < 0.5) == weak_sets, tol


def test_partly_blown_up_search_says_so(settings):
    def f(c):  # about 70 % of the candidates blow up, wherever they are
        return np.where((np.sum(c, axis=1) * 1e4) % 1 > 0.3, np.inf, 1.0 + c[:, 1])

    est = es.estimate(_problem_stub(), settings.model, _est(settings, iterations=300, batch=50), np.full(12, 0.5),
                      1, 0, objective=f)
    assert np.isfinite(est.E_m) and est.n_blown_up > 150 and "blew up" in est.message
    assert est.E_m == pytest.approx(1.0 + est.chi[1]) and est.E_m == np.min(est.E_evaluated)


def test_unknown_optimizer(settings):
    with pytest.raises(ConfigError, match="optimizer"):
        es.estimate(_problem_stub(), settings.model, _est(settings, optimizer="magic"), np.full(12, 0.5), 1, 0,
                    objective=lambda c: np.ones(len(c)))


def test_all_candidates_blown_up_does_not_crash(settings):
    estimation = _est(settings, iterations=100, batch=30)
    est = es.estimate(_problem_stub(), settings.model, estimation, np.full(12, 0.5), 1, 0,
                      objective=lambda c: np.full(len(c), np.inf))
    assert est.E_m == np.inf and est.n_blown_up == 100 and "blew up" in est.message
    assert est.coeffs.shape == (10,)


def test_build_problem(settings, campaign, chi_true, tmp_path):
    c, mu = prm.decode(chi_true, settings.model, campaign.string.mass_groups())
    df, t, q, p0 = make_trial(campaign, c, mu, tmp_path, drop=(4,))
    prob = build_problem(df, t, q, campaign, **_problem_settings(settings))
    n_rest = settings.tracking.rest_frames
    t_move = motion_start(t, q)
    ft = np.unique(df["t_s"])
    before = ft[(ft < t_move) & (ft >= t[0])]
    assert prob.frame_t[0] == pytest.approx(before[-n_rest])
    assert prob.frame_t[-1] <= t[-1] and prob.frame_t[-1] > t[-1] - 0.003
    assert prob.hand_t[0] == prob.frame_t[0] and np.all(np.diff(prob.hand_t) > 0)
    np.testing.assert_allclose(prob.hand[0], hand_pose(campaign.arm, q[0]), atol=1e-12)  # at rest
    np.testing.assert_allclose(np.delete(prob.p_init, 3, axis=0), np.delete(p0, 3, axis=0), atol=5e-5)  # settled to 1e-4 m/s
    assert prob.fallback_points == (4,)
    np.testing.assert_allclose(prob.p_init[3], p0[3], atol=2e-4)   # filled between points 3 and 5
    assert not prob.valid[:, 3].any() and prob.valid[:, 0].all()
    late = df[df["t_s"] > t[0] + 0.02]
    with pytest.raises(DataError, match="before the motion starts"):
        build_problem(late[late["t_s"] < t[0] + 0.02 + 0.003], t, q, campaign,
                         **_problem_settings(settings))
    with pytest.raises(DataError, match="missing columns"):
        build_problem(df.drop(columns="valid"), t, q, campaign, **_problem_settings(settings))


def test_compare_after_motion_cuts_the_window(settings, campaign, chi_true, tmp_path):
    """estimation.compare_after_motion_s: frames compared up to that long after the arm stops
    (the log holds the end posture 0.3 s), the start unchanged; null keeps the whole log."""
    c, mu = prm.decode(chi_true, settings.model, campaign.string.mass_groups())
    df, t, q, _ = make_trial(campaign, c, mu, tmp_path)
    whole = build_problem(df, t, q, campaign, **_problem_settings(settings))
    cut = build_problem(df, t, q, campaign, **_problem_settings(settings, compare_after_motion_s=0.1))
    t_stop = t[0] + 0.3 + 0.5          # make_trial: 0.3 s at rest, a 0.5 s motion, 0.3 s still
    assert cut.frame_t[0] == whole.frame_t[0]
    assert t_stop + 0.1 - 0.01 < cut.frame_t[-1] <= t_stop + 0.1 + 0.01
    assert whole.frame_t[-1] > t_stop + 0.25
    np.testing.assert_array_equal(cut.tracked, whole.tracked[:len(cut.frame_t)])
    none = _problem_settings(settings, compare_after_motion_s=None)
    assert len(build_problem(df, t, q, campaign, **none).frame_t) == len(whole.frame_t)


def test_hidden_rest_points_start_the_model_at_rest(settings, campaign, chi_true, tmp_path):
    """Points 1-3 never tracked (a gripper hides them): the filled rest state keeps the hidden segments
    at (at least) l0, so the model starts at rest and, while the arm is still, stays near the true pose."""
    c, mu = prm.decode(chi_true, settings.model, campaign.string.mass_groups())
    df, t, q, p0 = make_trial(campaign, c, mu, tmp_path, drop=(1, 2, 3))
    prob = build_problem(df, t, q, campaign, **_problem_settings(settings))
    assert prob.fallback_points == (1, 2, 3)
    seg = np.linalg.norm(np.diff(np.vstack([prob.hand[0, :2], prob.p_init]), axis=0), axis=1)
    # this chain hangs stretched by its load (chord > 4 l0): the gap is spaced evenly on the line
    np.testing.assert_allclose(seg[:4], seg[0], rtol=1e-9)
    assert seg[0] >= campaign.string.l0
    sim, ok = es.simulate_fit(prob, settings.model, chi_true)
    still = prob.frame_t < motion_start(t, q)
    assert ok and still.sum() > 10
    drift = np.linalg.norm(sim[still] - p0[None], axis=2).max()
    assert drift < 2e-3, f"the model moved {drift * 1000:.2f} mm while the arm was still"


def test_run_estimation_end_to_end(settings, campaign, chi_true, tmp_path):
    c, mu = prm.decode(chi_true, settings.model, campaign.string.mass_groups())
    make_trial(campaign, c, mu, tmp_path)
    # started from the truth (candidate 0), E is the model's own sampling error: the timing chain is right
    write_json(tmp_path / "prev.json", {"chi": chi_true})
    est = es.run_estimation(tmp_path / "tracks.parquet", tmp_path / "joints.csv", campaign,
                            tmp_path / "prev.json", 3, tmp_path / "params.json", tmp_path / "fit.parquet",
                            **_stage_settings(settings, iterations=64, batch=32))
    assert est.E_m < 1e-4 and est.seed == settings.estimation.seed + 3
    doc = read_json(tmp_path / "params.json")
    assert doc["M"] == 3 and doc["evaluations"] == 64 and doc["optimizer"] == "random_search"
    assert set(doc["coefficients"]) == set(PARAM_NAMES) and len(doc["mu"]) == campaign.string.n_points
    assert doc["special_points"] == campaign.string.special_points()
    assert len(doc["top"]) == 20 and doc["top"][0]["chi"] == pytest.approx(doc["chi"])  # the ensemble, best first
    assert np.all(np.diff([m["E_mm"] for m in doc["top"]]) >= 0)
    diag = doc["diagnostics"]
    assert [p["name"] for p in diag["parameters"]] == doc["chi_names"]
    assert set(diag["pinned"]) | set(diag["loose"]) == set(doc["chi_names"])
    w, n = settings.evaluation.w, campaign.string.n_points
    e_i = np.array(doc["E_i_mm"])
    assert doc["E_mm"] == pytest.approx(np.sum(e_i * (1 + w * np.arange(n))) / n, rel=1e-6)
    fit = read_parquet(tmp_path / "fit.parquet")
    assert list(fit.columns) == ["frame", "t_s", "point", "x_tracked_m", "y_tracked_m", "valid", "x_sim_m", "y_sim_m"]
    assert set(fit["point"]) == set(range(1, n + 1))
    sim = fit.dropna(subset=["x_sim_m"])
    assert fit["t_s"].min() < doc["t_sim_start_s"] == pytest.approx(sim["t_s"].min())
    err = np.hypot(sim["x_sim_m"] - sim["x_tracked_m"], sim["y_sim_m"] - sim["y_tracked_m"])
    assert err.groupby(sim["point"]).mean().to_numpy() == pytest.approx(e_i / 1000, abs=1e-9)

    # from the first plan's set (trial 1) the search improves on its start
    est1 = es.run_estimation(tmp_path / "tracks.parquet", tmp_path / "joints.csv", campaign, None, 1,
                             tmp_path / "p1.json", tmp_path / "f1.parquet",
                             **_stage_settings(settings, iterations=192, batch=64))
    assert est1.history["best_E_m"][-1] < 0.5 * est1.history["best_E_m"][0]
    assert read_json(tmp_path / "p1.json")["chi_start"] == pytest.approx(
        prm.start_chi(None, campaign.string, settings.model, settings.motion).tolist())


def test_cmaes_options_reach_cma_and_unknown_ones_are_refused(settings, monkeypatch):
    """estimation.cmaes_options goes to every cma.CMAEvolutionStrategy the search builds, over our
    defaults; a name cma does not know is a ConfigError that names it."""
    import cma

    seen = []
    real = cma.CMAEvolutionStrategy

    def spy(x0, sigma0, opts):
        seen.append(dict(opts))
        return real(x0, sigma0, opts)

    monkeypatch.setattr(cma, "CMAEvolutionStrategy", spy)
    corner = np.r_[np.ones(6), np.zeros(6)]
    estimation = _est(settings, optimizer="cmaes", iterations=600, batch=32, cmaes_runs=2, cmaes_grasp_flip=0.0,
                      cmaes_options={"CSA_dampfac": 0.5, "tolx": 1e-3})
    est = es.estimate(_problem_stub(), settings.model, estimation, np.full(12, 0.2), 1, seed=0,
                      objective=lambda c: np.sum((c - corner) ** 2, axis=1))
    assert len(seen) >= 2 and all(o["CSA_dampfac"] == 0.5 and o["tolx"] == 1e-3 for o in seen)
    assert est.E_m < 1e-3
    with pytest.raises(ConfigError, match="CSA_dampfak"):
        es.estimate(_problem_stub(), settings.model,
                    _est(settings, optimizer="cmaes", cmaes_options={"CSA_dampfak": 0.3}),
                    np.full(12, 0.2), 1, seed=0, objective=lambda c: np.zeros(len(c)))


def test_cmaes_first_look_samples_eq3_and_starts_at_its_best(settings):
    """cmaes_first_look = L: the first L candidates are eq. (3) at m = 0 around chi_best (the first is
    chi_best itself, the rest chi_best + chi0 / M RAND(-1, 1) clipped: many on the box's faces), and
    CMA-ES's first generation is centred on the best of them."""
    corner = np.r_[np.ones(6), np.zeros(6)]
    L, pop = 96, 4 + int(3 * np.log(12))
    estimation = _est(settings, optimizer="cmaes", iterations=L + 40 * pop, batch=32, cmaes_first_look=L)
    rec = Recording(lambda c: np.sum((c - corner) ** 2, axis=1))
    start = np.full(12, 0.2)
    es.estimate(_problem_stub(), settings.model, estimation, start, 1, seed=0, objective=rec)
    cand = np.concatenate(rec.calls)
    look = cand[:L]
    assert np.array_equal(look[0], start)
    assert np.all(np.abs(look[1:] - start) <= 1.0 + 1e-12)
    assert 0.5 < np.mean(look[1:] == 0.0) / 0.4 < 1.5          # P(step < -0.2) = 0.4: clipped onto the face
    best = look[np.argmin(np.sum((look - corner) ** 2, axis=1))]
    assert np.abs(cand[L:L + pop].mean(axis=0) - best).mean() < 0.15   # CMA-ES starts at the look's best
    assert np.sum((cand - corner) ** 2, axis=1).min() < 1e-3
