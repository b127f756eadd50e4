"""The string model (docs/string_model.md; paper Section IV.A, Tables 1-2), batched in numba.

A planar chain of n mass points p_1..p_n (p_n the tip) hangs from the grasp point
p_0, which the hand trajectory (x, y, phi_h) moves kinematically. Forces per
Table 1: axial spring-damper (k_s, c_s) per segment; bending spring-damper at each
node, (k_sh, c_sh) in tension and (k_h, c_h) in compression; a torsional
spring-damper (k_ph, c_ph) between the first segment and the hand; air drag
(C_c1, C_c2). Coefficients are per unit relative mass: a_i = F_i / mu_i + g, with
gravity g = (0, -9.81) m/s^2 added to every point whatever its mass. Integration:
semi-implicit Euler (v += a dt, then p += v dt), default dt = 1e-4 s.

Coefficient vector order: ``config.PARAM_NAMES`` =
(k_s, c_s, k_h, c_h, k_sh, c_sh, C_c1, C_c2, k_ph, c_ph).

Deviation from docs/string_model.md (documented here as it asks), with the reason:
the bending dampers (c_h, c_sh) are integrated *locally implicitly*. A node damper
pushes its three points along one direction a (forces +-(c / l) n), so it relaxes
at the rate c * lambda with lambda = sum_j |a_j|^2 / mu_j (~6 / (l0^2 mu)): up to
~1e6 1/s at Table 2's corner (c_h = 10, mu = 0.1, l0 = 30 mm), which no explicit
step of 1e-4 s survives (the plain scheme blows up there within a few ms). Each damper
uses c_eff = c / (1 + s dt c lambda), s = ``kernels.DAMPING_SAFETY`` = 2: backward
Euler for an isolated damper (s = 1), made safe for the three dampers a point
shares. c_eff -> c as dt -> 0, so the scheme converges to the same equations. The
relative change, s dt c lambda with mu = 1, l0 = 30 mm, is 1e-4 at c = 1e-4, 1 % at
c = 1e-2, and c_eff = 0.43 c at c = 1, where the damper's time constant is ~1.5 dt
and no first-order scheme resolves it anyway. All other terms are explicit.

Blow-up: a non-finite value or a segment longer than ``max_stretch`` * l0 (default
3) marks the candidate ok = False; the run stops there and never raises. With ``halvings`` = h > 0
(``model.blowup_halvings``) a blown-up candidate is run again at dt / 2, up to h times: an explicit
step too long for a stiff candidate blows it up though its equations do not (docs/method.md,
"Blow-ups of stiff strings"); a candidate that blows up at every step keeps ok = False.
"""
from __future__ import annotations

import math

import numpy as np

from stringcast.core import DRAG_LAWS

from . import batch_kernels as _bk

G = 9.81
"""Gravity, m/s^2 (acts along -y)."""

N_COEFFS = 10


def _f64(a, name, ndim=None, last=None) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=np.float64)
    if ndim is not None and a.ndim != ndim:
        raise ValueError(f"{name}: expected {ndim} dimensions, got shape {a.shape}")
    if last is not None and a.shape[-1] != last:
        raise ValueError(f"{name}: last dimension must be {last}, got shape {a.shape}")
    return a


def _batch(coeffs, mu, n: int) -> tuple[np.ndarray, np.ndarray]:
    """coeffs (10,) or (B, 10), mu (n,) or (B, n) -> both (B, ...), broadcast."""
    c = _f64(coeffs, "coeffs")
    m = _f64(mu, "mu")
    if c.shape[-1] != N_COEFFS or c.ndim not in (1, 2):
        raise ValueError(f"coeffs: expected (10,) or (B, 10), got shape {c.shape}")
    if m.shape[-1] != n or m.ndim not in (1, 2):
        raise ValueError(f"mu: expected ({n},) or (B, {n}), got shape {m.shape}")
    B = max(c.shape[0] if c.ndim == 2 else 1, m.shape[0] if m.ndim == 2 else 1)
    try:
        c = np.ascontiguousarray(np.broadcast_to(c, (B, N_COEFFS)))
        m = np.ascontiguousarray(np.broadcast_to(m, (B, n)))
    except ValueError as exc:
        raise ValueError(f"coeffs {c.shape} and mu {m.shape}: batch sizes differ") from exc
    if not np.all(np.isfinite(c)) or np.any(c < 0):
        raise ValueError("coeffs: must be finite and >= 0")
    if not np.all(np.isfinite(m)) or np.any(m <= 0):
        raise ValueError("mu: relative masses must be finite and > 0")
    return c, m


