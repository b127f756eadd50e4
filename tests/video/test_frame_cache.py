"""The video decoded once (``frames.npy``): the same frames, times and attributes as the video,
in any order; a cache of another or a changed video is refused; the real H.264 clip."""
import json
import os

import numpy as np
import pytest

from stringcast.cli import main
from stringcast.core.files import DataError
from stringcast.video import CachedVideo, open_trial_video, open_video, write_frame_cache

from conftest import SHARED_REAL, random_frames, write_ffv1


def _video(path, n=9, seed=0):
    """A small random FFV1 video at ``path``; returns its frames."""
    frames = random_frames(n, 24, 32, seed=seed)
    write_ffv1(path, frames)
    return frames


def test_cache_holds_the_videos_frames_times_and_attributes(tmp_path):
    frames = _video(tmp_path / "video.mkv")
    out = write_frame_cache(tmp_path / "video.mkv", tmp_path / "res" / "frames.npy")
    assert out.exists() and not list((tmp_path / "res").glob(".*"))      # no temporary file left
    assert np.load(out).shape == (9, 24, 32)           # a plain .npy any NumPy opens
    with open_video(tmp_path / "video.mkv") as v, open_trial_video(tmp_path / "video.mkv", out) as c:
        assert isinstance(c, CachedVideo)
        for key in ("n_frames", "width", "height", "dtype", "fps", "bit_depth"):
            assert getattr(c, key) == getattr(v, key), key
        np.testing.assert_array_equal(c.timestamps_s, v.timestamps_s)
        for k in (8, 0, 5, 5, 1):                       # any order, no decode
            assert np.array_equal(c.read(k), frames[k])
        assert [k for k, f in c if np.array_equal(f, frames[k])] == list(range(9))
        c.read(3)[:] = 0                                # a copy: the cache is not written
        assert np.array_equal(c.read(3), frames[3])
        with pytest.raises(IndexError):
            c.read(9)


def test_cache_of_a_changed_or_other_video_is_refused(tmp_path):
    _video(tmp_path / "video.mkv")
    _video(tmp_path / "other.mkv", seed=1)
    out = write_frame_cache(tmp_path / "video.mkv", tmp_path / "frames.npy")
    with pytest.raises(DataError, match="not from .*other.mkv"):
        CachedVideo(out, tmp_path / "other.mkv")
    st = (tmp_path / "video.mkv").stat()
    os.utime(tmp_path / "video.mkv", ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))   # the video rewritten since
    with pytest.raises(DataError, match="delete it to decode the video again"):
        CachedVideo(out, tmp_path / "video.mkv")
    (tmp_path / "frames.json").write_text("{not json")
    with pytest.raises(DataError, match="frames.npy: not a readable frame cache"):
        CachedVideo(out, tmp_path / "video.mkv")
    (tmp_path / "frames.json").write_text(json.dumps({"frames": 9}))
    with pytest.raises(DataError, match="frames.json lacks bit_depth, fps, source, timestamps_s"):
        CachedVideo(out, tmp_path / "video.mkv")


def test_a_truncated_video_leaves_no_cache_nor_partial_file(tmp_path):
    write_ffv1(tmp_path / "full.mkv", random_frames(30, 64, 64))
    data = (tmp_path / "full.mkv").read_bytes()
    (tmp_path / "cut.mkv").write_bytes(data[: len(data) // 2])
    with pytest.raises(DataError, match="cut.mkv.*truncated"):
        write_frame_cache(tmp_path / "cut.mkv", tmp_path / "res" / "frames.npy")
    assert list((tmp_path / "res").iterdir()) == []


def test_two_decodes_of_one_trial_side_by_side_each_leave_a_whole_cache(tmp_path, monkeypatch):
    """Two runs decoding the same trial at once (held together mid-decode by a barrier): both finish, and
    the cache is whole; a shared temporary name had one rename the other's file away and fail."""
    import threading

    frames = _video(tmp_path / "video.mkv", n=6)
    barrier = threading.Barrier(2, timeout=30)

    reader = type(open_video(tmp_path / "video.mkv"))
    frames_of = reader.__iter__

    def iterate(self):
        for k, frame in frames_of(self):
            if k == 3:
                barrier.wait()          # both decoders are half way through their files
            yield k, frame

    monkeypatch.setattr(reader, "__iter__", iterate)
    out, errors = tmp_path / "res" / "frames.npy", []

    def decode():
        try:
            write_frame_cache(tmp_path / "video.mkv", out)
        except Exception as exc:   # noqa: BLE001 (the test reports what either decoder raised)
            errors.append(exc)

    threads = [threading.Thread(target=decode) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert errors == []
    assert np.array_equal(np.load(out), np.stack(frames)) and json.loads(out.with_suffix(".json").read_text())["frames"] == 6
    assert sorted(p.name for p in out.parent.iterdir()) == ["frames.json", "frames.npy"]


def test_decode_command_writes_the_cache_beside_its_sidecar(tmp_path, capsys):
    trial = tmp_path / "trial_1"
    trial.mkdir()
    frames = _video(trial / "video.mkv", n=5)
    assert main(["decode", "--video", str(trial / "video.mkv"), "--out", str(tmp_path / "r" / "frames.npy")]) == 0
    meta = json.loads((tmp_path / "r" / "frames.json").read_text())
    assert meta["frames"] == 5 and meta["source"]["path"].endswith("video.mkv")
    assert np.array_equal(np.load(tmp_path / "r" / "frames.npy")[4], frames[4])
    assert main(["decode", "--video", str(tmp_path / "none" / "video.mkv"), "--out", str(tmp_path / "x.npy")]) == 2
    assert "none" in capsys.readouterr().err


def test_real_h264_clip_cached_equals_decoded(tmp_path):
    clip = SHARED_REAL / "charuco_clip" / "cam_0.mp4"
    if not clip.exists():
        pytest.skip(f"real data absent: {clip}")
    out = write_frame_cache(clip, tmp_path / "frames.npy")
    with open_video(clip) as v, open_trial_video(clip, out) as c:
        assert (c.n_frames, c.width, c.height) == (48, 1280, 720)
        for k in (47, 0, 20):
            assert np.array_equal(c.read(k), v.read(k))
