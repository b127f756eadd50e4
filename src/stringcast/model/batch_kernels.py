"""Batch runs of the string model in lock-step blocks (docs/string_model.md); drivers in ``string_model``.

Candidates are run W at a time (:mod:`stringcast.model.lockstep`: one block, the candidate
index innermost, so each step is vectorised across candidates), blocks in parallel
(``prange``). A candidate's results are the one-candidate kernel's (:func:`kernels.step`
in a loop) bit for bit: each lane does the same arithmetic in the same order. A lane that
blows up keeps stepping (masked) until the block ends; its outputs are NaN / inf as
docs/string_model.md's "Blow-up" says. A block stops early once every lane blew up.

Everything here assumes inputs already checked by ``stringcast.model.string_model``.
numba keys the compiled code on this file's text alone; :func:`drop_stale_cache` deletes it
when ``lockstep`` or ``kernels``, inlined here, have changed.
"""
from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np
from numba import njit, prange

from stringcast.core import write_text

from . import kernels, lockstep
from .lockstep import LANES, OK, PX, PY, ROW, VX, VY, W, any_ok, new_block, set_hand, step_block

_U = np.uint64
_KERNEL = dict(cache=True, fastmath=False, error_model="numpy")


@njit(**_KERNEL)
def _samples_block(coeffs, mu, hand_t, hand, hand_idx, p_init, l0, psi0, dt, sample_t, g, lmax, normal,
                   b0, out, ok):
    """Candidates b0 .. b0 + W - 1 of :func:`simulate_batch_kernel`: writes out[b] (F, n, 2) and
    ok[b] for those in the batch.

    Each sample is on the line through the substeps around it, p(t) = p_new - (t_new - t)
    v_new (exact for semi-implicit Euler); samples from the step that finds a lane blown up
    on are NaN.
    """
    n = p_init.shape[1]
    F = sample_t.shape[0]
    nb = min(LANES, coeffs.shape[0] - b0)
    S, P, lanes = new_block(coeffs, mu, p_init, hand_idx, b0)
    lane_hand = hand_idx[lanes]
    t0 = sample_t[0]
    f = 0
    while f < F and sample_t[f] <= t0:
        for w in range(nb):
            out[b0 + w, f] = p_init[lane_hand[w]]
        f += 1
    m = 0
    k = 0
    while f < F and any_ok(P):
        k = set_hand(S, P, hand_t, hand, lane_hand, t0 + m * dt, k)
        step_block(S, P, n, l0, psi0, dt, g, lmax, normal)
        m += 1
        t1 = t0 + m * dt
        while f < F and sample_t[f] <= t1:
            back = t1 - sample_t[f]
            for w in range(nb):
                o = _U(w)
                if P[OK + o] == 0.0:
                    out[b0 + w, f] = np.nan
                    continue
                for r in range(n):
                    o += ROW
                    out[b0 + w, f, r, 0] = S[o + PX] - back * S[o + VX]
                    out[b0 + w, f, r, 1] = S[o + PY] - back * S[o + VY]
            f += 1
    for w in range(nb):
        out[b0 + w, f:] = np.nan
        ok[b0 + w] = P[OK + _U(w)] != 0.0


