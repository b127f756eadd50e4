"""benchmarks/intrinsics_bias: the emulated misleading calibration and the outcome rule."""
import numpy as np
import pytest

from benchmarks.generalization import biased_intrinsics
from benchmarks.intrinsics_bias import outcome


def test_biased_intrinsics_moves_what_the_calibration_stage_judges(monkeypatch):
    """Inside the block the stage's judged_intrinsics returns fx, fy scaled and cx shifted by a share
    of the width, everything else as judged; outside it, the stage's own function again."""
    import stringcast.calibrate.calibration as stage
    from stringcast.calibrate.charuco import Intrinsics
    from stringcast.core import Verdict

    K = np.array([[1000.0, 0, 511.5], [0, 1000.0, 383.5], [0, 0, 1]])
    intr = Intrinsics(K=K, dist=np.zeros(5), rms_px=0.3, n_views=12, image_size=(1024, 768))
    monkeypatch.setattr(stage, "judged_intrinsics", lambda views, flags, st: (intr, {"q": 1}, Verdict()))
    plain = stage.judged_intrinsics
    with biased_intrinsics(0.025, 0.02):
        got, quality, verdict = stage.judged_intrinsics(None, 0, None)
    assert stage.judged_intrinsics is plain
    np.testing.assert_allclose(got.K, [[1025.0, 0, 511.5 + 20.48], [0, 1025.0, 383.5], [0, 0, 1]])
    assert got.rms_px == 0.3 and quality == {"q": 1} and verdict.ok
    np.testing.assert_array_equal(intr.K, K)                     # the judged one is left as it was
    with biased_intrinsics(0.0, 0.0):
        assert stage.judged_intrinsics(None, 0, None)[0] is intr


@pytest.mark.parametrize("row,want", [
    ({"tracking_median_mm": 0.4, "tracking_p95_mm": 1.9, "sync_error_ms": -0.3, "calibration_verdict": "warn"}, "within"),
    ({"tracking_median_mm": 0.4, "tracking_p95_mm": 3.4, "sync_error_ms": 0.1, "calibration_verdict": "warn"}, "warned"),
    ({"tracking_median_mm": 0.4, "tracking_p95_mm": 1.0, "sync_error_ms": 0.7, "sync_verdict": "warn"}, "warned"),
    ({"tracking_median_mm": 1.3, "tracking_p95_mm": 2.0, "sync_error_ms": 0.1, "tracking_verdict": "warn"}, "other"),
    ({"tracking_median_mm": 0.4, "tracking_p95_mm": 6.0, "sync_error_ms": 0.1}, "silent"),
    ({"error": "DataError: no board"}, "warned"),
])
def test_outcome(row, want):
    assert outcome(row) == want


def test_a_setups_string_follows_its_seed_and_a_film_of_another_string_is_not_reused(tmp_path):
    """The string type cycles with the seed, not with a setup's place in the run (seeds 3 and 4 run on
    their own were once filmed with types 1 and 2); a finished film is reused only for its own type."""
    import json

    from benchmarks.generalization import _filmed, string_type

    assert [string_type(s) for s in (0, 3, 4, 6, 7, 10)] == [1, 4, 5, 7, 1, 4]
    trial = tmp_path / "setup_3" / "trial_1"
    trial.mkdir(parents=True)
    assert not _filmed(trial, 4)                                  # stopped while filming: no ground truth
    (trial / "ground_truth.json").write_text("{}")
    assert _filmed(trial, 4)                                      # filmed before the marker existed
    (tmp_path / "setup_3" / "film.json").write_text(json.dumps({"seed": 3, "string_type": 1}))
    assert not _filmed(trial, 4) and _filmed(trial, 1)
