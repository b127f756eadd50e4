"""Sync from video.yaml's trigger time."""
import numpy as np
import pytest
import yaml

from stringcast.files import DataError, read_json
from stringcast.sync import frame_times, run_sync


def _meta(tmp_path, **kw):
    p = tmp_path / "video.yaml"
    p.write_text(yaml.safe_dump(kw))
    return p


def test_run_sync_writes_offset(tmp_path):
    doc = run_sync(_meta(tmp_path, fps=500.0, frames=7, trigger_time_s=0.0314), tmp_path / "out" / "sync.json")
    on_disk = read_json(tmp_path / "out" / "sync.json")
    assert on_disk == doc
    assert doc["offset_s"] == pytest.approx(0.0314) and doc["residual_mm"] is None
    assert doc["method"] == "video.yaml trigger_time_s" and "not estimated" in doc["note"]
    t = frame_times(doc)
    assert t.shape == (7,) and t[0] == pytest.approx(0.0314) and np.allclose(np.diff(t), 1 / 500.0)
    assert frame_times(doc, 3).shape == (3,)


@pytest.mark.parametrize("trigger", [None, "absent"])
def test_missing_trigger_says_estimation_comes_later(tmp_path, trigger):
    kw = dict(fps=500.0, frames=10)
    if trigger is None:
        kw["trigger_time_s"] = None
    with pytest.raises(DataError, match="video.yaml.*trigger_time_s.*later"):
        run_sync(_meta(tmp_path, **kw), tmp_path / "sync.json")
    assert not (tmp_path / "sync.json").exists()


def test_bad_video_yaml(tmp_path):
    with pytest.raises(DataError, match="video.yaml"):
        run_sync(_meta(tmp_path, fps=-1, frames=10, trigger_time_s=0.0))
    with pytest.raises(DataError, match="not found"):
        run_sync(tmp_path / "nope" / "video.yaml")
    with pytest.raises(DataError, match="fps"):
        frame_times({"offset_s": 0.0, "fps": 0.0, "frames": 3})
