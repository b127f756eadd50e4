"""Photron high-speed camera files: a ``.cihx`` (XML) or ``.cih`` (text) header + ``.mraw`` frames.

The header is parsed with ``pyMRAW.get_cih`` (frame count, size, record rate, bit depths).
The ``.mraw`` is raw frames back to back, no compression: 8- or 16-bit little-endian
pixels, or 12-bit packed big-endian (two pixels in three bytes, as ``pyMRAW`` unpacks
them), or colour with three interleaved channels (24 or 48 bits per pixel, RGB order
assumed). Frames are mapped with ``np.memmap`` and copied one at a time, so a long clip
is never held in memory (``pyMRAW.load_video`` would unpack a whole 12-bit file at once).

:func:`write_photron` writes a ``.cihx`` + ``.mraw`` pair (8, 12 packed or 16 bit, mono),
for tests and the virtual lab.
"""
from __future__ import annotations

import warnings
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np

from stringcast.core import DataError, atomic_path
from .base import VideoReader, to_grey


def _read_header(path: Path) -> dict:
    import pyMRAW

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            cih = pyMRAW.get_cih(str(path))
    except Exception as exc:  # pyMRAW raises KeyError/IndexError/ExpatError... on a bad header
        raise DataError(f"{path}: not a readable Photron header: {type(exc).__name__}: {exc}") from exc
    missing = [k for k in ("Total Frame", "Image Width", "Image Height", "Color Bit") if k not in cih]
    if missing:
        raise DataError(f"{path}: Photron header lacks {missing}")
    return cih


class PhotronReader(VideoReader):
    """A Photron ``.cihx``/``.cih`` + ``.mraw`` pair, streamed frame by frame.

    Attributes (beyond :class:`~stringcast.video.container.VideoReader`):
        cih: the header as ``pyMRAW.get_cih`` returns it.
        mraw_path: the frame file.

    ``fps`` is the header's ``Record Rate(fps)``; ``bit_depth`` its ``EffectiveBit Depth``
    when the significant bits are the lower ones, else the stored bits per channel;
    ``timestamps_s`` is None (the header has no per-frame times).

    Raises:
        DataError: missing ``.mraw``, unreadable header, unsupported pixel format, or an
            ``.mraw`` shorter than the header's frame count (truncated).
    """

    def __init__(self, path: str | Path):
        path = Path(path)
        if path.suffix.lower() == ".mraw":
            heads = [path.with_suffix(s) for s in (".cihx", ".cih") if path.with_suffix(s).exists()]
            if not heads:
                raise DataError(f"{path}: no .cihx/.cih header beside the .mraw")
            path = heads[0]
        self.path = path
        self.mraw_path = path.with_suffix(".mraw")
        if not self.mraw_path.is_file():
            raise DataError(f"{path}: the frame file {self.mraw_path.name} is missing")
        self.cih = cih = _read_header(path)
        fmt = str(cih.get("File Format", "MRaw")).lower()
        if fmt != "mraw":
            raise DataError(f"{path}: File Format {cih.get('File Format')!r}: only MRaw frames are read")
        self.n_frames = int(cih["Total Frame"])
        self.width, self.height = int(cih["Image Width"]), int(cih["Image Height"])
        bits = int(cih["Color Bit"])
        self._channels = 3 if bits in (24, 48) else 1
        self._bits = bits // self._channels  # per channel: 8, 12 or 16
        if self._bits not in (8, 12, 16) or (self._channels == 3 and self._bits == 12):
            raise DataError(f"{path}: Color Bit {bits} is not supported (8/12/16 mono, 24/48 colour)")
        self.dtype = np.dtype(np.uint8 if self._bits == 8 else np.uint16)
        eff, side = cih.get("EffectiveBit Depth"), str(cih.get("EffectiveBit Side", "Lower")).lower()
        self.bit_depth = int(eff) if isinstance(eff, int) and 0 < eff <= self._bits and side == "lower" else self._bits
        rate = float(cih.get("Record Rate(fps)", 0) or 0)
        self.fps = rate if np.isfinite(rate) and rate > 0 else None
        if self.n_frames < 1 or self.width < 1 or self.height < 1:
            raise DataError(f"{path}: header announces {self.n_frames} frames of {self.width}x{self.height} px")
        self._frame_bytes = self.width * self.height * self._channels * self._bits // 8
        size = self.mraw_path.stat().st_size
        if size < self.n_frames * self._frame_bytes:
            raise DataError(f"{self.mraw_path}: truncated: {size} bytes hold {size // self._frame_bytes} of the "
                            f"{self.n_frames} frames announced in {path.name}")
        self._mm = np.memmap(self.mraw_path, dtype=np.uint8, mode="r", shape=(self.n_frames, self._frame_bytes))

    def read(self, index: int) -> np.ndarray:
        index = self._check_index(index)
        if self._mm is None:
            raise DataError(f"{self.path}: the reader is closed")
        raw = np.array(self._mm[index])  # a copy: the frame outlives the map and may be written to
        if self._bits == 12:
            b = raw.reshape(-1, 3).astype(np.uint16)
            px = np.empty((b.shape[0], 2), np.uint16)
            px[:, 0] = (b[:, 0] << 4) | (b[:, 1] >> 4)
            px[:, 1] = ((b[:, 1] & 0x0F) << 8) | b[:, 2]
        else:
            px = raw.view("<u2") if self._bits == 16 else raw
        img = px.reshape(self.height, self.width, self._channels)
        return to_grey(np.ascontiguousarray(img), "RGB").astype(self.dtype, copy=False)

    def close(self) -> None:
        self._mm = None  # the map closes when its last reference goes


