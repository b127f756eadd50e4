"""The tracking-verdict benchmark's figures against the lab's truth (benchmarks/tracking_verdicts.py):
true point errors, the true string's stretch, and silent trials and false alarms."""
import numpy as np
import pandas as pd
import pytest

from benchmarks.tracking_verdicts import GOAL_P95_MM, SILENT_P95_MM, summarise, true_figures


def _table(xy: np.ndarray, valid: np.ndarray | None = None) -> pd.DataFrame:
    F, P = xy.shape[:2]
    out = pd.DataFrame({"frame": np.repeat(np.arange(F), P), "point": np.tile(np.arange(P), F),
                        "x_m": xy[..., 0].ravel(), "y_m": xy[..., 1].ravel()})
    if valid is not None:
        out["valid"] = valid.ravel()
    return out


def test_true_figures_measure_the_valid_points_and_the_true_stretch():
    F, n, L = 20, 10, 0.3
    s = np.arange(n + 1) * L / n
    truth = np.zeros((F, n + 1, 2))
    truth[..., 1] = -s * (1 + np.linspace(0, 0.1, F))[:, None]        # stretched up to 10 %: 30 mm
    tracked = truth.copy()
    tracked[:, 1:, 0] += 0.002                                          # every point 2 mm off
    valid = np.ones((F, n + 1), bool)
    valid[:, 5] = False
    tracked[:, 5] = 1.0                                                  # an invalid point far off: not counted
    fig = true_figures(_table(tracked, valid), _table(truth), L)
    assert fig["true_median_mm"] == pytest.approx(2.0) and fig["true_p99_mm"] == pytest.approx(2.0)
    assert fig["true_stretch_p95_mm"] == pytest.approx(30 * np.percentile(np.linspace(0, 1, F), 95), rel=1e-6)


def test_silent_trials_and_false_alarms_are_named():
    rows = [{"campaign": "a", "trial": "trial_1", "verdict": "ok", "true_p95_mm": SILENT_P95_MM + 1},
            {"campaign": "a", "trial": "trial_2", "verdict": "warn", "true_p95_mm": SILENT_P95_MM + 1},
            {"campaign": "b", "trial": "trial_1", "verdict": "warn", "true_p95_mm": GOAL_P95_MM - 1},
            {"campaign": "b", "trial": "trial_2", "verdict": "ok", "true_p95_mm": GOAL_P95_MM + 0.5}]
    doc = summarise(rows)
    assert doc["trials"] == 4 and doc["warn"] == 2 and doc["beyond_goal"] == 3
    assert doc["silent"] == ["a/trial_1"] and doc["false_alarms"] == ["b/trial_1"]
