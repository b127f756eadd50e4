"""Video readers: FFV1 containers, PNG/TIFF folders (8/12/16-bit, RGB), TIFF stacks, Photron
.cihx/.mraw, real H.264; timestamps and bad inputs."""

import cv2
import numpy as np
import pytest

from stringcast.core.files import DataError
from stringcast.video.container import ContainerReader, open_video
from stringcast.video.images import FrameFolderReader

from conftest import SHARED_REAL, random_frames, write_ffv1


def test_ffv1_mkv_lossless_stream_and_random_access(tmp_path):
    frames = random_frames(12)
    write_ffv1(tmp_path / "v.mkv", frames)
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
    frames = random_frames(4, dtype=np.uint16)
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
    frames = random_frames(11)
    for i, f in enumerate(frames):  # f2 must come before f10
        cv2.imwrite(str(tmp_path / f"f{i}.png"), cv2.cvtColor(f, cv2.COLOR_GRAY2BGR) if i % 2 else f)
    (tmp_path / "notes.txt").write_text("not a frame")
    v = open_video(tmp_path, fps=250.0)
    assert isinstance(v, FrameFolderReader)
    assert (v.n_frames, v.fps, v.dtype) == (11, 250.0, np.uint8)
    for i, f in v:
        assert np.array_equal(f, frames[i]), i


def test_tiff_folder_16bit(tmp_path):
    frames = random_frames(3, dtype=np.uint16)
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
    write_ffv1(tmp_path / "full.mkv", random_frames(30, 64, 64))
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


def test_tiff_folder_12bit_packed_and_rgb(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    pytest.importorskip("imagecodecs")  # tifffile packs/unpacks 12-bit integers through imagecodecs
    mono = [f >> 4 for f in random_frames(3, dtype=np.uint16, seed=1)]  # 12-bit values
    for i, f in enumerate(mono):
        tifffile.imwrite(tmp_path / f"m{i}.tif", f, bitspersample=12, photometric="minisblack")
    v = open_video(tmp_path)
    assert (v.dtype, v.bit_depth, v.n_frames) == (np.uint16, 12, 3)
    assert all(np.array_equal(f, mono[i]) for i, f in v)

    rgb = np.random.default_rng(2).integers(0, 65535, (40, 56, 3)).astype(np.uint16)
    (tmp_path / "rgb").mkdir()
    tifffile.imwrite(tmp_path / "rgb" / "c0.tiff", rgb, photometric="rgb")
    tifffile.imwrite(tmp_path / "rgb" / "c1.tiff", np.ascontiguousarray(rgb[..., ::-1]), photometric="rgb")
    v = open_video(tmp_path / "rgb")
    assert (v.dtype, v.bit_depth) == (np.uint16, 16)
    assert np.array_equal(v.read(0), cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY))  # tifffile gives RGB, not BGR
    assert np.array_equal(v.read(1), cv2.cvtColor(rgb, cv2.COLOR_BGR2GRAY))


