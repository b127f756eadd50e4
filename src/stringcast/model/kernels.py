"""One-candidate numba kernels of the string model (docs/string_model.md); drivers in ``string_model``.

Layout: one candidate's state is held in six 1-D arrays (structure of arrays)
``px, py, vx, vy`` (n,) and the force scratch ``fx, fy`` (n,), index j = point j+1.
:func:`step` advances one candidate by one semi-implicit Euler step; :func:`settle` runs it
for the hanging equilibrium. Batches run in lock-step blocks instead
(:mod:`stringcast.model.lockstep`, :mod:`stringcast.model.batch_kernels`), whose lanes do
:func:`step`'s arithmetic in the same order: the tests hold them to it bit for bit.

Everything here assumes inputs already checked by ``stringcast.model.string_model``.
"""
from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

DAMPING_SAFETY = 2.0
"""Safety factor s of the locally implicit bending damper, c_eff = c / (1 + s dt c lambda).

Each point takes part in at most three bending dampers, so the explicit update with
c_eff has a velocity-decay factor below 3 / s < 2 per step: stable for any c."""

TWO_PI = 2.0 * math.pi
TINY = 1e-300
"""Added to |u_s + u_{s+1}|^2 before its square root: a string folded back on itself at a node
(u_{s+1} = -u_s) gets a zero tangent there, so isotropic drag, instead of a division by zero."""