@njit(parallel=True, **_KERNEL)
def simulate_batch_kernel(coeffs, mu, hand_t, hand, hand_idx, p_init, l0, psi0, dt, sample_t, g, lmax, normal):
    """B candidates from sample_t[0] (at rest at p_init[hand_idx[b]]), sampled at sample_t.

    Parameters
    ----------
    coeffs : ndarray, (B, 10)
        Coefficients, ``config.PARAM_NAMES`` order, Table 2 units.
    mu : ndarray, (B, n)
        Relative masses.
    hand_t : ndarray, (K,)
        Hand sample times, s.
    hand : ndarray, (H, K, 3)
        Hand paths (x m, y m, phi rad).
    hand_idx : ndarray, (B,) int64
        Each candidate's hand path and initial state.
    p_init : ndarray, (H, n, 2)
        Initial positions at rest, m.
    l0, psi0, dt : float
        Rest segment length m, rest direction in the hand frame rad, step s.
    sample_t : ndarray, (F,)
        Sample times, s, non-decreasing; the run starts at sample_t[0].
    g, lmax : float
        Gravity m/s^2 along -y, blow-up segment length m.
    normal : float
        1.0: air drag on the velocity normal to the string; 0.0: on the whole velocity
        (:func:`stringcast.model.lockstep.step_block`).

    Returns
    -------
    pos : ndarray, (B, F, n, 2)
        Positions, m; NaN from the step a candidate blew up on.
    ok : ndarray, (B,) bool
    """
    B = coeffs.shape[0]
    out = np.empty((B, sample_t.shape[0], p_init.shape[1], 2))
    ok = np.zeros(B, dtype=np.bool_)
    for blk in prange((B + LANES - 1) // LANES):
        _samples_block(coeffs, mu, hand_t, hand, hand_idx, p_init, l0, psi0, dt, sample_t, g, lmax, normal,
                       blk * LANES, out, ok)
    return out, ok


# Per-lane state of a closest-approach block, Q (7 W,): field F of lane w is Q[F + w]: the
# tip at the previous step (AX, AY m), the target now (TX, TY m), d_min (DM m), t_min (TM s),
# min_y (MY m). One array, unsigned constant offsets: the lane loops vectorise (lockstep).
AX, AY, TX, TY, DM, TM, MY = (_U(i) * W for i in range(7))


@njit(inline="always", **_KERNEL)
def _set_targets(Q, targets, lane_target, target_dt, s):
    """Each lane's target (x, y) m at s s after t_start into Q's TX, TY.

    targets (P, S, 2) m sampled every target_dt s, lane_target (W,) int64 the path of each lane;
    linear between samples, held beyond them (S = 1: fixed)."""
    n_s = targets.shape[1]
    f = s / target_dt
    i = int(f) if n_s > 1 and f > 0.0 else 0
    if n_s == 1 or f <= 0.0 or i >= n_s - 1:
        e = 0 if (n_s == 1 or f <= 0.0) else n_s - 1
        for w in range(W):
            Q[TX + w] = targets[lane_target[w], e, 0]
            Q[TY + w] = targets[lane_target[w], e, 1]
        return
    a = f - i
    for w in range(W):
        p = lane_target[w]
        Q[TX + w] = targets[p, i, 0] + a * (targets[p, i + 1, 0] - targets[p, i, 0])
        Q[TY + w] = targets[p, i, 1] + a * (targets[p, i + 1, 1] - targets[p, i, 1])


@njit(inline="always", **_KERNEL)
def _approach(S, Q, tip, t, dt):
    """One tip-path segment per lane, from Q's AX, AY to the tip now (node offset tip of S):
    its distance to the target (TX, TY) lowers DM (and sets TM, s) where closer; then A = tip."""
    for w in range(W):
        ax = Q[AX + w]
        ay = Q[AY + w]
        bx = S[tip + PX + w]
        by = S[tip + PY + w]
        tx = Q[TX + w]
        ty = Q[TY + w]
        sx = bx - ax
        sy = by - ay
        s2 = sx * sx + sy * sy
        a = min(1.0, max(0.0, ((tx - ax) * sx + (ty - ay) * sy) / s2))
        a = a if s2 > 0.0 else 0.0
        d = math.sqrt((ax + a * sx - tx) ** 2 + (ay + a * sy - ty) ** 2)
        closer = d < Q[DM + w]
        t_hit, d_old = Q[TM + w], Q[DM + w]
        Q[TM + w] = t + a * dt if closer else t_hit
        Q[DM + w] = d if closer else d_old
        Q[AX + w] = bx
        Q[AY + w] = by


@njit(**_KERNEL)
def _closest_block(coeffs, mu, hand_t, hand, hand_idx, p_init, l0, psi0, dt, t_start, t_end,
                   targets, target_idx, target_dt, g, lmax, normal, b0, d_min, t_min, min_y, ok):
    """Candidates b0 .. b0 + W - 1 of :func:`closest_batch_kernel`: writes their d_min, t_min,
    min_y, ok. The tip path is the polyline through the substep tips; the distance is to each
    of its segments, from the target at the segment's end time."""
    n = p_init.shape[1]
    tip = _U(n) * ROW
    S, P, lanes = new_block(coeffs, mu, p_init, hand_idx, b0)
    lane_hand = hand_idx[lanes]
    lane_target = target_idx[lanes]
    Q = np.empty(7 * LANES)
    _set_targets(Q, targets, lane_target, target_dt, 0.0)
    for w in range(W):
        Q[AX + w] = S[tip + PX + w]
        Q[AY + w] = S[tip + PY + w]
        Q[DM + w] = math.sqrt((Q[AX + w] - Q[TX + w]) ** 2 + (Q[AY + w] - Q[TY + w]) ** 2)
        Q[TM + w] = t_start
        Q[MY + w] = S[ROW + PY + w]
        for r in range(2, n + 1):
            Q[MY + w] = min(Q[MY + w], S[_U(r) * ROW + PY + w])
    nsteps = int(math.ceil((t_end - t_start) / dt - 1e-9))
    k = 0
    for m in range(nsteps):
        if not any_ok(P):
            break
        t = t_start + m * dt
        k = set_hand(S, P, hand_t, hand, lane_hand, t, k)
        step_block(S, P, n, l0, psi0, dt, g, lmax, normal)
        _set_targets(Q, targets, lane_target, target_dt, (m + 1) * dt)
        _approach(S, Q, tip, t, dt)
        for r in range(_U(1), _U(n) + _U(1)):
            o = r * ROW + PY
            for w in range(W):
                y, y_min = S[o + w], Q[MY + w]
                Q[MY + w] = y if y < y_min else y_min
    for w in range(min(LANES, coeffs.shape[0] - b0)):
        u = _U(w)
        good = P[OK + u] != 0.0 and math.isfinite(Q[DM + u]) and math.isfinite(Q[MY + u])
        d_min[b0 + w] = Q[DM + u] if good else math.inf
        t_min[b0 + w] = Q[TM + u] if good else math.nan
        min_y[b0 + w] = Q[MY + u] if good else -math.inf
        ok[b0 + w] = good


@njit(parallel=True, **_KERNEL)
def closest_batch_kernel(coeffs, mu, hand_t, hand, hand_idx, p_init, l0, psi0, dt,
                         t_start, t_end, targets, target_idx, target_dt, g, lmax, normal):
    """Closest approach of B candidates' tip paths to their targets (docs/string_model.md, "Closest approach").

    Parameters
    ----------
    coeffs, mu, hand_t, hand, hand_idx, p_init, l0, psi0, dt, g, lmax, normal
        As :func:`simulate_batch_kernel`'s.
    t_start, t_end : float
        The run, s; it starts at rest at p_init.
    targets : ndarray, (P, S, 2)
        Target paths, m, sampled every target_dt s from t_start (S = 1: fixed).
    target_idx : ndarray, (B,) int64
        Each candidate's target path.
    target_dt : float
        s.

    Returns
    -------
    d_min, t_min, min_y : ndarray, (B,)
        Closest distance m and its time s, lowest y of any point over the run m; a blown-up
        candidate has (inf, NaN, -inf).
    ok : ndarray, (B,) bool
    """
    B = coeffs.shape[0]
    d_min = np.empty(B)
    t_min = np.empty(B)
    min_y = np.empty(B)
    ok = np.zeros(B, dtype=np.bool_)
    for blk in prange((B + LANES - 1) // LANES):
        _closest_block(coeffs, mu, hand_t, hand, hand_idx, p_init, l0, psi0, dt, t_start, t_end,
                       targets, target_idx, target_dt, g, lmax, normal, blk * LANES, d_min, t_min, min_y, ok)
    return d_min, t_min, min_y, ok


def drop_stale_cache(dispatcher, sources, name: str = "batch_kernels") -> bool:
    """Delete this file's cached kernels if the files they inline have changed since they were cached.

    numba keys a cached kernel on the text of the file that defines it (numba 0.68: its hash),
    so an edit of ``lockstep``'s step or of ``kernels``' helpers, inlined here, would leave the
    old compiled step running. The hash of ``sources`` is kept beside the cache (``<name>.inlined``);
    where it differs, every ``<name>.*.nbi``/``.nbc`` file there is deleted, and the kernels are
    compiled afresh on first use. Returns whether it deleted.

    Args:
        dispatcher: one of this file's cached kernels (its cache's folder is the one checked).
        sources: paths of the inlined files.
    """
    folder = getattr(getattr(dispatcher, "_cache", None), "_cache_path", None)
    if folder is None:
        return False
    digest = hashlib.sha256(b"".join(Path(p).read_bytes() for p in sources)).hexdigest()
    stamp = Path(folder) / f"{name}.inlined"
    try:
        if stamp.read_text() == digest:
            return False
    except OSError:
        pass
    for f in Path(folder).glob(f"{name}.*.nb[ic]"):
        f.unlink(missing_ok=True)
    try:
        write_text(stamp, digest)   # atomically: a job importing beside this one reads the old or the new stamp
    except OSError:
        pass
    return True


drop_stale_cache(simulate_batch_kernel, [lockstep.__file__, kernels.__file__])
