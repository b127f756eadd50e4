"""Video-to-controller clock synchronisation.

This issue takes the offset from ``video.yaml``: ``trigger_time_s`` is the controller-clock
time of frame 0 (its exposure centre), written by the recording system. Frame k is then at
``t_k = offset_s + k / fps``. Estimating the offset from the video (matching the tracked
grasp point with the forward kinematics of the joint log, sub-frame, with a residual in mm)
is a later issue; ``sync.json`` says so (``residual_mm: null`` and a note).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .files import DataError, read_video_meta, write_json

METHOD_TRIGGER = "video.yaml trigger_time_s"


def run_sync(video_yaml: str | Path, out_json: str | Path | None = None) -> dict:
    """Read the trigger time from ``video.yaml`` and write ``sync.json``.

    Returns:
        ``{"offset_s", "fps", "frames", "method", "residual_mm": None, "note"}``; offset_s
        is the controller-clock time of frame 0 in s.

    Raises:
        DataError: ``video.yaml`` missing/malformed, or without ``trigger_time_s``
            (estimating the offset from the video is a later issue).
    """
    video_yaml = Path(video_yaml)
    meta = read_video_meta(video_yaml)
    trig = meta.get("trigger_time_s")
    if trig is None:
        raise DataError(f"{video_yaml}: no trigger_time_s; estimating the video-to-controller offset "
                        "from the video is not implemented yet (a later issue), so give the controller-clock "
                        "time of frame 0 as trigger_time_s")
    doc = {
        "offset_s": float(trig),
        "fps": float(meta["fps"]),
        "frames": int(meta["frames"]),
        "method": METHOD_TRIGGER,
        "residual_mm": None,
        "note": "offset taken from the recording's trigger time, not estimated from the video",
    }
    if out_json is not None:
        write_json(out_json, doc)
    return doc


def frame_times(sync: dict, n: int | None = None) -> np.ndarray:
    """Controller-clock times of frames 0..n-1: ``offset_s + k / fps`` -> (n,) s.

    Args:
        sync: the ``sync.json`` mapping (offset_s, fps, frames).
        n: frame count (default ``sync["frames"]``).

    Raises:
        DataError: missing or non-positive fps, or missing offset.
    """
    try:
        offset, fps = float(sync["offset_s"]), float(sync["fps"])
        n = int(sync["frames"]) if n is None else int(n)
    except (KeyError, TypeError, ValueError) as exc:
        raise DataError(f"sync: needs offset_s, fps and frames, got {sync!r}") from exc
    if not (np.isfinite(fps) and fps > 0) or not np.isfinite(offset):
        raise DataError(f"sync: fps must be > 0 and offset finite, got fps={fps}, offset_s={offset}")
    return offset + np.arange(n) / fps
