"""Independent pieces of work side by side in forked worker processes (sync's and tracking's frames).

The frames of a decoded video (:class:`~stringcast.video.CachedVideo`) are independent and can be
read in any order, so a stage splits them into chunks and :func:`forked_map` hands the chunks to
worker processes. The workers are forked after the stage has set everything up: they inherit
its state (the tracker, the template, the memory-mapped frames) at no copying cost, and only the
chunk's index goes out and its small result comes back. The results come back in the chunks'
order, so a stage's output does not depend on the number of workers. A worker ends with its stage,
even one killed hard (:mod:`stringcast.core.lifeline`).
"""
from __future__ import annotations

import multiprocessing
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from collections.abc import Callable, Iterator, Sequence

from .lifeline import die_with_parent

_TASK: dict = {}   # the function and its chunks, set in the parent just before the workers are forked


def _run_chunk(i: int):
    return _TASK["func"](_TASK["chunks"][i])


def _worker_start(parent: int) -> None:
    """A worker ends with its stage (:func:`~stringcast.core.lifeline.die_with_parent`), even one
    killed hard; one whose stage is already gone ends now."""
    die_with_parent()
    if os.getppid() != parent:
        os._exit(1)


def forked_map(func: Callable, chunks: Sequence, workers: int) -> Iterator:
    """``func(chunk)`` for each of ``chunks``, yielded in order.

    ``func`` may be any callable, a closure included: the workers inherit it by ``fork``. With
    ``workers`` <= 1, one chunk, or off Linux, the chunks run here, one after the other (Windows
    has no ``fork``; on macOS a forked child of a process that used the system's frameworks may
    crash, which is why Python spawns there). Not re-entrant: ``func`` must not call
    :func:`forked_map` itself.
    """
    if workers <= 1 or len(chunks) < 2 or not sys.platform.startswith("linux"):
        for chunk in chunks:
            yield func(chunk)
        return
    if _TASK:
        raise RuntimeError("forked_map: already running (func may not call forked_map)")
    _TASK.update(func=func, chunks=chunks)
    try:
        with ProcessPoolExecutor(max_workers=min(workers, len(chunks)), mp_context=multiprocessing.get_context("fork"),
                                 initializer=_worker_start, initargs=(os.getpid(),)) as pool:
            try:
                yield from pool.map(_run_chunk, range(len(chunks)))
            except BaseException:   # an interrupt or a failed chunk: the others are not waited for
                _terminate(pool)
                raise
    finally:
        _TASK.clear()


def _terminate(pool: ProcessPoolExecutor) -> None:
    """End ``pool``'s workers now (Python 3.14's ``terminate_workers``; before it, each process)."""
    pool.shutdown(wait=False, cancel_futures=True)
    if hasattr(pool, "terminate_workers"):
        pool.terminate_workers()
        return
    for proc in list((getattr(pool, "_processes", None) or {}).values()):
        proc.terminate()


def chunked(items: Sequence, size: int) -> list:
    """``items`` in consecutive chunks of ``size`` (the last one shorter)."""
    return [items[i:i + size] for i in range(0, len(items), max(1, int(size)))]
