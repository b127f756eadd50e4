"""Frames tracked one after another, or side by side in worker processes (tracking's main pass).

Each frame is tracked on its own (:meth:`FrameTracker.track` keeps nothing from one frame to
the next), so frames read from the decoded video (:class:`~stringcast.video.CachedVideo`: any
frame, no decoding) go in chunks to worker processes (:func:`~stringcast.core.forked.forked_map`)
that share the tracker, the arm's poses and the memory-mapped frames with this process and send
back only each frame's points. The result does not depend on the number of workers.
"""
from __future__ import annotations

import sys
from collections.abc import Iterator

import numpy as np

from stringcast.core import chunked, forked_map

CHUNK = 16
"""Frames per task: a few ms each, so the workers' bookkeeping stays below 1 % and the load balances."""


def track_frames(tracker, video, frames, jpx: np.ndarray, ks: np.ndarray, shows: set, workers: int = 1
                 ) -> Iterator[tuple]:
    """Track frames ``ks`` (increasing); yields ``(k, FrameTrack, frame or None)`` in order of k,
    the frame itself only for k in ``shows`` (the overlay's).

    Args:
        tracker: :class:`~stringcast.track.frame_tracker.FrameTracker`.
        video: the trial's reader; frames: an iterator of ``(k, frame)`` decoding ``video`` in
            order (:func:`~stringcast.video.prefetch`), or None where ``video`` is a
            :class:`~stringcast.video.CachedVideo` (then read at random, by ``workers`` processes).
        jpx: (F, P, J + 2, 2) px, the arm's joints at P instants of each frame period.
    """
    from tqdm import tqdm

    ks = np.asarray(ks, int)
    bar = tqdm(total=len(ks), desc="tracking", unit="frame", disable=not sys.stderr.isatty())
    if frames is not None:
        want = set(ks.tolist())
        for k, frame in frames:
            if k in want:
                bar.update()
                yield k, tracker.track(frame, jpx[k]), frame if k in shows else None
    else:
        def chunk(part):
            return [(int(k), tracker.track(video.read(int(k)), jpx[k])) for k in part]

        for part in forked_map(chunk, chunked(ks, CHUNK), workers):
            bar.update(len(part))
            for k, ft in part:
                yield k, ft, video.read(k) if k in shows else None
    bar.close()
