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
    """Silent: ok with a true p95 past the silent bound. A false alarm: a reason that the points may be off
    (not the valid share's, a count of points not tracked) with a true p95 within the goal."""
    lost = "tracking: only 60% of the string's points were tracked"
    rows = [{"campaign": "a", "trial": "trial_1", "verdict": "ok", "reasons": [], "true_p95_mm": SILENT_P95_MM + 1},
            {"campaign": "a", "trial": "trial_2", "verdict": "warn", "reasons": ["tracking: the string's length"],
             "true_p95_mm": SILENT_P95_MM + 1},
            {"campaign": "b", "trial": "trial_1", "verdict": "warn", "reasons": [lost, "tracking: jitter"],
             "true_p95_mm": GOAL_P95_MM - 1},
            {"campaign": "b", "trial": "trial_2", "verdict": "warn", "reasons": [lost], "true_p95_mm": GOAL_P95_MM - 1},
            {"campaign": "b", "trial": "trial_3", "verdict": "ok", "reasons": [], "true_p95_mm": GOAL_P95_MM + 0.5}]
    doc = summarise(rows)
    assert doc["trials"] == 5 and doc["warn"] == 3 and doc["beyond_goal"] == 3
    assert doc["silent"] == ["a/trial_1"] and doc["false_alarms"] == ["b/trial_1"]


def test_the_valid_share_reason_is_the_one_the_benchmark_sets_apart():
    """claims_error tells the valid share's reason from the others by how it begins: the verdict's own."""
    from benchmarks.tracking_verdicts import VALID_SHARE_REASON, claims_error
    from stringcast.core import TrackingSettings
    from stringcast.track.quality import tracking_verdict

    doc = {"valid_share": 0.5, "judged_frames": 40, "off_image_share": 0.0, "segment_excess_p95_mm": 9.0,
           "rest_jitter_p95_mm": None, "past_roi_share": 0.0, "lost_points": None,
           "length_mismatch_mm": {"frames": 0, "median": None, "placed_frames": 0, "spread_p95": None,
                                  "longer_p95": None, "shorter_p95": None}}
    reasons = tracking_verdict(doc, TrackingSettings()).reasons
    assert len(reasons) == 2 and reasons[0].startswith(VALID_SHARE_REASON)
    assert not reasons[1].startswith(VALID_SHARE_REASON)
    assert claims_error({"reasons": list(reasons)}) and not claims_error({"reasons": [reasons[0]]})


def test_a_folder_without_the_campaigns_resolved_file_is_named(tmp_path):
    from benchmarks.tracking_verdicts import campaign_of

    (tmp_path / "config").mkdir()
    (tmp_path / "config" / "config.yaml").write_text("{}")
    with pytest.raises(FileNotFoundError, match="campaign-.*yaml"):
        campaign_of(tmp_path)
