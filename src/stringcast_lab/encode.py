"""The lab camera's recorder: the trial video in the codec a setup asks for (``lab.video``).

* ``ffv1`` (default): lossless FFV1 in Matroska (``video.mkv``), ``cv2.VideoWriter``
  (FFmpeg backend), 8-bit mono or BGR.
* ``mjpeg``: Motion JPEG in AVI (``video.avi``) through OpenCV's own MJPEG writer
  (``cv2.CAP_OPENCV_MJPEG``), JPEG quality ``mjpeg_quality`` (``VIDEOWRITER_PROP_QUALITY``).
  The FFmpeg backend is not used for it: it refuses the quality property, and its AVI
  muxer drops frames above 1000 fps. A mono camera's frames are written as BGR with three
  equal channels (OpenCV's MJPEG writer mis-encodes single-channel frames), so the
  chroma planes are flat and a grey read gives the frame back up to JPEG's loss.
* ``h264``: H.264 in MP4 (``video.mp4``), constant-quality ``h264_crf`` (libx264's CRF),
  preset ``h264_preset``, full-range YUV 4:2:0 (``gray`` for mono). OpenCV's wheels carry no
  H.264 encoder, so this takes PyAV (``av``) if installed, else the ffmpeg binary of
  ``imageio-ffmpeg``, else falls back to MPEG-4 part 2 (``mp4v``, OpenCV's FFmpeg backend,
  its default bit rate): also an inter-frame lossy codec. :func:`h264_backend` says which;
  the trial's ground truth records the codec written.

All writers take frames from a background thread (:class:`ThreadedWriter`): encoding costs
about as much as rendering a frame, and OpenCV, PyAV and a pipe release the GIL.
"""
from __future__ import annotations

import importlib.util
import queue
import subprocess
import threading
from fractions import Fraction
from pathlib import Path
from collections.abc import Mapping

import cv2
import numpy as np

from stringcast.core import ConfigError, DataError
from .settings import LabSettings

CODECS = {"ffv1": ".mkv", "mjpeg": ".avi", "h264": ".mp4"}
VIDEO_DEFAULTS = {"codec": "ffv1", "colour": False, "mjpeg_quality": 90, "h264_crf": 23, "h264_preset": "fast"}


def video_settings(config: Mapping) -> dict:
    """``lab.video`` over :data:`VIDEO_DEFAULTS` (codec, colour, mjpeg_quality, h264_crf, h264_preset).

    Raises:
        ConfigError: unknown keys, an unknown codec, quality outside 1..100 or CRF outside 0..51.
    """
    v = dict(LabSettings.from_config(config).video)
    unknown = set(v) - set(VIDEO_DEFAULTS)
    if unknown:
        raise ConfigError(f"lab.video: unknown keys {sorted(unknown)} (known: {sorted(VIDEO_DEFAULTS)})")
    v = {**VIDEO_DEFAULTS, **v}
    if v["codec"] not in CODECS:
        raise ConfigError(f"lab.video.codec = {v['codec']!r}: expected one of {sorted(CODECS)}")
    if not 1 <= int(v["mjpeg_quality"]) <= 100 or not 0 <= int(v["h264_crf"]) <= 51:
        raise ConfigError("lab.video: mjpeg_quality must be in 1..100 and h264_crf in 0..51")
    return v


def h264_backend() -> str:
    """How this machine writes ``h264``: ``"pyav"``, ``"imageio-ffmpeg"`` or ``"mp4v"`` (the fallback)."""
    if importlib.util.find_spec("av") is not None:
        return "pyav"
    if importlib.util.find_spec("imageio_ffmpeg") is not None:
        return "imageio-ffmpeg"
    return "mp4v"


class _OpenCVSink:
    """``cv2.VideoWriter`` for FFV1 (FFmpeg backend) or MJPEG (OpenCV's writer)."""

    def __init__(self, path: Path, codec: str, fps: float, size: tuple[int, int], colour: bool, quality: int):
        if codec == "ffv1":
            self._w = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"FFV1"), fps, size, isColor=colour)
        else:
            api = cv2.CAP_OPENCV_MJPEG if codec == "mjpeg" else cv2.CAP_FFMPEG
            self._w = cv2.VideoWriter(str(path), api, cv2.VideoWriter.fourcc(*("MJPG" if codec == "mjpeg" else "mp4v")),
                                      fps, size, True)
        if not self._w.isOpened():
            raise DataError(f"{path}: OpenCV cannot open a {codec} writer")
        if codec == "mjpeg" and not self._w.set(cv2.VIDEOWRITER_PROP_QUALITY, float(quality)):
            raise DataError(f"{path}: OpenCV's MJPEG writer refuses quality {quality}")
        self._expand = codec != "ffv1" and not colour     # MJPEG / mp4v take BGR frames

    def write(self, frame: np.ndarray) -> None:
        self._w.write(cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR) if self._expand else frame)

    def close(self) -> None:
        self._w.release()