def _hands(hand_t, hand, hand_idx, p_init, B: int | None):
    ht = _f64(hand_t, "hand_t", 1)
    h = _f64(hand, "hand", 3, 3)
    p = _f64(p_init, "p_init", 3, 2)
    if len(ht) < 1 or h.shape[1] != len(ht):
        raise ValueError(f"hand: expected (H, K={len(ht)}, 3), got shape {h.shape}")
    if np.any(np.diff(ht) <= 0) or not np.all(np.isfinite(ht)) or not np.all(np.isfinite(h)):
        raise ValueError("hand_t must be finite and strictly increasing; hand must be finite")
    if p.shape[0] != h.shape[0]:
        raise ValueError(f"p_init: expected one initial state per hand trajectory "
                         f"({h.shape[0]}), got shape {p.shape}")
    if p.shape[1] < 2 or not np.all(np.isfinite(p)):
        raise ValueError(f"p_init: need n >= 2 finite points, got shape {p.shape}")
    idx = np.ascontiguousarray(hand_idx, dtype=np.int64)
    if idx.ndim != 1 or (B is not None and len(idx) != B):
        raise ValueError(f"hand_idx: expected ({B},), got shape {idx.shape}")
    if len(idx) and (idx.min() < 0 or idx.max() >= h.shape[0]):
        raise ValueError(f"hand_idx: values must be in [0, {h.shape[0]})")
    return ht, h, idx, p


def _scalars(l0, dt, max_stretch):
    if not (l0 > 0 and dt > 0 and max_stretch > 1) or not math.isfinite(l0 * dt * max_stretch):
        raise ValueError(f"need l0 > 0, dt > 0, max_stretch > 1 (got {l0}, {dt}, {max_stretch})")
    return float(l0), float(dt), float(max_stretch) * float(l0)


def simulate_batch(coeffs, mu, hand_t, hand, hand_idx, p_init, l0, psi0, dt, sample_t,
                   *, g: float = G, max_stretch: float = 3.0, drag: str = "isotropic", halvings: int = 0):
    """Simulate B candidates of the string model (docs/string_model.md, the paper's CG model) and sample
    them at given times.

    Parameters
    ----------
    coeffs : ndarray, (B, 10)
        Coefficients, ``config.PARAM_NAMES`` order (Table 2 units).
    mu : ndarray, (B, n)
        Relative masses of points 1..n.
    hand_t : ndarray, (K,)
        Strictly increasing sample times of the hand trajectories, s.
    hand : ndarray, (H, K, 3)
        Hand trajectories (x m, y m, phi_h rad); linearly interpolated at each substep, the first and
        last sample held outside ``hand_t``.
    hand_idx : ndarray of int, (B,)
        The hand trajectory candidate b uses.
    p_init : ndarray, (H, n, 2)
        Positions of points 1..n at rest (v = 0) at ``sample_t[0]``, m.
    l0 : float
        Rest segment length, m.
    psi0 : float
        Rest direction of the string in the hand frame, rad.
    dt : float
        Time step, s.
    sample_t : ndarray, (F,)
        Sample times, s, non-decreasing; the simulation starts at ``sample_t[0]``.
    g : float
        Gravity, m/s^2 along -y (0 for tests).
    max_stretch : float
        Blow-up threshold, segment length / l0.
    drag : {"isotropic", "normal"}
        The air drag on each point's whole velocity (the paper's model, the default here) or on its
        velocity normal to the string (``model.drag``, docs/string_model.md "Air drag").
    halvings : int
        A blown-up candidate runs again at half the step, up to this many times (module doc); 0: never.

    Returns
    -------
    pos : ndarray, (B, F, n, 2)
        Positions at ``sample_t``, m (linear between the substeps around each sample; NaN after a blow-up).
    ok : ndarray of bool, (B,)
        Whether each candidate stayed valid.

    Raises
    ------
    ValueError
        Inconsistent shapes, non-finite / negative inputs or an unknown ``drag`` (never for a blow-up,
        which gives ok = False).
    """
    n = np.shape(p_init)[-2] if np.ndim(p_init) == 3 else -1
    c, m = _batch(coeffs, mu, n)
    if np.ndim(coeffs) != 2 or np.ndim(mu) != 2:
        raise ValueError("simulate_batch: coeffs must be (B, 10) and mu (B, n)")
    ht, h, idx, p = _hands(hand_t, hand, hand_idx, p_init, c.shape[0])
    l0, dt, lmax = _scalars(l0, dt, max_stretch)
    st = _f64(sample_t, "sample_t", 1)
    if len(st) < 1 or np.any(np.diff(st) < 0) or not np.all(np.isfinite(st)):
        raise ValueError("sample_t: need >= 1 finite, non-decreasing times")
    def run(lanes, step):
        return _bk.simulate_batch_kernel(c[lanes], m[lanes], ht, h, idx[lanes], p, l0, float(psi0), step, st,
                                         float(g), lmax, _normal(drag))

    return _halve_blown(run, dt, halvings)