def test_multipage_tiff_stack(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    frames = random_frames(5, dtype=np.uint16, seed=3)
    tifffile.imwrite(tmp_path / "stack.tif", np.stack(frames), photometric="minisblack")
    with open_video(tmp_path / "stack.tif", fps=1000.0) as v:
        assert (v.n_frames, v.fps, v.bit_depth, v.timestamps_s) == (5, 1000.0, 16, None)
        assert [i for i, f in v if np.array_equal(f, frames[i])] == [0, 1, 2, 3, 4]
    tifffile.imwrite(tmp_path / "one.tif", frames[0])
    with pytest.raises(DataError, match="one.tif.*single image"):
        open_video(tmp_path / "one.tif")


@pytest.mark.parametrize("bits", [8, 12, 16])
def test_photron_cihx_mraw_round_trip(tmp_path, bits):
    from stringcast.video.photron import PhotronReader, write_photron

    frames = [f >> (16 - bits) for f in random_frames(7, dtype=np.uint16, seed=bits)]
    cihx = write_photron(tmp_path / "shot.cihx", iter(frames), fps=2000.0, color_bit=bits)
    assert (tmp_path / "shot.mraw").stat().st_size == 7 * 40 * 56 * bits // 8
    for p in (cihx, tmp_path / "shot.mraw"):  # open by header or by frame file
        with open_video(p) as v:
            assert isinstance(v, PhotronReader)
            assert (v.n_frames, v.width, v.height, v.fps, v.bit_depth) == (7, 56, 40, 2000.0, bits)
            assert v.dtype == (np.uint8 if bits == 8 else np.uint16)
            assert [i for i, f in v if np.array_equal(f, frames[i])] == list(range(7))
            assert np.array_equal(v.read(3), frames[3]) and v.timestamps_s is None


def test_photron_agrees_with_pymraw(tmp_path):
    """Our 12-bit packing and .cihx match pyMRAW's reader; pyMRAW's own .cih writer reads back."""
    pyMRAW = pytest.importorskip("pyMRAW")
    from stringcast.video.photron import write_photron

    frames = np.stack([f >> 4 for f in random_frames(3, dtype=np.uint16, seed=9)])
    cihx = write_photron(tmp_path / "a.cihx", frames, fps=500.0, color_bit=12)
    images, cih = pyMRAW.load_video(str(cihx))  # unpacks the whole 12-bit file at once
    assert cih["Record Rate(fps)"] == 500.0 and np.array_equal(np.asarray(images), frames)

    frames16 = random_frames(4, dtype=np.uint16, seed=10)
    pyMRAW.save_mraw(np.stack(frames16), str(tmp_path / "b.cih"), bit_depth=16,
                     info_dict={"Record Rate(fps)": 750, "EffectiveBit Depth": 16})
    v = open_video(tmp_path / "b.cih")
    assert (v.n_frames, v.fps, v.bit_depth) == (4, 750.0, 16)
    assert np.array_equal(v.read(2), frames16[2])


def test_photron_truncated_or_missing_mraw(tmp_path):
    from stringcast.video.photron import write_photron

    cihx = write_photron(tmp_path / "c.cihx", random_frames(6, dtype=np.uint16), fps=1000.0)
    mraw = tmp_path / "c.mraw"
    mraw.write_bytes(mraw.read_bytes()[: 40 * 56 * 2 * 4 + 100])
    with pytest.raises(DataError, match=r"c.mraw: truncated: .* 4 of the 6 frames"):
        open_video(cihx)
    mraw.unlink()
    with pytest.raises(DataError, match="c.mraw is missing"):
        open_video(cihx)
    (tmp_path / "d.cihx").write_text("<cih><fileInfo></fileInfo></cih>\n")
    (tmp_path / "d.mraw").write_bytes(b"\0" * 10)
    with pytest.raises(DataError, match="d.cihx: not a readable Photron header"):
        open_video(tmp_path / "d.cihx")


def test_matroska_above_1000fps_counts_frames_exactly(tmp_path):
    """Matroska keeps ms times: at 2000 fps its announced count is off; the reader counts."""
    frames = random_frames(37, 24, 32, seed=4)
    write_ffv1(tmp_path / "fast.mkv", frames, fps=2000.0)
    announced = cv2.VideoCapture(str(tmp_path / "fast.mkv")).get(cv2.CAP_PROP_FRAME_COUNT)
    v = open_video(tmp_path / "fast.mkv")
    assert v.n_frames == 37 and announced != 37
    assert [i for i, f in v if np.array_equal(f, frames[i])] == list(range(37))
    for k in (36, 2, 30):  # no seeks on ambiguous times: still exact
        assert np.array_equal(v.read(k), frames[k])
    assert v.timestamps_s is None  # 1 ms ticks cannot resolve 0.5 ms frames


def test_container_timestamps_and_dropped_frames(tmp_path):
    from stringcast.video.container import dropped_frames

    write_ffv1(tmp_path / "v.mkv", random_frames(20, 24, 32), fps=500.0)
    v = open_video(tmp_path / "v.mkv")
    t = v.timestamps_s  # asked before any pass: one decoding pass
    assert t == pytest.approx(np.arange(20) / 500.0, abs=1e-9)
    assert dropped_frames(t, v.fps) == []
    assert dropped_frames(np.delete(t, [5, 12, 13]), 500.0) == [(4, 1), (10, 2)]
    list(v)  # a full pass records them too
    assert v.timestamps_s == pytest.approx(t)
    assert v.bit_depth == 8


def test_a_coarse_time_base_is_no_dropped_frame():
    """940 fps in a 1 ms time base: the stamps step by 1 or 2 ms (a single 2 ms step is 1.9 frame
    periods), yet no frame is missing; a frame taken out still shows, at its place."""
    from stringcast.video.container import dropped_frames

    t = np.round(np.arange(1914) / 940.0, 3)
    assert np.diff(t).max() == pytest.approx(0.002)
    assert dropped_frames(t, 940.0) == []
    assert dropped_frames(np.delete(t, [300, 301]), 940.0) == [(299, 2)]


@pytest.mark.parametrize("colour", [False, True])
def test_mjpeg_at_1200_fps_reads_as_grey_quietly(tmp_path, capfd, colour):
    """Motion JPEG in AVI (OpenCV's own writer, as the lab and many cameras write it), from a mono
    camera (equal B, G, R) or a colour one: every frame, grey within JPEG's loss, and no OpenCV
    warning (a YUV stream read raw warned for every frame)."""
    rng = np.random.default_rng(3)
    base = cv2.GaussianBlur(rng.uniform(0, 255, (96, 128, 3)).astype(np.float32), (0, 0), 4)
    frames = [np.clip((np.roll(base, 4 * k, axis=1) - 127) * 3 + 127, 0, 255).astype(np.uint8) for k in range(12)]
    if not colour:
        frames = [cv2.cvtColor(cv2.cvtColor(f, cv2.COLOR_BGR2GRAY), cv2.COLOR_GRAY2BGR) for f in frames]
    vw = cv2.VideoWriter(str(tmp_path / "v.avi"), cv2.CAP_OPENCV_MJPEG, cv2.VideoWriter_fourcc(*"MJPG"), 1200.0,
                         (128, 96), True)
    assert vw.isOpened() and vw.set(cv2.VIDEOWRITER_PROP_QUALITY, 90)
    for f in frames:
        vw.write(f)
    vw.release()
    capfd.readouterr()
    with open_video(tmp_path / "v.avi") as v:
        got = [f for _, f in v]
        assert (v.n_frames, v.width, v.height, v.fps) == (12, 128, 96, 1200.0)
        assert v.read(7).shape == (96, 128)
    grey = np.stack([cv2.cvtColor(f, cv2.COLOR_BGR2GRAY) for f in frames]).astype(float)
    assert np.abs(np.stack(got).astype(float) - grey).mean() < 3.0
    assert "unsupported picture format" not in capfd.readouterr().err
