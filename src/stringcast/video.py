"""Video readers: one streaming, mono interface over containers and frame folders.

:func:`open_video` opens

* a container OpenCV's FFmpeg backend reads (``.mkv``, ``.avi``, ``.mp4``, ...), through
  ``cv2.VideoCapture``. A mono stream (FFV1 ``gray``/``gray16le``, as the virtual lab and
  many high-speed cameras write) is read raw (``CAP_PROP_CONVERT_RGB = 0``), so 16-bit
  depth is kept; a colour stream is decoded to BGR and converted to grey with
  ``cv2.cvtColor(..., COLOR_BGR2GRAY)`` (ITU-R BT.601 luma, full range);
* a folder of PNG/TIFF frames (natural sort of the file names, so ``f2`` comes before
  ``f10``), read with ``cv2.imread(IMREAD_UNCHANGED)``; colour frames become grey, and
  8/16-bit depth is kept.

Every reader yields ``(index, frame)`` once when iterated, holds one frame at a time, and
reads single frames with :meth:`VideoReader.read`. Errors are :class:`~stringcast.files.DataError`
naming the file: unreadable, empty, frames of changing size, or a container that ends
before its announced frame count (truncated).

A Photron ``.cihx`` + ``.mraw`` pair is named in DESIGN.md but not read yet.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from .files import DataError

FRAME_SUFFIXES = (".png", ".tif", ".tiff")
_SEEK_GAP = 40  # a seek costs about as much as decoding 10-30 frames: grab forward over shorter gaps
_INTRA_CODECS = {"FFV1", "MJPG", "PNG ", "MPNG", "RAW ", "Y800", "GREY", "Y16 ", "HFYU", "FFVH", "ULRG", "ULY0"}


def to_grey(frame: np.ndarray) -> np.ndarray:
    """(H, W[, 3|4]) uint8/uint16 -> (H, W) grey of the same dtype (cv2.cvtColor, BT.601)."""
    if frame.ndim == 2:
        return frame
    if frame.ndim == 3 and frame.shape[2] == 1:
        return frame[:, :, 0]
    if frame.ndim == 3 and frame.shape[2] == 3:
        return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    if frame.ndim == 3 and frame.shape[2] == 4:
        return cv2.cvtColor(frame, cv2.COLOR_BGRA2GRAY)
    raise ValueError(f"cannot convert an image of shape {frame.shape} to grey")


class VideoReader:
    """A mono video, streamed.

    Attributes:
        path: the file or folder.
        n_frames: frame count.
        fps: frames per second, or None if the source does not say (frame folders).
        width, height: frame size in px.
        dtype: ``np.uint8`` or ``np.uint16``.

    Iterating yields ``(index, frame)`` with frame (height, width) of ``dtype``, each
    frame once, in order. Use as a context manager or call :meth:`close`.
    """

    path: Path
    n_frames: int
    fps: float | None
    width: int
    height: int
    dtype: np.dtype

    def __len__(self) -> int:
        return self.n_frames

    def __enter__(self) -> "VideoReader":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Release the underlying file handles (idempotent)."""

    def read(self, index: int) -> np.ndarray:
        """Frame ``index`` (0-based) as (height, width) ``dtype``. Raises IndexError, DataError."""
        raise NotImplementedError

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        raise NotImplementedError

    def _check_index(self, index: int) -> int:
        index = int(index)
        if not 0 <= index < self.n_frames:
            raise IndexError(f"{self.path}: frame {index} out of range 0..{self.n_frames - 1}")
        return index

    def _check_frame(self, frame: np.ndarray, index: int) -> np.ndarray:
        if frame.shape != (self.height, self.width) or frame.dtype != self.dtype:
            raise DataError(f"{self.path}: frame {index} is {frame.shape} {frame.dtype}, the first was "
                            f"{(self.height, self.width)} {np.dtype(self.dtype)}")
        return frame

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({str(self.path)!r}, {self.n_frames} frames, {self.width}x{self.height}, "
                f"{np.dtype(self.dtype).name}, fps={self.fps})")