def simulate(coeffs, mu, hand_t, hand, p_init, l0, psi0, dt, sample_t, *, g: float = G,
             max_stretch: float = 3.0, drag: str = "isotropic", halvings: int = 0):
    """One candidate of :func:`simulate_batch`.

    Parameters
    ----------
    coeffs : ndarray, (10,)
        Coefficients, ``config.PARAM_NAMES`` order (Table 2 units).
    mu : ndarray, (n,)
        Relative masses of points 1..n.
    hand_t : ndarray, (K,)
        Hand sample times, s.
    hand : ndarray, (K, 3)
        The hand trajectory (x m, y m, phi_h rad).
    p_init : ndarray, (n, 2)
        Positions at rest at ``sample_t[0]``, m.
    l0, psi0, dt, sample_t, g, max_stretch, drag, halvings
        As in :func:`simulate_batch`.

    Returns
    -------
    pos : ndarray, (F, n, 2)
        Positions at ``sample_t``, m (NaN after a blow-up).
    ok : bool
        Whether the run stayed valid.

    Raises
    ------
    ValueError
        As :func:`simulate_batch`.
    """
    pos, ok = simulate_batch(np.atleast_2d(coeffs), np.atleast_2d(mu), hand_t,
                             np.asarray(hand, float)[None], np.zeros(1, np.int64),
                             np.asarray(p_init, float)[None], l0, psi0, dt, sample_t,
                             g=g, max_stretch=max_stretch, drag=drag, halvings=halvings)
    return pos[0], bool(ok[0])


