"""``motion.taut_chord_share``: first and new plans prefer a hit on a taut model string (docs/method.md,
"Where the executions go, and a taut string at the hit"); ``motion.slack_warn_chord_share``: they warn of
a slack one ("A slack string at the predicted hit")."""
import numpy as np
import pytest

from stringcast.model import hanging_equilibrium
from stringcast.plan import planning as pn
from stringcast.plan.prediction import Predictor

import test_planning
from test_planning import _fake_model, _first, _with

small = test_planning.small        # the fixture: its small search budget, declared once


def test_the_chord_share_is_the_tips_distance_from_the_grasp_over_the_length(campaign, settings):
    """At rest at t = 0 a hanging string is straight (stretched a little by its weight): share ~1; a string
    folded back at its middle has its tip beside the grasp, at the fold's chord."""
    model, motion = settings.model, settings.motion
    coeffs, mu = _first(settings, campaign.string)
    pl = Predictor(campaign, model, motion, coeffs, mu)
    q = np.repeat(np.array([[0.3, -1.5, -0.4]]), 50, axis=0)[None]              # (1, K, J): the arm still
    hp = pl.hand_trajectory(q)[1][0, 0]
    rest = hanging_equilibrium(coeffs, mu, hp, pl.l0, pl.psi0, pl.n, pl.dt)
    share = pl.chord_share(q, rest[None], np.array([0.0]))
    assert 1.0 <= share[0] < 1.05
    n, l0 = pl.n, pl.l0
    down = np.arange(1, n // 2 + 1) * l0                                        # down to the fold, then back up
    s = np.concatenate([down, down[-1] - np.arange(1, n - n // 2 + 1) * l0])
    folded = np.column_stack([hp[0] + 0.01 * (np.arange(n) >= n // 2), hp[1] - s])
    share = pl.chord_share(np.repeat(q, 2, axis=0), np.stack([folded, folded]), np.array([0.0, 0.3]))
    assert share[0] == pytest.approx(np.linalg.norm(folded[-1] - hp[:2]) / (n * l0))
    assert share[0] < 0.2 < share[1]                 # released, the folded half falls: each at its own time
    assert np.isnan(pl.chord_share(q, rest[None], np.array([np.nan]))[0])   # a blown-up candidate's t_min


def _fake_chords(monkeypatch, d_best: dict, chords: dict, state: dict, radius: float):
    """Fake chord_share: candidate i (by its trajectory, :func:`_fake_model`'s state["id_of"]) at chords[i]
    (1 if absent); only hits (d_best <= radius) are asked."""
    def fake(self, q, p_init, t):
        ids = [state["id_of"][qi.tobytes()] for qi in q]
        assert all(d_best.get(i, 1.0) <= radius for i in ids)
        return np.array([chords.get(i, 1.0) for i in ids])

    monkeypatch.setattr(Predictor, "chord_share", fake)


def test_a_taut_hit_is_chosen_over_a_nearer_slack_one(monkeypatch, campaign, small):
    """Candidate 5 hits 1 mm from the centre on a string folded to 0.6 of its length, 130 hits 15 mm off on
    a taut one: off, 5 (the paper's nearest hit); at 0.95, 130, and the count of extra candidates starts
    there; with no taut hit at all, the nearest slack one after every candidate. A slack hit chosen is
    warned of (``motion.slack_warn_chord_share``, 0.9), whether the option is on or off, unless the
    warning is off."""
    d_best, chords = {5: 0.001, 130: 0.015}, {5: 0.6, 130: 1.0}
    state = _fake_model(monkeypatch, d_best, {})
    _fake_chords(monkeypatch, d_best, chords, state, campaign.target.radius)
    cfg = _with(small, max_candidates=400, extra_after_hit=20, batch=50)
    coeffs, mu = _first(cfg, campaign.string)
    res = pn.search(campaign, cfg.model, cfg.motion, coeffs, mu, np.random.default_rng(0))
    assert res.d_min == pytest.approx(0.001) and res.candidates == 100 and res.chord_share == 0.6
    assert res.slack and "slack at the predicted hit (its tip 0.60" in res.message
    cfg = _with(cfg, taut_chord_share=0.95)
    state["k"] = 0
    res = pn.search(campaign, cfg.model, cfg.motion, coeffs, mu, np.random.default_rng(0))
    assert res.d_min == pytest.approx(0.015) and res.candidates == 200 and res.chord_share == 1.0
    assert not res.slack and "slack" not in res.message
    chords[130] = 0.5
    state["k"] = 0
    res = pn.search(campaign, cfg.model, cfg.motion, coeffs, mu, np.random.default_rng(0))
    assert res.d_min == pytest.approx(0.001) and res.candidates == 400 and res.chord_share == 0.6
    assert res.hit and res.slack
    state["k"] = 0
    res = pn.search(campaign, cfg.model, _with(cfg, slack_warn_chord_share=0.0).motion, coeffs, mu,
                    np.random.default_rng(0))
    assert res.chord_share == 0.6 and not res.slack and "slack" not in res.message      # warning off


def test_a_perturbation_is_not_judged_by_its_chord(monkeypatch, campaign, small):
    """Later plans that perturb the played motion rest on a model checked there: no chord is computed,
    and no slack is warned of."""
    cfg = _with(small, max_candidates=64, extra_after_hit=0, batch=32, taut_chord_share=0.95)
    coeffs, mu = _first(cfg, campaign.string)
    first = pn.search(campaign, cfg.model, _with(small, max_candidates=64).motion, coeffs, mu, np.random.default_rng(0))
    monkeypatch.setattr(Predictor, "chord_share", lambda *a: pytest.fail("chord_share called for a perturbation"))
    res = pn.search(campaign, cfg.model, cfg.motion, coeffs, mu, np.random.default_rng(1), previous=first.motion)
    assert res.chord_share is None and not res.slack
