"""Static background of a trial's video and the sensor's noise model (tracking step 1).

See :func:`build_background`; used by :mod:`stringcast.track.tracking`.
"""
from __future__ import annotations

import math

import numpy as np

from stringcast.core import forked_map


def nan_median0(a: np.ndarray) -> np.ndarray:
    """Median over axis 0 ignoring NaN, as ``np.nanmedian(a, axis=0)`` (NaN where all are NaN), 4x faster.

    Sorting puts NaN last, so with n finite values per column the median is the mean of the
    sorted values at (n - 1) // 2 and n // 2. a: (S, ...) float -> (...) float."""
    s = np.sort(a, axis=0)
    n = np.sum(np.isfinite(a), axis=0)
    lo = np.take_along_axis(s, np.maximum((n - 1) // 2, 0)[None], axis=0)[0]
    hi = np.take_along_axis(s, np.maximum(n // 2, 0)[None], axis=0)[0]
    out = 0.5 * (lo + hi)
    out[n == 0] = np.nan
    return out


def background_samples(window: np.ndarray, n_samples: int, n_bursts: int) -> np.ndarray:
    """Frames for the background: ``n_bursts`` short runs spread evenly over ``window``.

    A container decodes every frame between two samples, and a seek costs about 20 decodes
    (FFV1 in Matroska, OpenCV's FFmpeg backend), so samples spread evenly over a whole motion
    cost as much as decoding it. Bursts of every other frame, evenly placed, keep the spread
    over the motion (where the string is elsewhere most of the time) and decode about
    2 ``n_samples`` frames. A window shorter than 8 ``n_samples`` (decoding it whole costs
    little more), ``n_bursts`` <= 0 or >= ``n_samples``: evenly spread samples, the better
    background (on a short clip of the string leaving the frame, bursts let an unseen point
    pass for a seen one).

    Args:
        window: (W,) sorted frame indices to sample from. Returns (<= n_samples,) sorted int.
    """
    window = np.asarray(window)
    n = min(len(window), n_samples)
    if n_bursts <= 0 or n_bursts >= n or 8 * n > len(window):
        return np.unique(np.round(np.linspace(window[0], window[-1], n))).astype(int)
    per = -(-n // n_bursts)  # frames per burst, every other frame
    starts = np.round(np.linspace(0, len(window) - 2 * per + 1, n_bursts)).astype(int)
    idx = (starts[:, None] + 2 * np.arange(per)[None]).ravel()[:n]
    return np.unique(window[np.clip(idx, 0, len(window) - 1)])


def build_background(video, sample_idx, pre_idx, arm_masks, workers: int = 1) -> tuple[np.ndarray, tuple[float, float]]:
    """Arm-masked temporal median background and the sensor's noise model.

    Args:
        video: :class:`~stringcast.video.container.VideoReader`.
        sample_idx: frames spread over the motion; pre_idx: pre-motion frames (fill-in).
        arm_masks: callable frame index -> (H, W) bool arm mask.
        workers: processes computing bands of rows side by side (:func:`~stringcast.core.forked_map`),
            for a video read in any order (a decoded :class:`~stringcast.video.CachedVideo`); the
            same result for any number (each pixel's median is its own).

    Returns:
        background (H, W) float32 (grey levels), and (a, b) of sigma^2 = a + b B, fitted by
        weighted least squares to robust (MAD) spreads of the samples about the background
        in 16 brightness bins.
    """
    h, w = video.height, video.width
    rows = -(-h // max(1, workers) // 64) * 64                  # bands of whole 64-row chunks
    bands = [(r, min(h, r + rows)) for r in range(0, h, rows)]

    def band(rng):  # (the band's background, its samples at every 4th row and column)
        r0, r1 = rng
        stack = np.empty((len(sample_idx), r1 - r0, w), np.float32)
        for j, k in enumerate(sample_idx):
            f = video.read(int(k))[r0:r1].astype(np.float32)
            f[arm_masks(int(k))[r0:r1]] = np.nan
            stack[j] = f
        bg = np.empty((r1 - r0, w), np.float32)
        for r in range(0, r1 - r0, 64):  # row chunks keep the sort's temporaries small
            bg[r:r + 64] = nan_median0(stack[:, r:r + 64])
        return bg, stack[:, ::4, ::4].copy()   # every 16th pixel: ~10^5 per bin at 1024^2

    parts = list(forked_map(band, bands, workers))
    bg = np.concatenate([p[0] for p in parts])
    sub = np.concatenate([p[1] for p in parts], axis=1)
    hole = ~np.isfinite(bg)
    if hole.any():
        src = pre_idx if len(pre_idx) else sample_idx
        pre = np.median(np.stack([video.read(int(k)) for k in src[:15]]), axis=0).astype(np.float32)
        bg[hole] = pre[hole]
    d = (sub - bg[None, ::4, ::4]).ravel()
    B = np.broadcast_to(bg[None, ::4, ::4], sub.shape).ravel()
    ok = np.isfinite(d)
    d, B = d[ok], B[ok]
    which = np.clip(np.searchsorted(np.quantile(B, np.linspace(0, 1, 17)), B, side="right") - 1, 0, 15)
    xs, ys, ws = [], [], []
    for i in range(16):
        di = d[which == i]
        if len(di) >= 500:
            xs.append(float(np.median(B[which == i])))
            ys.append((1.4826 * float(np.median(np.abs(di - np.median(di))))) ** 2)
            ws.append(math.sqrt(len(di)))
    if len(xs) >= 2:
        A = np.column_stack([np.ones(len(xs)), xs]) * np.asarray(ws)[:, None]
        a, b = np.linalg.lstsq(A, np.asarray(ys) * ws, rcond=None)[0]
        return bg, (max(float(a), 0.01), max(float(b), 0.0))
    return bg, (max(float(np.mean(ys)) if ys else 1.0, 0.01), 0.0)
