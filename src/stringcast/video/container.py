"""Video readers: one streaming, mono interface over containers, frame folders and Photron files.

:func:`open_video` opens

* a container OpenCV's FFmpeg backend reads (``.mkv``, ``.avi``, ``.mp4``, ...), through
  ``cv2.VideoCapture``. A mono stream (FFV1 ``gray``/``gray16le``, as the virtual lab and
  many high-speed cameras write) is read raw (``CAP_PROP_CONVERT_RGB = 0``), so 16-bit
  depth is kept; a colour stream is decoded to BGR and converted to grey with
  ``cv2.cvtColor(..., COLOR_BGR2GRAY)`` (ITU-R BT.601 luma, full range);
* a folder of PNG/TIFF frames (natural sort of the file names, so ``f2`` comes before
  ``f10``): PNG through ``cv2.imread(IMREAD_UNCHANGED)``, TIFF through ``tifffile`` (so
  12-bit packed and 16-bit, mono and RGB, all read); colour frames become grey, and the
  8/12/16-bit depth is kept (12-bit in ``uint16``);
* a multi-page TIFF file (one page per frame) through ``tifffile.TiffFile``;
* a Photron ``.cihx``/``.cih`` + ``.mraw`` pair (:mod:`stringcast.video.photron`).

The frame-folder and TIFF-stack readers are in :mod:`stringcast.video.images`.

Every reader yields ``(index, frame)`` once when iterated, holds one frame at a time, and
reads single frames with :meth:`VideoReader.read`. It reports ``fps`` and per-frame
``timestamps_s`` where the file has them, and the native ``bit_depth``. Errors are
:class:`~stringcast.core.files.DataError` naming the file: unreadable, empty, frames of changing
size, or a file that ends before its announced frame count (truncated).
"""
from __future__ import annotations

from pathlib import Path
from collections.abc import Iterator

import cv2
import numpy as np

from stringcast.core import DataError

from .base import FRAME_SUFFIXES, PHOTRON_SUFFIXES, TIFF_SUFFIXES, VideoReader, to_grey
from .images import FrameFolderReader, TiffStackReader
from .photron import PhotronReader

_SEEK_GAP = 40  # a seek costs about as much as decoding 10-30 frames: grab forward over shorter gaps
_INTRA_CODECS = {"FFV1", "MJPG", "PNG ", "MPNG", "RAW ", "Y800", "GREY", "Y16 ", "HFYU", "FFVH", "ULRG", "ULY0"}
_MS_CLOCK_SUFFIXES = (".mkv", ".webm", ".mka", ".mk3d")  # Matroska stores times in ms by default


