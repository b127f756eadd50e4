"""Frames tracked one after another, or side by side in worker processes (tracking's main pass).

Each frame is tracked on its own (:meth:`FrameTracker.track` keeps nothing from one frame to
the next), so frames read from the decoded video (:class:`~stringcast.video.CachedVideo`: any
frame, no decoding) are split into chunks that worker processes track side by side. The
workers are forked after the background is built: they share the tracker, the arm's poses
and the memory-mapped frames with the parent at no copying cost, and send back only each
frame's points. The result does not depend on the number of workers.
"""
from __future__ import annotations

import multiprocessing
import sys
from concurrent.futures import ProcessPoolExecutor
from typing import Iterator

import numpy as np

CHUNK = 16
"""Frames per task: a few ms each, so the workers' bookkeeping stays below 1 % and the load balances."""

_SHARED: dict = {}   # set in the parent just before the workers are forked; read by _track_chunk


def _track_chunk(ks: np.ndarray) -> list:
    tracker, video, jpx = _SHARED["tracker"], _SHARED["video"], _SHARED["jpx"]
    return [(int(k), tracker.track(video.read(int(k)), jpx[k])) for k in ks]


def track_frames(tracker, video, frames, jpx: np.ndarray, ks: np.ndarray, shows: set, workers: int = 1
                 ) -> Iterator[tuple]:
    """Track frames ``ks`` (increasing); yields ``(k, FrameTrack, frame or None)`` in order of k,
    the frame itself only for k in ``shows`` (the overlay's).

    Args:
        tracker: :class:`~stringcast.track.frame_tracker.FrameTracker`.
        video: the trial's reader; frames: an iterator of ``(k, frame)`` decoding ``video`` in
            order (:func:`~stringcast.video.prefetch`), or None where ``video`` is a
            :class:`~stringcast.video.CachedVideo` (then read at random, and by ``workers``
            processes when > 1; ``fork`` start method, so on Linux and macOS).
        jpx: (F, P, J + 2, 2) px, the arm's joints at P instants of each frame period.
    """
    from tqdm import tqdm

    ks = np.asarray(ks, int)
    bar = tqdm(total=len(ks), desc="tracking", unit="frame", disable=not sys.stderr.isatty())
    want = set(int(k) for k in ks)
    if frames is not None:
        for k, frame in frames:
            if k in want:
                bar.update()
                yield k, tracker.track(frame, jpx[k]), frame if k in shows else None
    elif workers <= 1 or len(ks) < 2 * CHUNK or "fork" not in multiprocessing.get_all_start_methods():
        for k in ks:
            frame = video.read(int(k))
            bar.update()
            yield int(k), tracker.track(frame, jpx[k]), frame if k in shows else None
    else:
        _SHARED.update(tracker=tracker, video=video, jpx=jpx)
        try:
            chunks = [ks[i:i + CHUNK] for i in range(0, len(ks), CHUNK)]
            with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork")) as pool:
                for part in pool.map(_track_chunk, chunks):
                    bar.update(len(part))
                    for k, ft in part:
                        yield k, ft, video.read(k) if k in shows else None
        finally:
            _SHARED.clear()
    bar.close()
