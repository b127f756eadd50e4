"""Estimation diagnostics: best K, near-best sets, per-parameter spread and the pinned/loose flag."""
import dataclasses

import numpy as np
import pytest

from stringcast.estimate import diagnostics as dg
from stringcast.estimate import estimation as es
from stringcast.core import PARAM_NAMES
from tests.estimate.test_estimation import _problem_stub

NAMES = list(PARAM_NAMES) + ["mu_others", "mu_10"]


def test_parameter_spread_and_flags():
    chi = np.array([[0.5, 0.1], [0.55, 0.9], [0.45, 0.5]])
    lo, hi = np.array([3.0, -4.0]), np.array([6.0, 0.0])
    out = dg.parameter_spread(chi, lo, hi, ["k_s", "k_sh"], pinned_spread=0.2)
    assert [p["status"] for p in out] == ["pinned", "loose"]
    assert out[0]["spread"] == pytest.approx(0.1) and out[1]["spread"] == pytest.approx(0.8)
    assert out[0]["best"] == pytest.approx(10 ** 4.5) and out[1]["log10_best"] == pytest.approx(-3.6)
    assert out[1]["log10_min"] == pytest.approx(-3.6) and out[1]["log10_max"] == pytest.approx(-0.4)
    assert out[0]["table_decades"] == 3.0
    with pytest.raises(ValueError, match="parameter_spread"):
        dg.parameter_spread(chi, lo, hi, ["k_s"], 0.2)


def test_near_best_takes_the_tolerance_or_the_best_k():
    E = np.array([1.0, 1.04, 2.0, 1.01, 3.0, 1.2])
    chi = np.arange(6.0)[:, None]
    c, e = dg.near_best(chi, E, k=2, tol=0.05)
    np.testing.assert_array_equal(c[:, 0], [0, 3, 1]) and np.testing.assert_array_equal(e, [1.0, 1.01, 1.04])
    c, e = dg.near_best(chi, E, k=4, tol=0.0)
    assert len(e) == 4 and e[-1] == 1.2  # fewer within the tolerance than k: the best k
    c, e = dg.near_best(chi, np.full(6, np.inf), k=3, tol=0.05)
    assert len(e) == 3 and np.all(np.isinf(e))


def test_best_k_two_basins_holds_the_other_basin_only_when_near_tied():
    """Column 0 splits at 0.5: the best set (E 1.0) is in the low basin; the high basin's best has E 1.03.
    Within the tolerance, half of k from each basin, sorted by E, the best first; beyond it, best_k."""
    chi = np.array([[0.1], [0.2], [0.3], [0.4], [0.45], [0.6], [0.7], [0.8]])
    E = np.array([1.0, 1.01, 1.02, 1.025, 1.05, 1.03, 1.04, 1.5])
    c, e = dg.best_k_two_basins(chi, E, k=4, index=0, tol=0.05)
    np.testing.assert_array_equal(e, [1.0, 1.01, 1.03, 1.04])
    np.testing.assert_array_equal(c[:, 0], [0.1, 0.2, 0.6, 0.7])
    for tol in (0.02, 0.0):                   # the other basin is 3 % worse: not a tie
        c, e = dg.best_k_two_basins(chi, E, k=4, index=0, tol=tol)
        np.testing.assert_array_equal(e, dg.best_k(chi, E, 4)[1])
    c, e = dg.best_k_two_basins(chi, E, k=5, index=0, tol=0.05)   # odd k: the extra set from the best's basin
    np.testing.assert_array_equal(c[:, 0], [0.1, 0.2, 0.3, 0.6, 0.7])
    c, e = dg.best_k_two_basins(chi[:5], E[:5], k=4, index=0, tol=1.0)   # one basin only: best_k
    np.testing.assert_array_equal(e, [1.0, 1.01, 1.02, 1.025])


def test_search_tells_excited_from_unexcited_parameters(settings):
    """E depends on chi[0] and chi[4] only: those are pinned, every other parameter is loose."""
    def f(c):
        return 0.005 + 0.05 * (c[:, 0] - 0.3) ** 2 + 0.05 * (c[:, 4] - 0.7) ** 2

    estimation = dataclasses.replace(settings.estimation, iterations=1500, batch=50, top_k=20, near_best_tol=0.05,
                                     pinned_spread=0.2)
    est = es.estimate(_problem_stub(), settings.model, estimation, np.full(12, 0.5), 1, seed=1, objective=f)
    lo, hi = np.full(12, -3.0), np.full(12, 3.0)
    d = dg.diagnostics(est.chi_evaluated, est.E_evaluated, lo, hi, NAMES, estimation)
    assert d["pinned"] == [NAMES[0], NAMES[4]]
    assert set(d["loose"]) == set(NAMES) - {NAMES[0], NAMES[4]}
    assert d["near_best"]["count"] >= 20 and d["near_best"]["E_mm_max"] <= 1.05 * est.E_m * 1000 + 1e-9
    assert d["parameters"][0]["log10_best"] == pytest.approx(-3 + 6 * 0.3, abs=0.1)
    assert d["blown_up_share"] == 0.0


def test_diagnostics_when_everything_blew_up(settings):
    estimation = dataclasses.replace(settings.estimation, iterations=60, batch=30)
    est = es.estimate(_problem_stub(), settings.model, estimation, np.full(12, 0.5), 1, 0,
                      objective=lambda c: np.full(len(c), np.inf))
    d = dg.diagnostics(est.chi_evaluated, est.E_evaluated, np.zeros(12), np.ones(12), NAMES, estimation)
    assert d["blown_up_share"] == 1.0 and d["near_best"]["count"] == 20 and len(d["parameters"]) == 12


def test_bad_settings(settings):
    estimation = dataclasses.replace(settings.estimation, pinned_spread=0.0)
    with pytest.raises(ValueError, match="pinned_spread"):
        dg.checked(estimation)