class _PyAVSink:
    """libx264 through PyAV: CRF, preset, full-range yuvj420p (colour) or gray (mono)."""

    def __init__(self, path: Path, fps: float, size: tuple[int, int], colour: bool, crf: int, preset: str):
        import av

        self._av = av
        self._out = av.open(str(path), "w")
        self._s = self._out.add_stream("libx264", rate=Fraction(fps).limit_denominator(1000))
        self._s.width, self._s.height = size
        self._s.pix_fmt = "yuvj420p" if colour else "gray"
        self._s.options = {"crf": str(int(crf)), "preset": preset, "x264-params": "fullrange=on"}
        self._fmt = "bgr24" if colour else "gray"

    def write(self, frame: np.ndarray) -> None:
        for packet in self._s.encode(self._av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format=self._fmt)):
            self._out.mux(packet)

    def close(self) -> None:
        for packet in self._s.encode():
            self._out.mux(packet)
        self._out.close()


class _FFmpegPipeSink:
    """libx264 through imageio-ffmpeg's ffmpeg binary, raw frames on its standard input."""

    def __init__(self, path: Path, fps: float, size: tuple[int, int], colour: bool, crf: int, preset: str):
        import imageio_ffmpeg

        exe = imageio_ffmpeg.get_ffmpeg_exe()
        fmt = "bgr24" if colour else "gray"
        cmd = [exe, "-hide_banner", "-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt", fmt,
               "-s", f"{size[0]}x{size[1]}", "-r", str(Fraction(fps).limit_denominator(1000)), "-i", "-",
               "-c:v", "libx264", "-crf", str(int(crf)), "-preset", preset, "-x264-params", "fullrange=on",
               "-pix_fmt", "yuvj420p" if colour else "gray", "-f", "mp4", str(path)]
        self._p = subprocess.Popen(cmd, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
        self._path = path

    def write(self, frame: np.ndarray) -> None:
        self._p.stdin.write(np.ascontiguousarray(frame).tobytes())

    def close(self) -> None:
        self._p.stdin.close()
        err = self._p.stderr.read().decode(errors="replace")
        if self._p.wait() != 0:
            raise DataError(f"{self._path}: ffmpeg (imageio-ffmpeg) failed: {err.strip()[-400:]}")


class ThreadedWriter:
    """A video sink fed from a background thread. Use as a context manager; :meth:`close` waits
    for the queue and re-raises a writer error as :class:`DataError`."""

    def __init__(self, sink, path: Path, queue_size: int = 8):
        self.path = Path(path)
        self._sink = sink
        self._q: queue.Queue = queue.Queue(queue_size)
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        self.frames = 0

    def _run(self) -> None:
        while True:
            frame = self._q.get()
            if frame is None:
                break
            if self._error is None:
                try:
                    self._sink.write(frame)
                except BaseException as exc:  # keep draining; reported in close()
                    self._error = exc

    def write(self, frame: np.ndarray) -> None:
        """Queue one (H, W) uint8 (mono) or (H, W, 3) uint8 BGR (colour) frame."""
        if self._error is not None:
            raise DataError(f"{self.path}: writing a frame failed: {self._error}")
        self._q.put(frame)
        self.frames += 1

    def close(self) -> None:
        if self._thread.is_alive():
            self._q.put(None)
            self._thread.join()
        if self._sink is not None:
            sink, self._sink = self._sink, None
            try:
                sink.close()
            except BaseException as exc:
                self._error = self._error or exc
        if self._error is not None:
            raise DataError(f"{self.path}: writing a frame failed: {self._error}")

    def __enter__(self) -> ThreadedWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class FFV1Writer(ThreadedWriter):
    """``cv2.VideoWriter`` (FFV1, 8-bit mono, or BGR with ``colour``) fed from a background thread.

    Raises:
        DataError: OpenCV cannot open an FFV1 writer for ``path``.
    """

    def __init__(self, path: Path, fps: float, width: int, height: int, queue_size: int = 8, colour: bool = False):
        super().__init__(_OpenCVSink(Path(path), "ffv1", fps, (width, height), colour, 0), path, queue_size)


def open_writer(path: Path, video: Mapping, fps: float, width: int, height: int) -> tuple[ThreadedWriter, str]:
    """A threaded writer for ``video`` (:func:`video_settings`) into ``path`` (its suffix picks the
    container: give :data:`CODECS`'s), and the codec it really writes (``ffv1``, ``mjpeg``,
    ``h264`` or ``mp4v``, see the module doc).

    Raises:
        DataError: the writer cannot be opened.
    """
    codec, colour, size = video["codec"], bool(video["colour"]), (int(width), int(height))
    if codec in ("ffv1", "mjpeg"):
        return ThreadedWriter(_OpenCVSink(path, codec, fps, size, colour, int(video["mjpeg_quality"])), path), codec
    backend = h264_backend()
    if backend == "mp4v":
        return ThreadedWriter(_OpenCVSink(path, "mp4v", fps, size, colour, 0), path), "mp4v"
    if size[0] % 2 or size[1] % 2:
        raise ConfigError(f"lab.video: H.264 (4:2:0) needs an even image size, got {size[0]}x{size[1]}")
    cls = _PyAVSink if backend == "pyav" else _FFmpegPipeSink
    return ThreadedWriter(cls(path, fps, size, colour, int(video["h264_crf"]), str(video["h264_preset"])), path), "h264"