@intrinsic
def fma(typingctx, a, b, c):
    """a * b + c in float64, rounded once: LLVM's ``llvm.fma.f64`` (the CPU's fused multiply-add,
    or an exact library call where it has none), so every machine gives the same bits, scalar and
    vectorised alike. The kernels write each fused product out (never ``fastmath``), in the same
    places in :func:`step` and the lock-step block; 15-20 % of a step's time on AVX2."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        f64 = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [f64], ir.FunctionType(f64, [f64, f64, f64]))
        return builder.call(fn, args)

    return sig, codegen


# Cephes atan (S. L. Moshier, Cephes Math Library, atan.c): rational P/Q on [0, 0.66]
_P = (-8.750608600031904122785e-1, -1.615753718733365076637e1, -7.500855792314704667340e1,
      -1.228866684490136173410e2, -6.485021904942025371773e1)
_Q = (2.485846490142306297962e1, 1.650270098316988542046e2, 4.328810604912902668951e2,
      4.853903996359136964868e2, 1.945506571482613964425e2)
_MOREBITS = 6.123233995736765886130e-17


@njit(cache=True, fastmath=False)
def atan2(y, x):
    """atan2(y, x) in [-pi, pi], within ~1 ulp of libm's (``math.atan2``, signed zeros too).

    Source: Cephes' ``atan`` (range reduction to |r| <= 0.66 via (r - 1)/(r + 1), then
    r + r^3 P(r^2)/Q(r^2)), applied to r = min(|x|,|y|)/max(|x|,|y|) with the quadrant
    restored afterwards; the reduced argument is formed in one division, (min - max)/(min + max),
    and the polynomials by :func:`fma`. The bending angle needs one per node per step; libm's
    atan2 took ~40 % of a step here.
    """
    ax = abs(x)
    ay = abs(y)
    if ax == 0.0 and ay == 0.0 or not (ax < math.inf and ay < math.inf):
        return math.atan2(y, x)
    swap = ay > ax
    num = ax if swap else ay
    den = ay if swap else ax
    off = 0.0
    extra = 0.0
    if num > 0.66 * den:
        off = 0.25 * math.pi
        extra = 0.5 * _MOREBITS
        r = (num - den) / (num + den)
    else:
        r = num / den
    z = r * r
    p = fma(fma(fma(fma(_P[0], z, _P[1]), z, _P[2]), z, _P[3]), z, _P[4])
    q = fma(fma(fma(fma(z + _Q[0], z, _Q[1]), z, _Q[2]), z, _Q[3]), z, _Q[4])
    a = off + (fma(r * z, p / q, r) + extra)
    if swap:
        a = 0.5 * math.pi - a
    if x < 0.0 or (x == 0.0 and math.copysign(1.0, x) < 0.0):
        a = math.pi - a
    return math.copysign(a, y)


@njit(cache=True, fastmath=False)
def step(px, py, vx, vy, fx, fy, sux, suy, hx, hy, hvx, hvy, phi, dphi, c, inv_mu,
         l0, psi0, dt, g, lmax, relax, normal):
    """One semi-implicit Euler step of one candidate (docs/string_model.md, Table 1).

    Forces use the state at time t and the hand (hx, hy, phi) with velocity (hvx, hvy, dphi) at t;
    then v += a dt, p += v dt in place. ``relax`` (1/s) adds a mass-proportional damping -relax * v
    to the acceleration (0 in normal runs; used by the equilibrium settling, where it does not change
    the rest state). ``normal`` 1.0: the air drag acts on each point's velocity normal to the string
    (its tangent u_s + u_{s+1}, u_n at the tip; ``model.drag: normal``), 0.0: on the whole velocity
    (``isotropic``, the paper's). ``sux``, ``suy`` (n,) are work arrays (the segments' unit vectors),
    the caller's so that a step allocates nothing. Returns False if a segment is longer than lmax or
    not finite (blow-up).
    """
    n = px.shape[0]
    k_s = c[0]
    c_s = c[1]
    k_h = c[2]
    c_h = c[3]
    k_sh = c[4]
    c_sh = c[5]
    C1 = c[6]
    C2 = c[7]
    k_ph = c[8]
    c_ph = c[9]
    ok = True
    qx = hx
    qy = hy
    qvx = hvx
    qvy = hvy
    pux = 0.0
    puy = 0.0
    pl = 0.0
    pil = 0.0
    pom = 0.0
    for j in range(n):
        # segment s = j + 1 from p_{s-1} (q) to p_s
        dx = px[j] - qx
        dy = py[j] - qy
        l = math.sqrt(fma(dx, dx, dy * dy))
        if not (l <= lmax and l > 0.0):
            ok = False
        il = 1.0 / l
        ux = dx * il
        uy = dy * il
        sux[j] = ux
        suy[j] = uy
        dvx = vx[j] - qvx
        dvy = vy[j] - qvy
        om = fma(ux, dvy, -(uy * dvx)) * il
        fe = fma(k_s, l - l0, c_s * fma(ux, dvx, uy * dvy))
        fx[j] = -fe * ux
        fy[j] = -fe * uy
        if j == 0:
            # hand torsional spring on p_1
            th0 = atan2(uy, ux) - phi - psi0
            th0 = fma(-TWO_PI, math.floor((th0 + math.pi) / TWO_PI), th0)
            tau0 = fma(-k_ph, th0, -(c_ph * (om - dphi)))
            fx[0] = fma(-tau0 * il, uy, fx[0])
            fy[0] = fma(tau0 * il, ux, fy[0])
        else:
            # bending at node i = j between segments i (previous) and i + 1 (this one)
            th = atan2(fma(pux, uy, -(puy * ux)), fma(pux, ux, puy * uy))
            if 0.5 * (pl + l) >= l0:
                kb = k_sh
                cb = c_sh
            else:
                kb = k_h
                cb = c_h
            ac = pil + il
            lam = fma(ac * ac, inv_mu[j - 1], il * il * inv_mu[j])
            if j >= 2:
                lam = fma(pil * pil, inv_mu[j - 2], lam)
            ceff = cb / fma(DAMPING_SAFETY * dt * cb, lam, 1.0)
            tau = fma(-kb, th, -(ceff * (om - pom)))
            f1x = -tau * il * uy
            f1y = tau * il * ux
            f2x = -tau * pil * puy
            f2y = tau * pil * pux
            fx[j] += f1x
            fy[j] += f1y
            fx[j - 1] = fma(fe, ux, fx[j - 1]) - (f1x + f2x)
            fy[j - 1] = fma(fe, uy, fy[j - 1]) - (f1y + f2y)
            if j >= 2:
                fx[j - 2] += f2x
                fy[j - 2] += f2y
        qx = px[j]
        qy = py[j]
        qvx = vx[j]
        qvy = vy[j]
        pux = ux
        puy = uy
        pl = l
        pil = il
        pom = om
    _drag_and_move(px, py, vx, vy, fx, fy, sux, suy, C1, C2, inv_mu, dt, g, relax, normal)
    return ok


@njit(cache=True, fastmath=False, inline="always")
def _drag_and_move(px, py, vx, vy, fx, fy, sux, suy, C1, C2, inv_mu, dt, g, relax, normal):
    """:func:`step`'s second half: each point's air drag C1 + C2 |v_n| on its (normal) velocity, then
    a = (f - drag) / mu - relax v - g, v += a dt, p += v dt in place (arrays (n,), as in :func:`step`)."""
    n = px.shape[0]
    for j in range(n):
        nxt = 1.0 if j + 1 < n else 0.0      # point j's tangent u_j + u_{j+1} (u_n at the tip)
        jn = j + 1 if j + 1 < n else j
        tx = fma(nxt, sux[jn], sux[j])
        ty = fma(nxt, suy[jn], suy[j])
        it = normal / math.sqrt(fma(tx, tx, fma(ty, ty, TINY)))
        tx *= it
        ty *= it
        vt = fma(vx[j], tx, vy[j] * ty)      # normal = 0: vt = 0, the drag on the whole v
        nx = fma(-vt, tx, vx[j])
        ny = fma(-vt, ty, vy[j])
        d = fma(C2, math.sqrt(fma(nx, nx, ny * ny)), C1)
        ax = fma(-d, nx, fx[j]) * inv_mu[j] - relax * vx[j]
        ay = fma(-d, ny, fy[j]) * inv_mu[j] - relax * vy[j] - g
        vx[j] = fma(ax, dt, vx[j])
        vy[j] = fma(ay, dt, vy[j])
        px[j] = fma(vx[j], dt, px[j])
        py[j] = fma(vy[j], dt, py[j])


@njit(cache=True, fastmath=False)
def _state(p_init):
    """Work arrays of one simulation: positions px, py (n,) from p_init (n, 2) at rest
    (vx = vy = 0), force buffers fx, fy (n,) and segment unit vectors sux, suy (n,)."""
    n = p_init.shape[0]
    px = np.empty(n)
    py = np.empty(n)
    for j in range(n):
        px[j] = p_init[j, 0]
        py[j] = p_init[j, 1]
    return px, py, np.zeros(n), np.zeros(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)


@njit(cache=True, fastmath=False)
def settle(c, mu, hand_pose, p_init, l0, psi0, dt, g, lmax, relax, tol, t_max, check_every):
    """Relax one candidate hanging from a fixed hand until it is at rest.

    At rest: every speed < tol and every acceleration < tol * max(relax, 1) (so the
    speeds would stay below ~tol over the next 1 / relax seconds), checked every
    ``check_every`` steps. Returns (positions (n, 2), status): 0 settled, 1 blow-up,
    2 t_max reached.
    """
    n = p_init.shape[0]
    px, py, vx, vy, fx, fy, sux, suy = _state(p_init)
    wx = np.empty(n)
    wy = np.empty(n)
    inv_mu = 1.0 / mu
    out = np.empty((n, 2))
    nsteps = int(math.ceil(t_max / dt))
    a_tol = tol * max(relax, 1.0)
    status = 2
    for m in range(nsteps):
        check = (m + 1) % check_every == 0
        if check:
            wx[:] = vx
            wy[:] = vy
        ok = step(px, py, vx, vy, fx, fy, sux, suy, hand_pose[0], hand_pose[1], 0.0, 0.0,
                  hand_pose[2], 0.0, c, inv_mu, l0, psi0, dt, g, lmax, relax, 0.0)  # at rest: no drag either way
        if not ok:
            status = 1
            break
        if check:
            vmax = 0.0
            amax = 0.0
            for j in range(n):
                vmax = max(vmax, math.sqrt(vx[j] * vx[j] + vy[j] * vy[j]))
                amax = max(amax, math.sqrt((vx[j] - wx[j]) ** 2 + (vy[j] - wy[j]) ** 2) / dt)
            if vmax < tol and amax < a_tol:
                status = 0
                break
    for j in range(n):
        out[j, 0] = px[j]
        out[j, 1] = py[j]
    return out, status