def closest_approach_batch(coeffs, mu, hand_t, hand, hand_idx, p_init, l0, psi0, dt,
                           t_start, t_end, target_xy, floor_y=None, *, target_dt: float | None = None,
                           target_idx=None, g: float = G, max_stretch: float = 3.0, drag: str = "isotropic",
                           halvings: int = 0):
    """Closest approach of each candidate's tip path to a target (motion planning).

    Simulates from t_start (at rest at p_init) to t_end without storing the path.
    The distance is from the target to the segment between consecutive substep tip
    positions, so a fast tip cannot jump over the target.

    Parameters
    ----------
    coeffs : ndarray, (10,) or (B, 10)
        Coefficients (Table 2 units), broadcast to the batch.
    mu : ndarray, (n,) or (B, n)
        Relative masses, broadcast to the batch.
    hand_t, hand, hand_idx, p_init : ndarray, (K,), (H, K, 3), (B,) and (H, n, 2)
        As in :func:`simulate_batch`.
    l0, psi0, dt : float
        As in :func:`simulate_batch` (m, rad, s).
    t_start, t_end : float
        The run, s, t_start < t_end (at rest at ``p_init`` at t_start).
    target_xy : ndarray, (2,) or (P, S, 2)
        A fixed target, m; or moving targets sampled every ``target_dt`` s from t_start (linear between
        samples, held beyond them), candidate b taking path ``target_idx[b]`` (default 0): the
        residual-corrected target of :mod:`stringcast.plan.residual`.
    floor_y : float, optional
        Unused here (the caller compares min_y with it); kept for the API.
    target_dt : float, optional
        The moving targets' sample step, s.
    target_idx : ndarray of int, (B,), optional
        Each candidate's target path.
    g, max_stretch : float
        As in :func:`simulate_batch`.
    drag : {"isotropic", "normal"}, halvings : int
        As in :func:`simulate_batch`.

    Returns
    -------
    d_min : ndarray, (B,)
        Closest approach, m (inf for a blown-up candidate).
    t_min : ndarray, (B,)
        Its time, s (NaN for a blown-up candidate).
    min_y : ndarray, (B,)
        Lowest y of any point 1..n over the run, m (-inf for a blown-up candidate).
    ok : ndarray of bool, (B,)
        Whether each candidate stayed valid.

    Raises
    ------
    ValueError
        Inconsistent shapes, non-finite targets, or a moving target without ``target_dt`` > 0.
    """
    n = np.shape(p_init)[-2] if np.ndim(p_init) == 3 else -1
    B = len(np.atleast_1d(hand_idx))
    c, m = _batch(coeffs, mu, n)
    if c.shape[0] == 1 and B > 1:
        c = np.ascontiguousarray(np.broadcast_to(c, (B, N_COEFFS)))
        m = np.ascontiguousarray(np.broadcast_to(m, (B, n)))
    ht, h, idx, p = _hands(hand_t, hand, np.atleast_1d(hand_idx), p_init, c.shape[0])
    l0, dt, lmax = _scalars(l0, dt, max_stretch)
    targets, tidx, tdt = _targets(target_xy, target_dt, target_idx, B)
    if not (math.isfinite(t_start) and math.isfinite(t_end) and t_end > t_start):
        raise ValueError(f"need finite t_start < t_end (got {t_start}, {t_end})")
    def run(lanes, step):
        return _bk.closest_batch_kernel(c[lanes], m[lanes], ht, h, idx[lanes], p, l0, float(psi0), step,
                                        float(t_start), float(t_end), targets, tidx[lanes], tdt, float(g), lmax,
                                        _normal(drag))

    return _halve_blown(run, dt, halvings)


def _halve_blown(run, dt: float, halvings: int) -> tuple:
    """``run(lanes, dt)`` -> a kernel's outputs for those lanes, ok last; every lane at dt (a slice: the
    inputs as views, no copy), then the blown-up ones again at dt / 2, up to ``halvings`` times (module
    doc). Returns the outputs (B, ...)."""
    if isinstance(halvings, bool) or not isinstance(halvings, (int, np.integer)) or halvings < 0:
        raise ValueError(f"halvings: expected an int >= 0, got {halvings!r}")
    outs = run(slice(None), dt)
    for _ in range(int(halvings)):
        blown = np.flatnonzero(~np.asarray(outs[-1], bool))
        if not len(blown):
            break
        dt = dt / 2
        for out, again in zip(outs, run(blown, dt)):
            out[blown] = again
    return outs


def _normal(drag: str) -> float:
    """The kernels' ``normal`` flag of a drag law (:data:`stringcast.core.DRAG_LAWS`): 1.0 normal, 0.0 isotropic."""
    if drag not in DRAG_LAWS:
        raise ValueError(f"drag: {drag!r} is not one of {', '.join(DRAG_LAWS)}")
    return 1.0 if drag == "normal" else 0.0


def _targets(target_xy, target_dt, target_idx, B: int):
    """target_xy (2,) or (P, S, 2) -> targets (P, S, 2), target_idx (B,), target_dt (checked)."""
    t = _f64(target_xy, "target_xy")
    if t.ndim == 1:
        t = _f64(t, "target_xy", 1, 2)[None, None]
    if t.ndim != 3 or t.shape[-1] != 2 or t.shape[0] < 1 or t.shape[1] < 1:
        raise ValueError(f"target_xy: expected (2,) or (P, S, 2), got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError("target_xy: must be finite")
    tdt = 1.0 if target_dt is None else float(target_dt)
    if t.shape[1] > 1 and not (target_dt is not None and math.isfinite(tdt) and tdt > 0):
        raise ValueError("target_dt: a moving target (S > 1 samples) needs target_dt > 0")
    idx = np.zeros(B, np.int64) if target_idx is None else np.ascontiguousarray(target_idx, dtype=np.int64)
    if idx.shape != (B,) or (B and (idx.min() < 0 or idx.max() >= t.shape[0])):
        raise ValueError(f"target_idx: expected ({B},) values in [0, {t.shape[0]}), got {idx}")
    return t, idx, tdt