class ContainerReader(VideoReader):
    """A video container read through ``cv2.VideoCapture`` (FFmpeg backend).

    Random access (:meth:`read`) decodes forward from the current position over short
    gaps (so reading frames in increasing order costs one decode each), and seeks with
    ``CAP_PROP_POS_FRAMES`` over long gaps for intra-only codecs (FFV1, MJPEG, PNG, raw),
    where it is exact; for inter-frame codecs (H.264, ...) it decodes forward from the
    start (or the current position), which is exact but slow.

    Matroska keeps times in ms, so above 1000 fps its announced frame count (duration x
    fps) and frame seeks are ambiguous: the count is then found by decoding the file once
    at opening (unless ``count_frames`` is False: a header-only look, whose ``n_frames`` is then
    the announced count, known to ``count_slack`` frames), and :meth:`read` never seeks.
    ``timestamps_s`` are the frames' presentation times (``CAP_PROP_POS_MSEC``), recorded while
    iterating or, if asked for before a full pass, by one decoding pass; None if they do not
    increase strictly.
    """

    def __init__(self, path: str | Path, count_frames: bool = True):
        self.path = Path(path)
        if not self.path.is_file():
            raise DataError(f"{self.path}: file not found")
        if self.path.stat().st_size == 0:
            raise DataError(f"{self.path}: empty file")
        cap = self._open(raw=False)
        ok, bgr = cap.read()
        self.fourcc = int(cap.get(cv2.CAP_PROP_FOURCC)).to_bytes(4, "little").decode("latin-1").upper()
        pixel_format = int(cap.get(cv2.CAP_PROP_CODEC_PIXEL_FORMAT))
        fps = float(cap.get(cv2.CAP_PROP_FPS))
        count = int(round(cap.get(cv2.CAP_PROP_FRAME_COUNT)))
        cap.release()
        if not ok or bgr is None:
            raise DataError(f"{self.path}: no frame could be decoded (empty or unreadable video)")
        # Mono stream: the raw frame is 2-D and equals the BGR conversion (or is 16-bit). Only a grey
        # pixel format is read raw: OpenCV reads any other (YUV of MJPEG, H.264) raw as its luma
        # plane with a warning for every frame, and its luma may be limited-range.
        ok, raw = False, None
        if _grey_pixel_format(pixel_format, bgr):
            cap = self._open(raw=True)
            ok, raw = cap.read()
            cap.release()
        self._raw = bool(ok and raw is not None and raw.ndim == 2 and raw.shape == bgr.shape[:2]
                         and (raw.dtype == np.uint16 or np.array_equal(raw, to_grey(bgr))))
        first = raw if self._raw else to_grey(bgr)
        self.height, self.width = first.shape
        self.dtype = first.dtype
        self.bit_depth = 8 * first.dtype.itemsize
        self.fps = fps if np.isfinite(fps) and fps > 0 else None
        self._pts_ms: list[float] | None = None
        self._can_seek = self.fourcc in _INTRA_CODECS
        if self.path.suffix.lower() in _MS_CLOCK_SUFFIXES and self.fps is not None and self.fps > 1000.0:
            self._can_seek = False
            # duration (ms) x fps is not exact: count by decoding, or take it as known to a ms of frames
            self.count_slack = int(np.ceil(self.fps / 1000.0)) + 1
            count = -1 if count_frames else count
        if count <= 0 and count_frames:
            self._pts_ms = self._decode_pass()
            count, self.count_slack = len(self._pts_ms), 0
        elif count <= 0:
            count, self.count_slack = 0, None
        self.n_frames = count
        self._cap: cv2.VideoCapture | None = None
        self._pos = 0  # index of the frame the next _cap.read() returns

    def _open(self, raw: bool) -> cv2.VideoCapture:
        cap = cv2.VideoCapture(str(self.path), cv2.CAP_FFMPEG)
        if not cap.isOpened():
            raise DataError(f"{self.path}: not a video OpenCV can open (unreadable or unknown container)")
        if raw:
            cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)
        return cap

    def _decode_pass(self) -> list[float]:
        """Grab every frame once; their presentation times in ms."""
        cap = self._open(raw=True)
        pts = []
        while cap.grab():
            pts.append(float(cap.get(cv2.CAP_PROP_POS_MSEC)))
        cap.release()
        return pts

    @property
    def timestamps_s(self) -> np.ndarray | None:
        if self._pts_ms is None:
            pts = self._decode_pass()
            if len(pts) < self.n_frames:
                raise DataError(f"{self.path}: truncated or corrupt: {len(pts)} of {self.n_frames} announced "
                                "frames could be decoded")
            self._pts_ms = pts[: self.n_frames]
        t = np.asarray(self._pts_ms, float) * 1e-3
        if len(t) != self.n_frames or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            return None
        return t

    def _decode(self, cap: cv2.VideoCapture, index: int) -> np.ndarray:
        ok, frame = cap.read()
        if not ok or frame is None:
            raise DataError(f"{self.path}: truncated or corrupt: frame {index} of {self.n_frames} "
                            "announced could not be decoded")
        frame = frame if self._raw else to_grey(frame)
        return self._check_frame(frame, index)

    def read(self, index: int) -> np.ndarray:
        index = self._check_index(index)
        if self._cap is None or index < self._pos:
            if self._cap is not None:
                self._cap.release()
            self._cap = self._open(self._raw)
            self._pos = 0
        if index != self._pos:
            if self._can_seek and index - self._pos > _SEEK_GAP:
                self._cap.set(cv2.CAP_PROP_POS_FRAMES, index)
            else:
                while self._pos < index:
                    if not self._cap.grab():
                        raise DataError(f"{self.path}: truncated or corrupt: frame {self._pos} of "
                                        f"{self.n_frames} announced could not be decoded")
                    self._pos += 1
            self._pos = index
        frame = self._decode(self._cap, index)
        self._pos = index + 1
        return frame

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        cap = self._open(self._raw)
        pts = []
        try:
            for i in range(self.n_frames):
                frame = self._decode(cap, i)
                pts.append(float(cap.get(cv2.CAP_PROP_POS_MSEC)))
                yield i, frame
            if self._pts_ms is None:
                self._pts_ms = pts
        finally:
            cap.release()

    def close(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None


def _grey_pixel_format(pixel_format: int, bgr: np.ndarray) -> bool:
    """Whether a stream is grey: its FFmpeg pixel format as OpenCV names it (``Y800``, ``Y1`` + depth:
    gray, gray10/12/16), or, where OpenCV does not say (<= 0), a first frame with equal channels."""
    if pixel_format > 0:
        tag = pixel_format.to_bytes(4, "little")
        return tag[:1] == b"Y" and tag[1:2] in (b"8", b"1")
    return bgr.ndim == 2 or all(np.array_equal(bgr[..., 0], bgr[..., c]) for c in range(1, bgr.shape[2]))


def dropped_frames(timestamps_s: np.ndarray, fps: float) -> list[tuple[int, int]]:
    """Gaps in per-frame timestamps: ``[(index, n_missing), ...]``.

    ``index`` is the frame after which ``n_missing >= 1`` frames are missing. Each frame's
    place on the frame clock, ``rint((t_k - t_0) fps)``, less its index is its offset; a frame
    dropped raises the offset of every later frame for good, while a container's coarse time
    base (Matroska's 1 ms against a 1.06 ms period at 940 fps) only moves single frames by one
    and back. So a gap is a step up of the smallest offset from there on (the last frame's
    step is taken as read). Empty list: no frame dropped.
    """
    t = np.asarray(timestamps_s, float)
    if len(t) < 2:
        return []
    offset = np.rint((t - t[0]) * float(fps)).astype(int) - np.arange(len(t))
    floor = np.minimum.accumulate(offset[::-1])[::-1]
    missing = np.diff(floor)
    return [(int(i), int(missing[i])) for i in np.flatnonzero(missing >= 1)]


def video_meta_problems(reader: VideoReader, meta: dict) -> list[tuple[str, str, object, str]]:
    """How a video disagrees with its ``video.yaml`` (``meta``, read by :func:`files.read_video_meta`).

    A frame count the reader knows only to ``count_slack`` frames (a header-only look at a Matroska
    file above 1000 fps) is compared within it; one it does not know (``count_slack`` None) is not.

    Returns:
        ``[(severity, key, value, what), ...]``: ``"error"`` for ``frames`` (and ``width_px`` /
        ``height_px`` where given) that disagree with the video, ``"warn"`` for ``fps`` and
        ``bit_depth``; ``value`` is the yaml's, ``what`` says what the video holds.
    """
    out: list[tuple[str, str, object, str]] = []
    slack = getattr(reader, "count_slack", 0)
    if slack is not None and abs(int(meta["frames"]) - reader.n_frames) > slack:
        about = "" if slack == 0 else f" (announced, to {slack} frames)"
        out.append(("error", "frames", meta["frames"], f"the video {reader.path} has {reader.n_frames} frames{about} "
                                                        f"({reader.n_frames - int(meta['frames']):+d})"))
    for key, got in (("width_px", reader.width), ("height_px", reader.height)):
        if meta.get(key) is not None and int(meta[key]) != got:
            out.append(("error", key, meta[key], f"the video {reader.path} is {reader.width}x{reader.height} px"))
    if reader.fps is not None and abs(reader.fps - float(meta["fps"])) > 1e-3 * float(meta["fps"]):
        out.append(("warn", "fps", meta["fps"], f"{reader.path} says {reader.fps:g}; using {meta['fps']}"))
    if meta.get("bit_depth") is not None and int(meta["bit_depth"]) > reader.bit_depth:
        out.append(("warn", "bit_depth", meta["bit_depth"], f"{reader.path} holds {reader.bit_depth}-bit frames"))
    return out


def check_frame_count(reader: VideoReader, meta: dict, video_yaml_path: str | Path) -> list[str]:
    """Check a video against its ``video.yaml`` (read by :func:`files.read_video_meta`;
    :func:`video_meta_problems`).

    Raises:
        DataError: ``frames`` (or ``width_px``/``height_px`` where given) disagree with
            the video; the message names both files.

    Returns:
        warnings: fps or ``bit_depth`` that disagree (the yaml is used for time).
    """
    src = f"{video_yaml_path}"
    problems = video_meta_problems(reader, meta)
    for severity, key, value, what in problems:
        if severity == "error":
            raise DataError(f"{src}: {key}: {value}, but {what}")
    return [f"{src}: {key} {value} but {what}" for severity, key, value, what in problems if severity == "warn"]


def open_video(path: str | Path, fps: float | None = None, count_frames: bool = True) -> VideoReader:
    """Open a video file or a folder of frames as a mono :class:`VideoReader`.

    Opening reads the header and the first frame; only a container whose header does not give
    its frame count exactly (Matroska above 1000 fps, or no count) is decoded once to count it.

    Parameters
    ----------
    path : str or Path
        A container OpenCV reads (mkv/avi/mp4/...), a folder of PNG/TIFF frames, a
        multi-page TIFF, or a Photron ``.cihx``/``.cih`` (or its ``.mraw``).
    fps : float, optional
        Frame rate to report for a frame folder or TIFF stack, frames / s (the others report their own).
    count_frames : bool
        False: never decode to count a container's frames (a look at its header:
        ``n_frames`` is then the announced count, known to the reader's ``count_slack``
        frames, None where unknown; for :func:`video_meta_problems`, not for reading frames).

    Returns
    -------
    VideoReader
        The mono reader (:class:`ContainerReader`, a frame-folder, TIFF-stack or Photron reader): frames
        (H, W) grey, ``uint8`` or ``uint16`` (12-bit in ``uint16``; the native depth is ``bit_depth``).

    Raises
    ------
    DataError
        Missing, empty, unreadable or truncated source; a single image.
    """
    path = Path(path)
    if path.is_dir():
        return FrameFolderReader(path, fps)
    if not path.exists():
        raise DataError(f"{path}: file not found")
    suffix = path.suffix.lower()
    if suffix in PHOTRON_SUFFIXES:
        return PhotronReader(path)
    if suffix in TIFF_SUFFIXES:
        return TiffStackReader(path, fps)
    if suffix in FRAME_SUFFIXES:
        raise DataError(f"{path}: a single image, not a video (put frames in a folder)")
    return ContainerReader(path, count_frames)
