"""The rod's hanging equilibrium under gravity, clamped at the hand: where the lab starts it.

The planar discrete rod of :class:`~.material.RodMaterial` (element angles theta_e, element 0
along the gripper axis phi_h): minimise gravity's potential sum_k m_k g y_k plus the junctions'
bending energy sum_v EI_v / (2 l) (theta_{v+1} - theta_v)^2 over theta_1..theta_{n-1}
(L-BFGS-B, analytic gradient), inextensible; then stretch each element by its static tension,
N_e = -g M_e sin(theta_e) (M_e the mass below it), N_e / EA_e. Shear is left to the dynamics.
"""
from __future__ import annotations

import numpy as np

from .material import G_ACC, RodMaterial
from .plugins import directors


def hanging_angles(mat: RodMaterial, phi_h: float) -> np.ndarray:
    """(n,) element angles, rad, of the rod hanging at rest from a clamp at angle ``phi_h`` rad
    (element 0 = phi_h). Starts from straight down and takes the minimum the minimiser reaches
    from there. Straight down is taken within half a turn of phi_h (the angles are not wrapped in
    the energy): from -pi/2 itself, a clamp at phi_h = 4.3 rad (the arm's joint sum, 22 deg left
    of down) started the rod wound by -338 deg at its first junction, and the minimiser kept a loop
    a hanging cord does not have."""
    from scipy.optimize import minimize

    n, l = mat.n, mat.l
    k = mat.junction_EI / l                                     # (n - 1,) N m / rad
    below = np.cumsum(mat.node_mass[::-1])[::-1][1:]            # (n,) mass of nodes e + 1..n
    free = mat.grasp != "rigid"                                  # element 0 on the grasp spring (or a pivot)

    def fun(x):
        th = x if free else np.concatenate([[phi_h], x])
        dth = np.diff(th)
        e = 0.5 * np.sum(k * dth * dth) + G_ACC * l * np.sum(below * np.sin(th))
        g = G_ACC * l * below * np.cos(th)
        g[:-1] -= k * dth
        g[1:] += k * dth
        if free:
            e += 0.5 * mat.k_grasp * (th[0] - phi_h) ** 2
            g[0] += mat.k_grasp * (th[0] - phi_h)
            return e, g
        return e, g[1:]

    down = phi_h + (-np.pi / 2 - phi_h + np.pi) % (2 * np.pi) - np.pi      # -pi/2 (mod 2 pi), nearest phi_h
    x0 = np.full(n if free else n - 1, down)
    res = minimize(fun, x0, jac=True, method="L-BFGS-B", options={"gtol": 1e-12, "ftol": 1e-15, "maxiter": 5000})
    return res.x.copy() if free else np.concatenate([[phi_h], res.x])


def hanging_nodes(mat: RodMaterial, grasp_xy, phi_h: float, stretch: bool = True) -> np.ndarray:
    """(n + 1, 2) node positions, m, of the rod hanging at rest from the hand (x, y, phi_h):
    :func:`hanging_angles`, each element stretched by its static tension (``stretch``)."""
    th = hanging_angles(mat, phi_h)
    below = np.cumsum(mat.node_mass[::-1])[::-1][1:]
    strain = -G_ACC * below * np.sin(th) / mat.EA if stretch else np.zeros(mat.n)
    seg = mat.l * (1 + strain)[:, None] * np.column_stack([np.cos(th), np.sin(th)])
    return np.asarray(grasp_xy, float)[:2] + np.vstack([np.zeros(2), np.cumsum(seg, axis=0)])


def rod_equilibrium(rod, mat: RodMaterial, pose, nodes0: np.ndarray) -> float:
    """Put the ``elastica.CosseratRod`` ``rod`` at its exact static equilibrium hanging from the
    hand pose (x, y, phi_h), starting from ``nodes0`` (n + 1, 2) m (:func:`hanging_nodes`).

    Solves, with MINPACK's hybrid Newton (``scipy.optimize.root``, finite-difference Jacobian),
    the rod's own equilibrium: at nodes 1..n its internal force (``internal_forces``, PyElastica's
    discrete Cosserat operators) plus gravity is zero, and on elements 1..n-1 its in-plane internal
    torque is zero; unknowns the node positions and element angles (node 0 and element 0 are the
    clamp's). So the integrator starts at rest in its own equilibrium, shear and stretch included.
    Leaves the rod at rest there (at ``nodes0`` if Newton made it worse). Returns the largest
    residual force, N.
    """
    from scipy.optimize import root

    n = mat.n
    pose = np.asarray(pose, float)
    free = mat.grasp != "rigid"               # element 0's angle is an unknown, its couple the grasp's
    e0 = 0 if free else 1
    weight = G_ACC * mat.node_mass[1:]
    f_scale = max(G_ACC * mat.node_mass.max(), 1e-9)
    t_scale = max(float(mat.junction_EI.max()) / mat.l, 1e-12)

    def place(x):
        rod.position_collection[0, 0], rod.position_collection[1, 0] = pose[0], pose[1]
        rod.position_collection[:2, 1:] = x[:2 * n].reshape(n, 2).T
        rod.position_collection[2] = 0.0
        if not free:
            rod.director_collection[..., 0] = directors(pose[2])
        for e in range(e0, n):
            rod.director_collection[..., e] = directors(x[2 * n + e - e0])

    def fun(x):
        place(x)
        rod.compute_internal_forces_and_torques(np.float64(0.0))
        f = rod.internal_forces[:2, 1:].copy()
        f[1] -= weight
        tq = rod.internal_torques[0, e0:].copy()
        if free:
            tq[0] -= mat.k_grasp * ((x[2 * n] - pose[2] + np.pi) % (2 * np.pi) - np.pi)
        return np.concatenate([f.T.ravel() / f_scale, tq / t_scale])

    d = np.diff(nodes0, axis=0)
    x0 = np.concatenate([np.asarray(nodes0, float)[1:].ravel(), np.arctan2(d[e0:, 1], d[e0:, 0])])
    res = root(fun, x0, method="hybr", options={"xtol": 1e-13, "maxfev": 200 * (len(x0) + 1)})
    start = np.abs(fun(x0)).max()
    x = res.x if np.all(np.isfinite(res.x)) and np.abs(fun(res.x)).max() < start else x0
    resid = fun(x)
    rod.velocity_collection[:] = 0.0
    rod.omega_collection[:] = 0.0
    return float(np.abs(resid[:2 * n]).max() * f_scale)
