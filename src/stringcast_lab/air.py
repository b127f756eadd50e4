"""Air drag on a string: the standard cable (Morison-type) model, compiled with numba.

On a cylinder element (diameter d, length l, axis a) moving at v through still
air of density rho and kinematic viscosity nu:

* normal drag   f_n = -0.5 rho C_n(Re) d l |v_n| v_n,  C_n = 1 + 10 Re^(-2/3)
  (F. M. White, *Viscous Fluid Flow*: cylinder in cross-flow, 1 < Re < 2e5,
  Re = |v_n| d / nu);
* tangential skin friction  f_t = -0.5 rho C_f pi d l |v_t| v_t (C_f = 0.02).

On a sphere (a clay lump): f = -0.5 rho C_d pi d^2 / 4 |v| v with Clift & Gauvin's
C_d(Re) = 24/Re (1 + 0.15 Re^0.687) + 0.42 / (1 + 4.25e4 Re^-1.16).
"""
from __future__ import annotations

import math

import numba

C_FRICTION = 0.02
"""Skin-friction coefficient of a cord (on its wetted area pi d l)."""


@numba.njit(cache=True)
def cylinder_cd(re: float) -> float:
    """Cross-flow drag coefficient of a circular cylinder, C_n = 1 + 10 Re^(-2/3) (F. M. White)."""
    return 1.0 + 10.0 * max(re, 1e-3) ** (-2.0 / 3.0)


@numba.njit(cache=True)
def sphere_cd(re: float) -> float:
    """Sphere drag coefficient, Clift & Gauvin (1970): 24/Re (1 + 0.15 Re^0.687) + 0.42 / (1 + 4.25e4 Re^-1.16)."""
    re = max(re, 1e-3)
    return 24.0 / re * (1 + 0.15 * re ** 0.687) + 0.42 / (1 + 4.25e4 * re ** -1.16)


@numba.njit(cache=True)
def drag_kernel(xpos, xmat, cvel, com, xipos, cyl_b, cyl_p, cyl_d, ll, sph_b, sph_p, sph_d,
                 rho, nu, cf, out):  # pragma: no cover - compiled
    """Air drag on links (cylinders) and clay lumps (spheres), written into ``out``.

    Args:
        xpos (nbody, 3), xmat (nbody, 9), cvel (nbody, 6), xipos (nbody, 3): MuJoCo's
            body frames, com-based velocities [rot; lin] and centres of mass.
        com: (3,) subtree_com of the tree's root (the reference point of cvel).
        cyl_b (C,) int body ids, cyl_p (C, 3) element centres in the body frame,
            cyl_d (C,) diameters, m; ll: element length, m (the axis is the body's x).
        sph_b (B,), sph_p (B, 3), sph_d (B,): the same for spheres.
        rho: air density, kg/m^3; nu: kinematic viscosity, m^2/s; cf: C_f.
        out: (nbody, 6) force and torque about xipos (MuJoCo's ``xfrc_applied``), N, N m.
    """
    out[:, :] = 0.0
    if rho <= 0.0:
        return
    ne = len(cyl_b) + len(sph_b)
    for e in range(ne):
        cyl = e < len(cyl_b)
        if cyl:
            b, pl, dia = cyl_b[e], cyl_p[e], cyl_d[e]
        else:
            b, pl, dia = sph_b[e - len(cyl_b)], sph_p[e - len(cyl_b)], sph_d[e - len(cyl_b)]
        p0 = xpos[b, 0] + xmat[b, 0] * pl[0] + xmat[b, 1] * pl[1] + xmat[b, 2] * pl[2]
        p1 = xpos[b, 1] + xmat[b, 3] * pl[0] + xmat[b, 4] * pl[1] + xmat[b, 5] * pl[2]
        p2 = xpos[b, 2] + xmat[b, 6] * pl[0] + xmat[b, 7] * pl[1] + xmat[b, 8] * pl[2]
        r0, r1, r2 = p0 - com[0], p1 - com[1], p2 - com[2]
        w0, w1, w2 = cvel[b, 0], cvel[b, 1], cvel[b, 2]
        v0 = cvel[b, 3] + w1 * r2 - w2 * r1
        v1 = cvel[b, 4] + w2 * r0 - w0 * r2
        v2 = cvel[b, 5] + w0 * r1 - w1 * r0
        if cyl:
            a0, a1, a2 = xmat[b, 0], xmat[b, 3], xmat[b, 6]          # link axis = body x
            vt = v0 * a0 + v1 * a1 + v2 * a2
            t0, t1, t2 = vt * a0, vt * a1, vt * a2
            n0, n1, n2 = v0 - t0, v1 - t1, v2 - t2
            sn = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
            st = abs(vt)
            cn = cylinder_cd(sn * dia / nu)
            k = -0.5 * rho * dia * ll
            f0 = k * (cn * sn * n0 + cf * math.pi * st * t0)
            f1 = k * (cn * sn * n1 + cf * math.pi * st * t1)
            f2 = k * (cn * sn * n2 + cf * math.pi * st * t2)
        else:
            sp = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
            cd = sphere_cd(sp * dia / nu)
            k = -0.5 * rho * cd * math.pi * dia * dia / 4 * sp
            f0, f1, f2 = k * v0, k * v1, k * v2
        q0, q1, q2 = p0 - xipos[b, 0], p1 - xipos[b, 1], p2 - xipos[b, 2]
        out[b, 0] += f0
        out[b, 1] += f1
        out[b, 2] += f2
        out[b, 3] += q1 * f2 - q2 * f1
        out[b, 4] += q2 * f0 - q0 * f2
        out[b, 5] += q0 * f1 - q1 * f0