def write_photron(path: str | Path, frames, fps: float, color_bit: int = 16, effective_bit: int | None = None) -> Path:
    """Write mono frames as a Photron ``.cihx`` header + ``.mraw`` (atomically, frame by frame).

    Args:
        path: the ``.cihx`` to write; the ``.mraw`` goes beside it.
        frames: iterable of (H, W) integer arrays (values below ``2**color_bit``).
        fps: record rate, frames per second.
        color_bit: 8, 12 (packed) or 16 bits per pixel in the ``.mraw``.
        effective_bit: significant (lower) bits; default ``color_bit``.

    Returns:
        The ``.cihx`` path. Raises ValueError for other bit depths or changing frame sizes.
    """
    if color_bit not in (8, 12, 16):
        raise ValueError(f"color_bit must be 8, 12 or 16, got {color_bit}")
    path = Path(path).with_suffix(".cihx")
    n, shape = 0, None
    with atomic_path(path.with_suffix(".mraw")) as tmp, open(tmp, "wb") as f:
        for fr in frames:
            fr = np.asarray(fr)
            if shape is None:
                shape = fr.shape
            if fr.ndim != 2 or fr.shape != shape or fr.size % 2:
                raise ValueError(f"frame {n}: shape {fr.shape} (need 2-D, constant, even pixel count)")
            if color_bit == 12:
                p = fr.astype(np.uint16).reshape(-1, 2)
                fr = np.stack([p[:, 0] >> 4, ((p[:, 0] & 0x0F) << 4) | (p[:, 1] >> 8), p[:, 1] & 0xFF], 1)
                f.write(fr.astype(np.uint8).tobytes())
            else:
                f.write(fr.astype("<u2" if color_bit == 16 else np.uint8).tobytes())
            n += 1
    h, w = shape if shape is not None else (0, 0)
    eff = effective_bit or color_bit
    xml = (f"<cih><fileInfo><date>2000/01/01</date></fileInfo>"
           f"<deviceInfo><deviceName>{escape('stringcast write_photron')}</deviceName></deviceInfo>"
           f"<recordInfo><recordRate>{fps:g}</recordRate><shutterSpeed>{1.0 / fps:.9g}</shutterSpeed></recordInfo>"
           f"<frameInfo><totalFrame>{n}</totalFrame><recordedFrame>{n}</recordedFrame></frameInfo>"
           f"<imageDataInfo><resolution><width>{w}</width><height>{h}</height></resolution>"
           f"<colorInfo><type>Mono</type><bit>{color_bit}</bit></colorInfo>"
           f"<effectiveBit><depth>{eff}</depth><side>Lower</side></effectiveBit></imageDataInfo>"
           f"<imageFileInfo><fileFormat>MRaw</fileFormat></imageFileInfo><basicInfo><comment></comment></basicInfo></cih>")
    with atomic_path(path) as tmp:
        tmp.write_text('<?xml version="1.0" encoding="UTF-8" ?>\n' + xml.replace("><", ">\n<") + "\n")
    return path
