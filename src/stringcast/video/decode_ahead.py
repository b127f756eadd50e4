"""Video frames decoded ahead in a background thread (used by :mod:`stringcast.track.tracking`).

OpenCV's decoder releases the GIL, so decoding the next frames overlaps the per-frame
processing of the current one.
"""
from __future__ import annotations

import queue
import threading


def prefetch(video, depth: int):
    """Iterate ``(index, frame)`` of ``video`` decoded ahead in a thread (OpenCV's decoder releases
    the GIL), at most ``depth`` frames held; the reader's errors are raised in the caller."""
    q: queue.Queue = queue.Queue(maxsize=max(1, depth))
    stop = threading.Event()

    def work():
        try:
            for item in video:
                while not stop.is_set():
                    try:
                        q.put(item, timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if stop.is_set():
                    return
            q.put(None)
        except BaseException as exc:  # noqa: BLE001 - handed to the consumer
            q.put(exc)

    th = threading.Thread(target=work, name="tracking-decode", daemon=True)
    th.start()

    def gen():
        try:
            while True:
                item = q.get()
                if item is None:
                    return
                if isinstance(item, BaseException):
                    raise item
                yield item
        finally:
            stop.set()
            th.join(timeout=5)

    return gen()
