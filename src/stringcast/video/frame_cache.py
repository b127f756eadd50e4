"""A trial's video decoded once: the frames as one NumPy array on disk, read back by memory map.

Sync, the arm's sweep and tracking all read the trial's video. Decoding it costs the same for
each of them: even the sweep's 40 frames spread over the clip decode every frame between them
(an FFV1 seek in Matroska costs about 30 decodes), so the trial's three stages decoded the clip
three times, and tracking's background a fourth time in part. The workflow's ``decode`` rule
now decodes it once into ``frames.npy`` and the stages read frames from it at the cost of a
memory copy. The file is F x H x W pixels (823 MB for 823 frames of 1024 x 1024, 8-bit): the
price of not decoding again when a later stage reruns.

* ``frames.npy``: (F, H, W) ``uint8`` or ``uint16``, the grey frames exactly as
  :func:`~stringcast.video.container.open_video` gives them, in NumPy's ``.npy`` format (any
  NumPy opens it: ``np.load(path, mmap_mode="r")``);
* ``frames.json`` beside it: the source video's path, size and modification time (a cache of
  another or a changed video is refused), fps, bit depth and per-frame timestamps.
"""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np

from stringcast.core import DataError, atomic_path

from .base import VideoReader
from .container import open_video


def _sidecar(frames_npy: Path) -> Path:
    return Path(frames_npy).with_suffix(".json")


def _source_stamp(video_path: Path) -> dict:
    """What identifies the source video: its real path (links followed), byte size and modification time (ns)."""
    real = Path(video_path).resolve()
    st = real.stat()
    return {"path": str(real), "bytes": int(st.st_size), "mtime_ns": int(st.st_mtime_ns)}


def write_frame_cache(video_path: str | Path, frames_npy: str | Path, fps: float | None = None,
                      progress: bool | None = None) -> Path:
    """Decode ``video_path`` once into ``frames_npy`` (+ ``frames.json``); returns ``frames_npy``.

    Parameters
    ----------
    video_path : str or Path
        Any :func:`~stringcast.video.container.open_video` source.
    frames_npy : str or Path
        The ``.npy`` file to write, (F, H, W) ``uint8`` or ``uint16``; written under a temporary name of its
        own and renamed (the sidecar first), so an interrupted decode leaves no half cache and two
        decodes of the same trial side by side each leave a whole one.
    fps : float, optional
        The frame rate for a source that has none (frame folders), frames / s, as ``open_video``.
    progress : bool, optional
        Show a tqdm bar (default: when stderr is a terminal).

    Returns
    -------
    Path
        ``frames_npy``.

    Raises
    ------
    DataError
        The video is missing, unreadable or truncated (named by the reader).
    """
    from tqdm import tqdm

    video_path, frames_npy = Path(video_path), Path(frames_npy)
    # temporary names of their own (atomic_path): two runs decoding the same trial each rename a whole file
    with atomic_path(frames_npy) as tmp, atomic_path(_sidecar(frames_npy)) as side_tmp:
        with open_video(video_path, fps=fps) as video, open(tmp, "wb") as fh:
            # the .npy header, then each frame's bytes as decoded: a plain sequential write (a memory
            # map took a page fault per 4 KiB written, a third of the decode's time)
            np.lib.format.write_array_header_2_0(fh, {"descr": np.lib.format.dtype_to_descr(np.dtype(video.dtype)),
                                                      "fortran_order": False,
                                                      "shape": (video.n_frames, video.height, video.width)})
            if hasattr(os, "posix_fallocate"):   # the file's blocks reserved at once: a third of the writes' system time
                os.posix_fallocate(fh.fileno(), fh.tell(), video.n_frames * video.height * video.width
                                   * np.dtype(video.dtype).itemsize)
            show = sys.stderr.isatty() if progress is None else progress
            for _, frame in tqdm(video, total=video.n_frames, desc="decode", unit="frame", disable=not show):
                fh.write(np.ascontiguousarray(frame).data)
            stamps = video.timestamps_s                   # recorded by the pass above: no second decode
            meta = {"source": _source_stamp(video_path), "fps": video.fps, "bit_depth": int(video.bit_depth),
                    "frames": int(video.n_frames), "width": int(video.width), "height": int(video.height),
                    "timestamps_s": None if stamps is None else [float(t) for t in stamps]}
        side_tmp.write_text(json.dumps(meta))
    return frames_npy


class CachedVideo(VideoReader):
    """The frames of :func:`write_frame_cache`, with the :class:`VideoReader` interface.

    :meth:`read` is a copy out of the memory map (any frame, any order, no decode); the
    attributes are the source reader's, as recorded.

    Raises:
        DataError: the cache or its ``frames.json`` is missing or malformed, or it was made
            from another video than ``video_path`` or from an earlier version of it.
    """

    def __init__(self, frames_npy: str | Path, video_path: str | Path):
        self.path = Path(video_path)
        frames_npy = Path(frames_npy)
        try:
            meta = json.loads(_sidecar(frames_npy).read_text())
            self._frames = np.load(frames_npy, mmap_mode="r")
            missing = {"source", "frames", "fps", "bit_depth", "timestamps_s"} - set(meta)
            if missing:
                raise ValueError(f"{_sidecar(frames_npy).name} lacks {', '.join(sorted(missing))}")
        except (OSError, ValueError, TypeError, EOFError) as exc:   # np.load of an empty file: EOFError
            raise DataError(f"{frames_npy}: not a readable frame cache ({exc}); delete it to decode the video "
                            "again") from exc
        if meta.get("source") != _source_stamp(self.path):
            raise DataError(f"{frames_npy}: made from {meta.get('source', {}).get('path')} as it was then, not from "
                            f"{self.path} as it is now; delete it to decode the video again")
        if self._frames.ndim != 3 or self._frames.shape[0] != meta["frames"]:
            raise DataError(f"{frames_npy}: holds {self._frames.shape}, {_sidecar(frames_npy)} says "
                            f"{meta['frames']} frames")
        self.n_frames, self.height, self.width = (int(x) for x in self._frames.shape)
        self.dtype = self._frames.dtype
        self.fps = meta["fps"]
        self.bit_depth = int(meta["bit_depth"])
        self._stamps = None if meta["timestamps_s"] is None else np.asarray(meta["timestamps_s"], float)

    @property
    def timestamps_s(self) -> np.ndarray | None:
        return self._stamps

    def read(self, index: int) -> np.ndarray:
        return np.array(self._frames[self._check_index(index)])

    def close(self) -> None:
        self._frames = None


def open_trial_video(video_path: str | Path, frames_npy: str | Path | None = None,
                     fps: float | None = None) -> VideoReader:
    """``frames_npy``'s :class:`CachedVideo` of ``video_path`` when given, else
    :func:`~stringcast.video.container.open_video` (``fps`` as there; a cache has its own)."""
    if frames_npy is None:
        return open_video(video_path, fps=fps)
    video = CachedVideo(frames_npy, video_path)
    if video.fps is None:
        video.fps = fps
    return video
