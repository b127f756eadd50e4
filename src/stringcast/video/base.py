"""The video reader interface: :class:`VideoReader` (streamed, mono) and :func:`to_grey`.

Readers for containers (:mod:`.container`), frame folders and TIFF stacks (:mod:`.images`)
and Photron files (:mod:`.photron`) subclass it; :func:`~stringcast.video.open_video` picks one.
"""
from __future__ import annotations

from pathlib import Path
from collections.abc import Iterator

import cv2
import numpy as np

from stringcast.core import DataError

FRAME_SUFFIXES = (".png", ".tif", ".tiff")
TIFF_SUFFIXES = (".tif", ".tiff")
PHOTRON_SUFFIXES = (".cihx", ".cih", ".mraw")


def to_grey(frame: np.ndarray, order: str = "BGR") -> np.ndarray:
    """(H, W[, 1|3|4]) uint8/uint16 -> (H, W) grey of the same dtype (cv2.cvtColor, BT.601).

    ``order`` is the channel order of a colour frame: ``"BGR"`` (OpenCV) or ``"RGB"``
    (tifffile, Photron). Raises ValueError for other shapes.
    """
    if frame.ndim == 2:
        return frame
    if frame.ndim == 3 and frame.shape[2] == 1:
        return frame[:, :, 0]
    rgb = order.upper() == "RGB"
    if frame.ndim == 3 and frame.shape[2] == 3:
        return cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY if rgb else cv2.COLOR_BGR2GRAY)
    if frame.ndim == 3 and frame.shape[2] == 4:
        return cv2.cvtColor(frame, cv2.COLOR_RGBA2GRAY if rgb else cv2.COLOR_BGRA2GRAY)
    raise ValueError(f"cannot convert an image of shape {frame.shape} to grey")


class VideoReader:
    """A mono video, streamed.

    Attributes:
        path: the file or folder.
        n_frames: frame count.
        fps: frames per second, or None if the source does not say (frame folders).
        width, height: frame size in px.
        dtype: ``np.uint8`` or ``np.uint16``.
        bit_depth: significant bits per pixel in the file (8, 10, 12, 16): pixel values are
            below ``2**bit_depth``; 12-bit data come in ``uint16``.
        timestamps_s: (n_frames,) per-frame times in s from the file (container
            presentation times), or None where the file has none or they cannot resolve
            the frame period; see :func:`dropped_frames`.

    Iterating yields ``(index, frame)`` with frame (height, width) of ``dtype``, each
    frame once, in order. Use as a context manager or call :meth:`close`.
    """

    path: Path
    n_frames: int
    count_slack: int | None = 0
    """How many frames ``n_frames`` may be off (0: exact; see :func:`~stringcast.video.open_video`'s
    ``count_frames``)."""
    fps: float | None
    width: int
    height: int
    dtype: np.dtype
    bit_depth: int

    @property
    def timestamps_s(self) -> np.ndarray | None:
        return None

    def __len__(self) -> int:
        return self.n_frames

    def __enter__(self) -> VideoReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Release the underlying file handles (idempotent)."""

    def read(self, index: int) -> np.ndarray:
        """Frame ``index`` (0-based) as (height, width) ``dtype``. Raises IndexError, DataError."""
        raise NotImplementedError

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        for i in range(self.n_frames):
            yield i, self.read(i)

    def _check_index(self, index: int) -> int:
        index = int(index)
        if not 0 <= index < self.n_frames:
            raise IndexError(f"{self.path}: frame {index} out of range 0..{self.n_frames - 1}")
        return index

    def _check_frame(self, frame: np.ndarray, index: int, source: Path | None = None) -> np.ndarray:
        if frame.shape != (self.height, self.width) or frame.dtype != self.dtype:
            raise DataError(f"{source or self.path}: frame {index} is {frame.shape} {frame.dtype}, the first was "
                            f"{(self.height, self.width)} {np.dtype(self.dtype)}")
        return frame

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({str(self.path)!r}, {self.n_frames} frames, {self.width}x{self.height}, "
                f"{self.bit_depth}-bit, fps={self.fps})")