class ContainerReader(VideoReader):
    """A video container read through ``cv2.VideoCapture`` (FFmpeg backend).

    Random access (:meth:`read`) decodes forward from the current position over short
    gaps (so reading frames in increasing order costs one decode each), and seeks with
    ``CAP_PROP_POS_FRAMES`` over long gaps for intra-only codecs (FFV1, MJPEG, PNG, raw),
    where it is exact; for inter-frame codecs (H.264, ...) it decodes forward from the
    start (or the current position), which is exact but slow.
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        if not self.path.is_file():
            raise DataError(f"{self.path}: file not found")
        if self.path.stat().st_size == 0:
            raise DataError(f"{self.path}: empty file")
        cap = self._open(raw=False)
        ok, bgr = cap.read()
        self.fourcc = int(cap.get(cv2.CAP_PROP_FOURCC)).to_bytes(4, "little").decode("latin-1").upper()
        fps = float(cap.get(cv2.CAP_PROP_FPS))
        count = int(round(cap.get(cv2.CAP_PROP_FRAME_COUNT)))
        cap.release()
        if not ok or bgr is None:
            raise DataError(f"{self.path}: no frame could be decoded (empty or unreadable video)")
        # Mono stream: the raw frame is 2-D and equals the BGR conversion (or is 16-bit).
        cap = self._open(raw=True)
        ok, raw = cap.read()
        cap.release()
        self._raw = bool(ok and raw is not None and raw.ndim == 2 and raw.shape == bgr.shape[:2]
                         and (raw.dtype == np.uint16 or np.array_equal(raw, to_grey(bgr))))
        first = raw if self._raw else to_grey(bgr)
        self.height, self.width = first.shape
        self.dtype = first.dtype
        self.fps = fps if np.isfinite(fps) and fps > 0 else None
        if count <= 0:
            count = self._count_by_decoding()
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

    def _count_by_decoding(self) -> int:
        cap = self._open(raw=True)
        n = 0
        while cap.grab():
            n += 1
        cap.release()
        return n

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
            if self.fourcc in _INTRA_CODECS and index - self._pos > _SEEK_GAP:
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
        try:
            for i in range(self.n_frames):
                yield i, self._decode(cap, i)
        finally:
            cap.release()

    def close(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None


def _natural_key(p: Path) -> list:
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", p.name)]


class FrameFolderReader(VideoReader):
    """A folder of PNG/TIFF frames, one file per frame, in natural name order."""

    def __init__(self, path: str | Path, fps: float | None = None):
        self.path = Path(path)
        if not self.path.is_dir():
            raise DataError(f"{self.path}: not a folder")
        self.files = sorted((p for p in self.path.iterdir() if p.suffix.lower() in FRAME_SUFFIXES
                             and not p.name.startswith(".")), key=_natural_key)
        if not self.files:
            raise DataError(f"{self.path}: no PNG/TIFF frames in the folder")
        first = self._load(self.files[0])
        self.height, self.width = first.shape
        self.dtype = first.dtype
        self.n_frames = len(self.files)
        self.fps = fps

    def _load(self, f: Path) -> np.ndarray:
        img = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
        if img is None or img.size == 0:
            raise DataError(f"{f}: not a readable image")
        if img.dtype not in (np.uint8, np.uint16):
            raise DataError(f"{f}: pixel type {img.dtype} (expected 8- or 16-bit)")
        try:
            return to_grey(img)
        except ValueError as exc:
            raise DataError(f"{f}: {exc}") from exc

    def read(self, index: int) -> np.ndarray:
        index = self._check_index(index)
        frame = self._load(self.files[index])
        if frame.shape != (self.height, self.width) or frame.dtype != self.dtype:
            raise DataError(f"{self.files[index]}: {frame.shape} {frame.dtype}, the first frame was "
                            f"{(self.height, self.width)} {np.dtype(self.dtype)}")
        return frame

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        for i in range(self.n_frames):
            yield i, self.read(i)


def open_video(path: str | Path, fps: float | None = None) -> VideoReader:
    """Open a video file or a folder of frames as a mono :class:`VideoReader`.

    Args:
        path: a container OpenCV reads (mkv/avi/mp4/...) or a folder of PNG/TIFF frames.
        fps: frame rate to report for a frame folder (containers report their own).

    Raises:
        DataError: missing, empty or unreadable source; a Photron ``.cihx`` (not read yet).
    """
    path = Path(path)
    if path.is_dir():
        return FrameFolderReader(path, fps)
    if not path.exists():
        raise DataError(f"{path}: file not found")
    if path.suffix.lower() in (".cihx", ".cih", ".mraw"):
        raise DataError(f"{path}: Photron .cihx/.mraw is not read yet; convert it to a PNG/TIFF folder")
    if path.suffix.lower() in FRAME_SUFFIXES:
        raise DataError(f"{path}: a single image, not a video (put frames in a folder)")
    return ContainerReader(path)
