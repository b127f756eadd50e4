"""The frames on the controller clock: ``sync.json``'s offset and frame rate as frame times.

Its own module because every later stage needs it (the sweep, tracking) and none of them needs
the offset's estimator and its compiled strip sampling.
"""
from __future__ import annotations

import numpy as np

from stringcast.core import DataError


def frame_times(sync: dict, n: int | None = None) -> np.ndarray:
    """Controller-clock times of frames 0..n-1: ``offset_s + k / fps`` -> (n,) s.

    Parameters
    ----------
    sync : dict
        The ``sync.json`` (or ``clock.json``) mapping: ``offset_s`` (s), ``fps`` (frames / s), ``frames``.
    n : int, optional
        Frame count (default ``sync["frames"]``).

    Returns
    -------
    ndarray, (n,)
        Each frame's exposure centre on the controller clock, s.

    Raises
    ------
    DataError
        Missing or non-positive fps, or missing offset (or one not finite).
    """
    try:
        offset, fps = float(sync["offset_s"]), float(sync["fps"])
        n = int(sync["frames"]) if n is None else int(n)
    except (KeyError, TypeError, ValueError) as exc:
        raise DataError(f"sync: needs offset_s, fps and frames, got {sync!r}") from exc
    if not (np.isfinite(fps) and fps > 0) or not np.isfinite(offset):
        raise DataError(f"sync: fps must be > 0 and offset finite, got fps={fps}, offset_s={offset}")
    return offset + np.arange(n) / fps
