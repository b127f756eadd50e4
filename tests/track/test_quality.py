"""The tracking's verdict: a clean track is ok; lost points, points misplaced along the string and
jitter at rest each warn and name their cause; the seen length against L is reported."""
import numpy as np
import pandas as pd
import pytest

from stringcast.core import TrackingSettings
from stringcast.track.quality import frames_judged, tracking_quality

ST = TrackingSettings()
L, N, F = 0.3, 10, 60


def _swing(rng=None, jitter_m=0.0):
    """A straight string of length L swinging about its grasp at (0, 0): (F, N + 1, 2) m, the
    first 20 frames at rest (hanging straight down)."""
    ang = np.r_[np.zeros(20), np.linspace(0, 1.2, F - 20)]
    s = np.arange(N + 1) * L / N
    xy = np.stack([np.outer(np.sin(ang), s), -np.outer(np.cos(ang), s)], axis=-1)
    if rng is not None:
        xy[:, 1:] += rng.normal(0, jitter_m, xy[:, 1:].shape)
    return xy


def _table(xy, valid=None):
    valid = np.ones(xy.shape[:2], bool) if valid is None else valid
    xy = np.where(valid[..., None], xy, np.nan)
    return pd.DataFrame({"frame": np.repeat(np.arange(F), N + 1), "point": np.tile(np.arange(N + 1), F),
                         "x_m": xy[..., 0].ravel(), "y_m": xy[..., 1].ravel(), "valid": valid.ravel()})


def _judge(xy, valid=None, mismatch=None):
    t = np.arange(F) / 100.0
    moving, rest = frames_judged(t, np.ones(F, bool), 0.2 + 0.021, 0.59, settle_s=0.0)
    D = np.full(F, 0.0005) if mismatch is None else mismatch
    return tracking_quality(_table(xy, valid), D, L, N, moving, rest, ST)


def test_a_clean_track_is_ok():
    doc = _judge(_swing())
    assert doc["verdict"]["status"] == "ok", doc["verdict"]
    assert doc["valid_share"] == 1.0 and doc["length_mismatch_mm"]["median"] == pytest.approx(0.5)
    assert doc["segment_excess_p95_mm"] == pytest.approx(0.0, abs=1e-9)
    assert doc["rest_jitter_p95_mm"] == pytest.approx(0.0, abs=1e-9)


def test_lost_points_warn():
    valid = np.ones((F, N + 1), bool)
    valid[20:, 5:] = False                                           # the outer half lost in motion
    doc = _judge(_swing(), valid)
    assert doc["valid_share"] == pytest.approx(0.4, abs=0.01)
    assert doc["verdict"]["status"] == "warn" and "tracked in the moving frames" in doc["verdict"]["reasons"][0]


def test_the_seen_length_is_reported_not_judged():
    doc = _judge(_swing(), mismatch=np.full(F, 0.008))               # 8 mm short in every frame
    assert doc["length_mismatch_mm"]["median"] == pytest.approx(8.0) and doc["verdict"]["status"] == "ok"
    noisy = np.array([-0.012, 0.0, 0.012])[np.arange(F) % 3]        # +-12 mm from frame to frame
    doc = _judge(_swing(), mismatch=noisy)
    assert doc["length_mismatch_mm"]["spread_p95"] == pytest.approx(12.0) and doc["verdict"]["status"] == "ok"


def test_points_misplaced_along_the_string_and_jitter_at_rest_warn():
    xy = _swing()
    xy[20:, 5] = xy[20:, 4] + 1.4 * (xy[20:, 5] - xy[20:, 4])         # point 5 pushed 12 mm out along the string
    doc = _judge(xy)
    assert doc["segment_excess_p95_mm"] == pytest.approx(12.0, abs=0.1)
    assert "farther apart" in " ".join(doc["verdict"]["reasons"])
    doc = _judge(_swing(np.random.default_rng(0), 0.002))            # 2 mm noise on every point
    assert doc["rest_jitter_p95_mm"] > 2.0 and "jitter" in " ".join(doc["verdict"]["reasons"])


def test_mismatched_lengths_raise():
    with pytest.raises(ValueError, match="rows"):
        tracking_quality(_table(_swing()).iloc[:-1], np.zeros(F), L, N, np.ones(F, bool), np.zeros(F, bool), ST)
