"""Video readers: FFV1 container, PNG folder, 16-bit TIFF folder, real H.264, bad inputs."""

import cv2
import numpy as np
import pytest

from stringcast.files import DataError
from stringcast.video import ContainerReader, FrameFolderReader, open_video

from conftest import SHARED_REAL


def _frames(n, h=40, w=56, dtype=np.uint8, seed=0):
    rng = np.random.default_rng(seed)
    hi = 255 if dtype == np.uint8 else 65535
    return [rng.integers(0, hi, (h, w)).astype(dtype) for _ in range(n)]


def _write_ffv1(path, frames, fps=500.0):
    h, w = frames[0].shape
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), fps, (w, h), isColor=False)
    assert vw.isOpened()
    for f in frames:
        vw.write(f)
    vw.release()


def test_ffv1_mkv_lossless_stream_and_random_access(tmp_path):
    frames = _frames(12)
    _write_ffv1(tmp_path / "v.mkv", frames)
    with open_video(tmp_path / "v.mkv") as v:
        assert isinstance(v, ContainerReader)
        assert (v.n_frames, v.width, v.height, v.dtype, v.fps) == (12, 56, 40, np.uint8, 500.0)
        seen = [i for i, f in v if np.array_equal(f, frames[i])]
        assert seen == list(range(12))
        for k in (7, 2, 11, 0):  # backwards and forwards
            assert np.array_equal(v.read(k), frames[k])
        with pytest.raises(IndexError):
            v.read(12)


def test_16bit_ffv1_keeps_depth(tmp_path):
    frames = _frames(4, dtype=np.uint16)
    h, w = frames[0].shape
    vw = cv2.VideoWriter(str(tmp_path / "v16.mkv"), cv2.CAP_FFMPEG, cv2.VideoWriter_fourcc(*"FFV1"), 100.0,
                         (w, h), [cv2.VIDEOWRITER_PROP_DEPTH, cv2.CV_16U, cv2.VIDEOWRITER_PROP_IS_COLOR, 0])
    for f in frames:
        vw.write(f)
    vw.release()
    v = open_video(tmp_path / "v16.mkv")
    assert v.dtype == np.uint16
    assert np.array_equal(v.read(3), frames[3])


def test_png_folder_natural_order_and_colour_to_grey(tmp_path):
    frames = _frames(11)
    for i, f in enumerate(frames):  # f2 must come before f10
        cv2.imwrite(str(tmp_path / f"f{i}.png"), cv2.cvtColor(f, cv2.COLOR_GRAY2BGR) if i % 2 else f)
    (tmp_path / "notes.txt").write_text("not a frame")
    v = open_video(tmp_path, fps=250.0)
    assert isinstance(v, FrameFolderReader)
    assert (v.n_frames, v.fps, v.dtype) == (11, 250.0, np.uint8)
    for i, f in v:
        assert np.array_equal(f, frames[i]), i


def test_tiff_folder_16bit(tmp_path):
    frames = _frames(3, dtype=np.uint16)
    for i, f in enumerate(frames):
        assert cv2.imwrite(str(tmp_path / f"frame_{i:04d}.tiff"), f)
    v = open_video(tmp_path)
    assert v.dtype == np.uint16 and v.fps is None
    assert np.array_equal(v.read(1), frames[1])
    assert [i for i, _ in v] == [0, 1, 2]


def test_folder_with_changing_frame_size(tmp_path):
    cv2.imwrite(str(tmp_path / "a0.png"), np.zeros((10, 10), np.uint8))
    cv2.imwrite(str(tmp_path / "a1.png"), np.zeros((12, 10), np.uint8))
    v = open_video(tmp_path)
    with pytest.raises(DataError, match="a1.png"):
        list(v)


def test_truncated_video_raises_naming_file(tmp_path):
    _write_ffv1(tmp_path / "full.mkv", _frames(30, 64, 64))
    data = (tmp_path / "full.mkv").read_bytes()
    (tmp_path / "cut.mkv").write_bytes(data[: len(data) // 2])
    v = open_video(tmp_path / "cut.mkv")
    with pytest.raises(DataError, match="cut.mkv.*truncated"):
        for _ in v:
            pass


@pytest.mark.parametrize("content", [b"", b"this is not a video" * 50])
def test_unreadable_or_empty(tmp_path, content):
    p = tmp_path / "video.mkv"
    p.write_bytes(content)
    with pytest.raises(DataError, match="video.mkv"):
        open_video(p)


def test_missing_and_empty_folder(tmp_path):
    with pytest.raises(DataError, match="not found"):
        open_video(tmp_path / "nope.mkv")
    with pytest.raises(DataError, match="no PNG/TIFF"):
        open_video(tmp_path)


def test_real_h264_clip_to_grey():
    clip = SHARED_REAL / "charuco_clip" / "cam_0.mp4"
    if not clip.exists():
        pytest.skip(f"real data absent: {clip}")
    v = open_video(clip)
    assert (v.width, v.height, v.n_frames, v.dtype) == (1280, 720, 48, np.uint8)
    cap = cv2.VideoCapture(str(clip))
    for _ in range(5):
        ok, bgr = cap.read()
    assert np.array_equal(v.read(4), cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY))
