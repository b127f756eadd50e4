"""Image-sequence readers of :func:`stringcast.video.container.open_video`: a folder of PNG/TIFF frames and a multi-page TIFF.

PNG through ``cv2.imread(IMREAD_UNCHANGED)``, TIFF through ``tifffile`` (12-bit packed and
16-bit, mono and RGB); colour frames become grey (:func:`stringcast.video.container.to_grey`) and the
8/12/16-bit depth is kept. Errors are :class:`~stringcast.core.files.DataError` naming the file.
"""
from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np

from stringcast.core import DataError
from .base import FRAME_SUFFIXES, TIFF_SUFFIXES, VideoReader, to_grey


def _natural_key(p: Path) -> list:
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", p.name)]


def _tiff_page(page, source: Path) -> tuple[np.ndarray, int]:
    """One ``tifffile`` page -> (grey frame, bits per sample). Raises DataError."""
    try:
        img = page.asarray()
    except Exception as exc:  # tifffile raises several types for damaged files
        raise DataError(f"{source}: TIFF page {page.index} is unreadable or truncated: {exc}") from exc
    if img.dtype not in (np.uint8, np.uint16):
        raise DataError(f"{source}: pixel type {img.dtype} (expected 8- to 16-bit unsigned integers)")
    if img.ndim == 3 and img.shape[0] in (3, 4) and img.shape[2] not in (3, 4):  # planar RGB
        img = np.moveaxis(img, 0, -1)
    try:
        grey = to_grey(np.ascontiguousarray(img), "RGB")
    except ValueError as exc:
        raise DataError(f"{source}: {exc}") from exc
    bps = page.bitspersample
    return grey, int(bps if isinstance(bps, int) else max(bps))


class FrameFolderReader(VideoReader):
    """A folder of PNG/TIFF frames, one file per frame, in natural name order.

    PNG is read with ``cv2.imread(IMREAD_UNCHANGED)``, TIFF with ``tifffile`` (first page
    of each file). ``bit_depth`` is the first TIFF's BitsPerSample, or the PNG's dtype width.
    """

    def __init__(self, path: str | Path, fps: float | None = None):
        self.path = Path(path)
        if not self.path.is_dir():
            raise DataError(f"{self.path}: not a folder")
        self.files = sorted((p for p in self.path.iterdir() if p.suffix.lower() in FRAME_SUFFIXES
                             and not p.name.startswith(".")), key=_natural_key)
        if not self.files:
            raise DataError(f"{self.path}: no PNG/TIFF frames in the folder")
        first, self.bit_depth = self._load(self.files[0])
        self.height, self.width = first.shape
        self.dtype = first.dtype
        self.n_frames = len(self.files)
        self.fps = fps

    def _load(self, f: Path) -> tuple[np.ndarray, int]:
        if f.suffix.lower() in TIFF_SUFFIXES:
            import tifffile

            try:
                with tifffile.TiffFile(f) as tif:
                    return _tiff_page(tif.pages[0], f)
            except DataError:
                raise
            except Exception as exc:
                raise DataError(f"{f}: not a readable TIFF image: {exc}") from exc
        img = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
        if img is None or img.size == 0:
            raise DataError(f"{f}: not a readable image")
        if img.dtype not in (np.uint8, np.uint16):
            raise DataError(f"{f}: pixel type {img.dtype} (expected 8- or 16-bit)")
        try:
            return to_grey(img), 8 * img.dtype.itemsize
        except ValueError as exc:
            raise DataError(f"{f}: {exc}") from exc

    def read(self, index: int) -> np.ndarray:
        index = self._check_index(index)
        return self._check_frame(self._load(self.files[index])[0], index, self.files[index])


def _tiff_announced_frames(tif) -> int | None:
    """Frame count a stack's ImageJ or tifffile ("shaped") metadata announces, if any."""
    ij = tif.imagej_metadata or {}
    if ij.get("images"):
        return int(ij["images"])
    shaped = tif.shaped_metadata or ()
    shape = shaped[0].get("shape") if shaped else None
    if shape and len(shape) >= 3 and tif.pages[0].shape == tuple(shape[1:]):
        return int(shape[0])  # (frames, H, W[, samples])
    return None


class TiffStackReader(VideoReader):
    """A multi-page TIFF file, one page per frame, read page by page with ``tifffile``."""

    def __init__(self, path: str | Path, fps: float | None = None):
        import tifffile

        self.path = Path(path)
        try:
            self._tif = tifffile.TiffFile(self.path)
            self.n_frames = len(self._tif.pages)
            announced = _tiff_announced_frames(self._tif)
        except Exception as exc:
            raise DataError(f"{self.path}: not a readable TIFF file: {exc}") from exc
        if announced is not None and announced > self.n_frames:
            self._tif.close()
            raise DataError(f"{self.path}: truncated: {self.n_frames} of the {announced} pages its metadata "
                            "announces could be found")
        if self.n_frames < 2:
            self._tif.close()
            raise DataError(f"{self.path}: a single image, not a video (put frames in a folder)")
        first, self.bit_depth = _tiff_page(self._tif.pages[0], self.path)
        self.height, self.width = first.shape
        self.dtype = first.dtype
        self.fps = fps

    def read(self, index: int) -> np.ndarray:
        index = self._check_index(index)
        try:
            page = self._tif.pages[index]
        except Exception as exc:
            raise DataError(f"{self.path}: truncated or corrupt: page {index} of {self.n_frames}: {exc}") from exc
        return self._check_frame(_tiff_page(page, self.path)[0], index)

    def close(self) -> None:
        self._tif.close()
