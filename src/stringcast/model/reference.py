"""Plain NumPy reference of the string model: one candidate, slow, readable.

The same equations as the numba kernels in ``kernels`` and ``lockstep`` (docs/string_model.md,
including the locally implicit bending damper documented in ``model``), written
with whole-array NumPy operations so they can be read against Table 1. Tests check
that the fast kernels agree with it (to ~1e-9 m on short runs).
"""
from __future__ import annotations

import numpy as np

from .kernels import DAMPING_SAFETY, TINY


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def hand_at(hand_t: np.ndarray, hand: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Hand pose (3,) and velocity (3,) at t: linear interpolation of the samples.

    The velocity is the slope of the sample interval [hand_t[k], hand_t[k+1]) holding t;
    outside [hand_t[0], hand_t[-1]) the end sample is held with zero velocity.
    """
    if t < hand_t[0] or len(hand_t) == 1:
        return hand[0].copy(), np.zeros(3)
    if t >= hand_t[-1]:
        return hand[-1].copy(), np.zeros(3)
    k = int(np.searchsorted(hand_t, t, side="right")) - 1
    h = hand_t[k + 1] - hand_t[k]
    w = (t - hand_t[k]) / h
    d = hand[k + 1] - hand[k]
    return hand[k] + w * d, d / h


def accelerations(p, v, hand_pose, hand_vel, coeffs, mu, l0, psi0, dt, g=9.81, drag="isotropic"):
    """Accelerations (n, 2) of points 1..n (Table 1), and the segment lengths (n,).

    p, v: (n, 2) positions m and velocities m/s; hand_pose (x, y, phi), hand_vel
    (vx, vy, dphi/dt); coeffs (10,) in ``config.PARAM_NAMES`` order; mu (n,); drag: "isotropic"
    (the paper's) or "normal" (on the velocity normal to the string, docs/string_model.md).
    """
    k_s, c_s, k_h, c_h, k_sh, c_sh, C1, C2, k_ph, c_ph = coeffs
    q = np.vstack([hand_pose[None, :2], p])          # p_0 .. p_n
    w = np.vstack([hand_vel[None, :2], v])
    seg = np.diff(q, axis=0)                          # segment s = 1..n: p_s - p_{s-1}
    l = np.linalg.norm(seg, axis=1)
    u = seg / l[:, None]
    nrm = np.stack([-u[:, 1], u[:, 0]], axis=1)
    dv = np.diff(w, axis=0)
    omega = _cross(u, dv) / l                         # segment angular velocity
    F = np.zeros_like(q)                              # row 0 (the hand) is discarded

    # elastic and damping along each segment
    fe = k_s * (l - l0) + c_s * np.sum(dv * u, axis=1)
    F[:-1] += fe[:, None] * u
    F[1:] -= fe[:, None] * u

    # bending at nodes i = 1..n-1 (between segments i and i+1)
    ua, ub = u[:-1], u[1:]
    theta = np.arctan2(_cross(ua, ub), np.sum(ua * ub, axis=1))
    dtheta = omega[1:] - omega[:-1]
    tension = 0.5 * (l[:-1] + l[1:]) >= l0
    kb = np.where(tension, k_sh, k_h)
    cb = np.where(tension, c_sh, c_h)
    inv_mu = np.r_[0.0, 1.0 / mu]                      # the hand does not move under forces
    ia, ib = 1.0 / l[:-1], 1.0 / l[1:]
    lam = ia ** 2 * inv_mu[:-2] + (ia + ib) ** 2 * inv_mu[1:-1] + ib ** 2 * inv_mu[2:]
    c_eff = cb / (1.0 + DAMPING_SAFETY * dt * cb * lam)  # locally implicit damper
    tau = -kb * theta - c_eff * dtheta
    f_next = (tau / l[1:])[:, None] * nrm[1:]         # on p_{i+1}
    f_prev = (tau / l[:-1])[:, None] * nrm[:-1]       # on p_{i-1}
    F[2:] += f_next
    F[:-2] += f_prev
    F[1:-1] -= f_next + f_prev

    # hand torsional spring on p_1
    th0 = np.arctan2(u[0, 1], u[0, 0]) - hand_pose[2] - psi0
    th0 = (th0 + np.pi) % (2 * np.pi) - np.pi
    tau0 = -k_ph * th0 - c_ph * (omega[0] - hand_vel[2])
    F[1] += tau0 / l[0] * nrm[0]

    # air resistance, then a = F / mu + g
    F = F[1:]
    if drag == "normal":                              # point s's tangent u_s + u_{s+1}, u_n at the tip
        t = u.copy()
        t[:-1] += u[1:]
        t /= np.sqrt(np.sum(t * t, axis=1) + TINY)[:, None]
        v = v - np.sum(v * t, axis=1)[:, None] * t
    speed = np.linalg.norm(v, axis=1)
    F -= (C1 + C2 * speed)[:, None] * v
    return F / mu[:, None] + np.array([0.0, -g]), l


def simulate_reference(coeffs, mu, hand_t, hand, p_init, l0, psi0, dt, sample_t, g=9.81,
                       max_stretch=3.0, drag="isotropic"):
    """One candidate, same contract as ``model.simulate``: returns pos (F, n, 2), ok."""
    coeffs, mu = np.asarray(coeffs, float), np.asarray(mu, float)
    hand_t, hand = np.asarray(hand_t, float), np.asarray(hand, float)
    sample_t = np.asarray(sample_t, float)
    p = np.array(p_init, float)
    v = np.zeros_like(p)
    out = np.full((len(sample_t), len(p), 2), np.nan)
    t0 = sample_t[0]
    f = int(np.searchsorted(sample_t, t0, side="right"))
    out[:f] = p
    m = 0
    while f < len(sample_t):
        pose, vel = hand_at(hand_t, hand, t0 + m * dt)
        a, l = accelerations(p, v, pose, vel, coeffs, mu, l0, psi0, dt, g, drag)
        if not np.all(l <= max_stretch * l0) or not np.all(l > 0):
            return out, False
        p_old = p
        v = v + a * dt
        p = p + v * dt
        m += 1
        t1 = t0 + m * dt
        while f < len(sample_t) and sample_t[f] <= t1:
            s = (sample_t[f] - (t1 - dt)) / dt
            out[f] = p_old + s * (p - p_old)
            f += 1
    return out, True
