"""``motion.newton_steps``: the least change of the played motion that aims the residual-corrected tip at
the target's centre (:mod:`stringcast.plan.newton`), on the real model."""
import numpy as np
import pytest

from stringcast.model import simulate
from stringcast.plan import planning as pn
from stringcast.plan.newton import _clip_box, newton_perturbation
from stringcast.plan.prediction import Predictor

import test_planning
from test_planning import _first, _with

small = test_planning.small        # the fixture: its small search budget, declared once
MISS = 0.025    # m: the "lab's" tip, seen this far from the model's on the played motion, across its path


def _played_and_observed(campaign, cfg):
    """A first plan that hits under the model, and its "tracked" tip: the model's, moved by MISS across the
    model tip's path at its closest approach (so the played motion missed by about MISS): the observed tuple
    of :func:`stringcast.plan.residual.observed_tip`."""
    coeffs, mu = _first(cfg, campaign.string)
    first = pn.search(campaign, cfg.model, cfg.motion, coeffs, mu, np.random.default_rng(5))
    assert first.hit
    pl = Predictor(campaign, cfg.model, cfg.motion, coeffs, mu)
    m, p0 = first.motion, pl.equilibrium(first.motion.q0)
    hand_t, hand = pl.hand_trajectory(m.q)
    ft = np.arange(0.0, m.T + pl.flight, 0.002)
    pos, _ = simulate(coeffs, mu, hand_t, hand, p0, pl.l0, pl.psi0, pl.dt, np.concatenate([[0.0], ft]))
    tip = pos[1:, -1]
    i = int(np.argmin(np.abs(ft - first.t_min)))
    v = tip[i + 1] - tip[i - 1]
    across = np.array([-v[1], v[0]]) / np.hypot(*v)
    across *= np.sign(across @ (tip[i] - campaign.target.xy)) or 1.0        # away from the target
    return first, coeffs, mu, (ft, tip + MISS * across, np.ones(len(ft), bool), 0.3)


def test_clip_box_scales_a_change_back_along_itself():
    change = np.array([0.2, -0.8, 0.4])
    out = _clip_box(change, 0.5)
    assert np.max(np.abs(out)) == pytest.approx(0.5) and np.allclose(out * 1.6, change)
    assert _clip_box(change, 1.0) is change


def test_newton_steps_bring_the_corrected_tip_to_the_target_with_a_small_change(campaign, small):
    """The played motion misses by about MISS once corrected; a few Newton steps move its control points
    by far less than the +-0.5 rad/s box and bring the corrected tip well inside the target. The
    box holds every change; without a residual correction there is nothing to aim at."""
    first, coeffs, mu, observed = _played_and_observed(campaign, small)
    pl = Predictor(campaign, small.model, small.motion, coeffs, mu)
    p0 = pl.equilibrium(first.motion.q0)
    assert newton_perturbation(pl, first.motion, p0, 8, 0.5, np.random.default_rng(0)) == []    # no residual
    assert pl.set_residual(first.motion, observed, p0[None], coeffs[None], mu[None]) == ""
    d_played = pl.evaluate(first.motion.q[None], first.motion.T, p0[None])[0][0]
    assert d_played > 0.01                                        # the correction moved the played tip off
    (cp, q0, q, i), = newton_perturbation(pl, first.motion, p0, 8, 0.5, np.random.default_rng(0))
    change = np.abs(cp - first.motion.control_points)
    assert i == 0 and np.array_equal(q0, first.motion.q0) and np.all(change[:, -1] == 0)    # V_N kept
    assert 0 < change.max() < 0.25
    d, _, _, ok = pl.evaluate(q[None], first.motion.T, p0[None])
    assert ok[0] and d[0] < min(0.25 * d_played, campaign.target.radius / 2)
    boxed = newton_perturbation(pl, first.motion, p0, 8, 0.01, np.random.default_rng(0))
    assert np.abs(boxed[0][0] - first.motion.control_points).max() <= 0.01 + 1e-12


def test_the_search_plays_the_newton_change_only_when_asked(campaign, small):
    """With ``motion.newton_steps`` the plan is the least change (its note says so), predicted to hit;
    without it, the random perturbation of Section V.B, drawn over the whole box."""
    first, coeffs, mu, observed = _played_and_observed(campaign, small)
    cfg = _with(small, max_candidates=256, extra_after_hit=32)
    off = pn.search(campaign, cfg.model, cfg.motion, coeffs, mu, np.random.default_rng(1), previous=first.motion,
                    observed=observed)
    cfg = _with(cfg, newton_steps=8)
    on = pn.search(campaign, cfg.model, cfg.motion, coeffs, mu, np.random.default_rng(1), previous=first.motion,
                   observed=observed)
    assert "newton_steps" in on.message and "newton_steps" not in off.message
    assert on.hit and on.residual is not None
    change = [np.abs(r.motion.control_points - first.motion.control_points).max() for r in (on, off)]
    assert change[0] < 0.25 < change[1]
