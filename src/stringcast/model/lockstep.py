"""One lock-step step of the string model for a block of W candidates, the candidate innermost.

Source: docs/string_model.md (Table 1, "Integration", "Blow-up"). The arithmetic, and its
order, is :func:`stringcast.model.kernels.step`'s (with relax = 0), lane by lane, so a lane
gives the one-candidate kernel's numbers bit for bit; the batch runs that drive it are in
:mod:`stringcast.model.batch_kernels`.

Layout (structure of arrays): a block is two flat float64 arrays, the lane (candidate)
index last and contiguous. ``S`` ((n + 1) * ROW,): field F of node r in lane w is
``S[r * ROW + F + w]``; node 0 is the hand (p_0: its position and velocity are the hand's,
its force field takes the forces the kinematic hand drops, its 1/mu is 0), nodes 1..n the
mass points. Fields: position PX, PY (m), velocity VX, VY (m/s), force FX, FY (per kg:
N/kg), IMU = 1/mu, and of segment r (node r - 1 to r) the unit vector UX, UY, length LEN
(m), 1/length IL (1/m) and angular velocity OM (rad/s). ``P`` (NP * W,): coefficient i of
lane w (``config.PARAM_NAMES`` order, Table 2 units) is ``P[i * W + w]``, then the hand's
angle PHI (rad) and angular velocity DPHI (rad/s) at this step and the lane's OK flag
(1.0, or 0.0 once it blew up).

Every loop over lanes is branch-free (selects), so LLVM vectorises it across candidates
(``kernels.inspect_asm`` shows packed ``vdivpd``/``vsqrtpd``/``vmulpd`` on zmm registers on
an AVX-512 host). Offsets are unsigned (``numpy.uint64``): numba then indexes without the
negative-index wraparound select, which hid the offsets' constant differences from LLVM's
dependence analysis and left the lane loops scalar. Division by zero gives inf/NaN
(``error_model="numpy"``) instead of an exception, which would branch out of the loop.
A lane that blows up is marked and keeps stepping on its own inf/NaN values, which never
reach the other lanes.

Numba's cache (``cache=True``) keys a function on its own file's text only: the batch runs
in ``batch_kernels`` inline this module's functions, and ``batch_kernels.drop_stale_cache``
deletes their cached code when this file (or ``kernels``) has changed.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .kernels import DAMPING_SAFETY, TINY, TWO_PI, fma

_U = np.uint64
LANES = 16
"""Candidates per block: two AVX-512 registers of float64. LLVM vectorises a loop that needs a
runtime alias check (S against P) only from 16 iterations on; at 8 the lane loops stayed scalar."""
W = _U(LANES)

PX, PY, VX, VY, FX, FY, IMU, UX, UY, LEN, IL, OM = (_U(i) * W for i in range(12))
ROW = _U(12) * W
K_S, C_S, K_H, C_H, K_SH, C_SH, C_C1, C_C2, K_PH, C_PH, PHI, DPHI, OK = (_U(i) * W for i in range(13))
NP = 13
_1 = _U(1)
_2 = _U(2)

# Cephes atan (S. L. Moshier, Cephes Math Library, atan.c), as in kernels.atan2
_P0, _P1, _P2, _P3, _P4 = (-8.750608600031904122785e-1, -1.615753718733365076637e1,
                           -7.500855792314704667340e1, -1.228866684490136173410e2,
                           -6.485021904942025371773e1)
_Q0, _Q1, _Q2, _Q3, _Q4 = (2.485846490142306297962e1, 1.650270098316988542046e2,
                           4.328810604912902668951e2, 4.853903996359136964868e2,
                           1.945506571482613964425e2)
_MOREBITS = 6.123233995736765886130e-17
_QUARTER_PI = 0.25 * math.pi
_HALF_PI = 0.5 * math.pi

_KERNEL = dict(cache=True, fastmath=False, error_model="numpy")


@njit(inline="always", **_KERNEL)
def atan2_lane(y, x):
    """atan2(y, x) in rad without branches: :func:`kernels.atan2` bit for bit for finite (y, x) != (0, 0).

    The same Cephes steps written as selects, so a loop over lanes vectorises. Non-finite
    arguments or (0, 0) give NaN or a meaningless angle: only a blown-up lane, already
    marked, passes them.
    """
    ax = abs(x)
    ay = abs(y)
    swap = ay > ax
    num = ax if swap else ay
    den = ay if swap else ax
    big = num > 0.66 * den
    r = (num - den if big else num) / (num + den if big else den)
    off = _QUARTER_PI if big else 0.0
    extra = 0.5 * _MOREBITS if big else 0.0
    z = r * r
    p = fma(fma(fma(fma(_P0, z, _P1), z, _P2), z, _P3), z, _P4)
    q = fma(fma(fma(fma(z + _Q0, z, _Q1), z, _Q2), z, _Q3), z, _Q4)
    a = off + (fma(r * z, p / q, r) + extra)
    a = _HALF_PI - a if swap else a
    a = math.pi - a if math.copysign(1.0, x) < 0.0 else a
    return math.copysign(a, y)


@njit(inline="always", **_KERNEL)
def _segment(S, P, o, w, lmax, l0):
    """Segment ending at node offset o (= r * ROW), lane w: stores UX, UY, LEN, IL, OM, clears P's
    OK flag on a blow-up (length > lmax m, 0 or not finite); returns (ux, uy, l, il, om, fe)."""
    q = o - ROW
    dx = S[o + PX + w] - S[q + PX + w]
    dy = S[o + PY + w] - S[q + PY + w]
    l = math.sqrt(fma(dx, dx, dy * dy))
    good = (l <= lmax) & (l > 0.0)
    P[OK + w] *= 1.0 if good else 0.0          # the flag stays exactly 1.0 or 0.0
    il = 1.0 / l
    ux = dx * il
    uy = dy * il
    dvx = S[o + VX + w] - S[q + VX + w]
    dvy = S[o + VY + w] - S[q + VY + w]
    om = fma(ux, dvy, -(uy * dvx)) * il
    fe = fma(P[K_S + w], l - l0, P[C_S + w] * fma(ux, dvx, uy * dvy))
    S[o + UX + w] = ux
    S[o + UY + w] = uy
    S[o + LEN + w] = l
    S[o + IL + w] = il
    S[o + OM + w] = om
    return ux, uy, l, il, om, fe


@njit(inline="always", **_KERNEL)
def step_block(S, P, n, l0, psi0, dt, g, lmax, normal):
    """One semi-implicit Euler step of a block (docs/string_model.md, Table 1, "Integration").

    Forces use the state at t; then v += a dt, p += v dt in place (nodes 1..n).

    Parameters
    ----------
    S : ndarray, ((n + 1) * ROW,) float64
        The block's state (module docstring); node 0 must hold each lane's hand at t.
    P : ndarray, (NP * W,) float64
        Coefficients; PHI, DPHI must hold the hand's angle (rad) and rate (rad/s) at t.
        A lane whose segments had blown up before the step gets OK = 0.
    n : int
        Mass points.
    l0, psi0, dt, g, lmax : float
        Rest segment length m, rest direction in the hand frame rad, step s, gravity
        m/s^2 along -y, blow-up length m.
    normal : float
        1.0: air drag on each point's velocity normal to the string (``model.drag: normal``);
        0.0: on its whole velocity (``isotropic``, the paper's). docs/string_model.md, "Air drag".
    """
    sdt = DAMPING_SAFETY * dt
    o = ROW
    for w in range(W):                          # segment 1 and the hand spring
        ux, uy, l, il, om, fe = _segment(S, P, o, w, lmax, l0)
        th0 = atan2_lane(uy, ux) - P[PHI + w] - psi0
        th0 = fma(-TWO_PI, math.floor((th0 + math.pi) / TWO_PI), th0)
        tau0 = fma(-P[K_PH + w], th0, -(P[C_PH + w] * (om - P[DPHI + w])))
        S[o + FX + w] = fma(-tau0 * il, uy, -fe * ux)
        S[o + FY + w] = fma(tau0 * il, ux, -fe * uy)
    for s in range(_2, _U(n) + _1):             # segment s and the bending at node s - 1
        o = s * ROW
        q = o - ROW
        qq = q - ROW
        for w in range(W):
            ux, uy, l, il, om, fe = _segment(S, P, o, w, lmax, l0)
            pux = S[q + UX + w]
            puy = S[q + UY + w]
            pil = S[q + IL + w]
            th = atan2_lane(fma(pux, uy, -(puy * ux)), fma(pux, ux, puy * uy))
            tension = 0.5 * (S[q + LEN + w] + l) >= l0
            k_h, c_h, k_sh, c_sh = P[K_H + w], P[C_H + w], P[K_SH + w], P[C_SH + w]
            kb = k_sh if tension else k_h
            cb = c_sh if tension else c_h
            ac = pil + il                       # node 0's 1/mu is 0: lam's last term vanishes at s = 2
            lam = fma(pil * pil, S[qq + IMU + w], fma(ac * ac, S[q + IMU + w], il * il * S[o + IMU + w]))
            ceff = cb / fma(sdt * cb, lam, 1.0)  # the locally implicit damper
            tau = fma(-kb, th, -(ceff * (om - S[q + OM + w])))
            f1x = -tau * il * uy
            f1y = tau * il * ux
            f2x = -tau * pil * puy
            f2y = tau * pil * pux
            S[o + FX + w] = -fe * ux + f1x
            S[o + FY + w] = -fe * uy + f1y
            S[q + FX + w] = fma(fe, ux, S[q + FX + w]) - (f1x + f2x)
            S[q + FY + w] = fma(fe, uy, S[q + FY + w]) - (f1y + f2y)
            S[qq + FX + w] += f2x
            S[qq + FY + w] += f2y
    for s in range(_1, _U(n) + _1):             # drag, v += a dt, p += v dt
        o = s * ROW
        nxt = 1.0 if s < _U(n) else 0.0         # node s's tangent: u_s + u_{s+1} (u_n at the tip)
        on = o + ROW if s < _U(n) else o
        for w in range(W):
            vx = S[o + VX + w]
            vy = S[o + VY + w]
            tx = fma(nxt, S[on + UX + w], S[o + UX + w])
            ty = fma(nxt, S[on + UY + w], S[o + UY + w])
            it = normal / math.sqrt(fma(tx, tx, fma(ty, ty, TINY)))
            tx *= it
            ty *= it
            vt = fma(vx, tx, vy * ty)           # normal = 0: vt = 0, the drag on the whole v
            nx = fma(-vt, tx, vx)
            ny = fma(-vt, ty, vy)
            d = fma(P[C_C2 + w], math.sqrt(fma(nx, nx, ny * ny)), P[C_C1 + w])
            vx = fma(fma(-d, nx, S[o + FX + w]) * S[o + IMU + w], dt, vx)
            vy = fma(fma(-d, ny, S[o + FY + w]) * S[o + IMU + w] - g, dt, vy)
            S[o + VX + w] = vx
            S[o + VY + w] = vy
            S[o + PX + w] = fma(vx, dt, S[o + PX + w])
            S[o + PY + w] = fma(vy, dt, S[o + PY + w])


@njit(**_KERNEL)
def new_block(coeffs, mu, p_init, hand_idx, b0):
    """A block for candidates b0 .. b0 + W - 1 (lanes past the batch repeat its last candidate).

    Parameters
    ----------
    coeffs : ndarray, (B, 10)
        Coefficients, ``config.PARAM_NAMES`` order, Table 2 units.
    mu : ndarray, (B, n)
        Relative masses.
    p_init : ndarray, (H, n, 2)
        Initial positions, m, one per hand path.
    hand_idx : ndarray, (B,) int64
        The hand path (and p_init) of each candidate.
    b0 : int
        The block's first candidate.

    Returns
    -------
    S, P : ndarray
        The block (module docstring), at rest at p_init[hand_idx[b]], every OK = 1; node 0
        (the hand) is left at 0 for :func:`set_hand`.
    lanes : ndarray, (W,) int64
        Each lane's candidate b.
    """
    B = coeffs.shape[0]
    n = p_init.shape[1]
    S = np.zeros((n + 1) * LANES * 12)
    P = np.zeros(NP * LANES)
    lanes = np.empty(LANES, np.int64)
    for w in range(W):
        b = min(b0 + np.int64(w), B - 1)
        lanes[w] = b
        for i in range(10):
            P[_U(i) * W + w] = coeffs[b, i]
        P[OK + w] = 1.0
        for r in range(1, n + 1):
            o = _U(r) * ROW + w
            S[o + PX] = p_init[hand_idx[b], r - 1, 0]
            S[o + PY] = p_init[hand_idx[b], r - 1, 1]
            S[o + IMU] = 1.0 / mu[b, r - 1]
    return S, P, lanes


@njit(inline="always", **_KERNEL)
def set_hand(S, P, hand_t, hand, lane_hand, t, k):
    """Each lane's hand at time t into node 0 of S and P's PHI, DPHI (docs/string_model.md, "Frame").

    Linear interpolation of the samples; the velocity is the slope of the sample interval
    holding t; before the first and from the last sample the end pose is held, at rest.

    Parameters
    ----------
    S, P : ndarray
        The block (module docstring), written in place.
    hand_t : ndarray, (K,)
        Sample times, s, strictly increasing; shared by all lanes, so is the interval.
    hand : ndarray, (H, K, 3)
        Hand paths (x m, y m, phi rad).
    lane_hand : ndarray, (W,) int64
        Each lane's hand path.
    t : float
        Time, s.
    k : int
        The sample interval of the previous call (time only moves forward); 0 at first.

    Returns
    -------
    int
        The interval index for the next call.
    """
    K = hand_t.shape[0]
    if t < hand_t[0] or K == 1 or t >= hand_t[K - 1]:
        e = 0 if (t < hand_t[0] or K == 1) else K - 1
        for w in range(W):
            h = lane_hand[w]
            S[PX + w] = hand[h, e, 0]
            S[PY + w] = hand[h, e, 1]
            P[PHI + w] = hand[h, e, 2]
            S[VX + w] = 0.0
            S[VY + w] = 0.0
            P[DPHI + w] = 0.0
        return 0 if e == 0 else K - 2
    while hand_t[k + 1] <= t:
        k += 1
    h_dt = hand_t[k + 1] - hand_t[k]
    a = (t - hand_t[k]) / h_dt
    for w in range(W):
        h = lane_hand[w]
        dx = hand[h, k + 1, 0] - hand[h, k, 0]
        dy = hand[h, k + 1, 1] - hand[h, k, 1]
        dp = hand[h, k + 1, 2] - hand[h, k, 2]
        S[PX + w] = hand[h, k, 0] + a * dx
        S[PY + w] = hand[h, k, 1] + a * dy
        P[PHI + w] = hand[h, k, 2] + a * dp
        S[VX + w] = dx / h_dt
        S[VY + w] = dy / h_dt
        P[DPHI + w] = dp / h_dt
    return k


@njit(**_KERNEL)
def any_ok(P):
    """Whether any lane of the block is still valid."""
    for w in range(W):
        if P[OK + w] != 0.0:
            return True
    return False
