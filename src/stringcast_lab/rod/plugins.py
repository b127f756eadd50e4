"""The rod's PyElastica plug-ins: the gripper clamp, air drag and the cord's internal damping.

* :class:`HandClamp` (a ``elastica.ConstraintBase``): node 0 and element 0's directors follow the
  hand (x, y, phi_h) of a :class:`HandPath`; element 0's axis d3 is the gripper axis
  (cos phi_h, sin phi_h), d1 = +z (the swing plane's normal).
* :class:`AirDrag` (an ``elastica.NoForces``): cable drag on every element and sphere drag on the
  clay lumps, in still air.
* :class:`CordDamping` (an ``elastica.DamperBase``): Kelvin-Voigt dashpots on bending (the
  configured ``bending_damping``) and on stretch, applied implicitly after each step.

Planar: the rod lies in z = 0 and every force here is in that plane (z components stay 0).

The three classes subclass PyElastica's, so they are made on first use by :func:`plugin_classes`:
PyElastica is imported only when a rod is built (it takes 0.5-0.9 s, scipy.interpolate
included), as the MuJoCo chain imports MuJoCo only when a chain is built, so ``stringcast_lab``
stays as quick to import as it was. The numba kernels and :class:`HandPath` need neither.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .material import RodMaterial


class HandPath:
    """The hand's pose on an even clock, looked up by time (the clamp's input).

    Args:
        t0: time of the first sample, s. h: sample step, s.
        pose: (N, 3) x, y m, phi_h rad (unwrapped). vel: (N, 3) their rates.
    """

    def __init__(self, t0: float, h: float, pose: np.ndarray, vel: np.ndarray):
        self.t0, self.h = float(t0), float(h)
        self.pose = np.ascontiguousarray(pose, float)
        self.vel = np.ascontiguousarray(vel, float)

    @classmethod
    def hold(cls, pose) -> HandPath:
        """The hand held still at ``pose`` (x, y, phi_h) for all time."""
        p = np.asarray(pose, float).reshape(1, 3)
        return cls(0.0, 1.0, p, np.zeros((1, 3)))

    def index(self, time: float) -> int:
        """The sample nearest ``time`` (clipped to the path)."""
        return int(_sample(self.t0, self.h, len(self.pose), float(time)))


def directors(phi: float) -> np.ndarray:
    """(3, 3) PyElastica director matrix (rows d1, d2, d3) of an element along angle phi in the
    x-y plane: d1 = +z, d2 = d3 x d1 = (sin phi, -cos phi, 0), d3 = (cos phi, sin phi, 0)."""
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[0.0, 0.0, 1.0], [s, -c, 0.0], [c, s, 0.0]])


@njit(cache=True)
def _sample(t0: float, h: float, n: int, time: float) -> int:  # pragma: no cover - compiled
    """The index of the sample nearest ``time`` on a clock t0 + i h, i in [0, n)."""
    i = int(math.floor((time - t0) / h + 0.5))
    return min(max(i, 0), n - 1)


@njit(cache=True)
def _clamp_values(position, director, pose, t0, h, time, held):  # pragma: no cover - compiled
    """Node 0 to the hand's (x, y, 0) and, if ``held``, element 0's directors to :func:`directors` (phi_h)."""
    i = _sample(t0, h, pose.shape[0], time)
    c, s = math.cos(pose[i, 2]), math.sin(pose[i, 2])
    position[0, 0] = pose[i, 0]
    position[1, 0] = pose[i, 1]
    position[2, 0] = 0.0
    if not held:
        return
    director[0, 0, 0], director[0, 1, 0], director[0, 2, 0] = 0.0, 0.0, 1.0
    director[1, 0, 0], director[1, 1, 0], director[1, 2, 0] = s, -c, 0.0
    director[2, 0, 0], director[2, 1, 0], director[2, 2, 0] = c, s, 0.0


@njit(cache=True)
def _clamp_rates(velocity, omega, vel, t0, h, time, held):  # pragma: no cover - compiled
    """Node 0's velocity to the hand's and, if ``held``, element 0's angular velocity to (dphi_h/dt, 0, 0)
    (frame d1 = +z)."""
    i = _sample(t0, h, vel.shape[0], time)
    velocity[0, 0] = vel[i, 0]
    velocity[1, 0] = vel[i, 1]
    velocity[2, 0] = 0.0
    if not held:
        return
    omega[0, 0] = vel[i, 2]
    omega[1, 0] = 0.0
    omega[2, 0] = 0.0


# --------------------------------------------------------------------------------------- air
@njit(cache=True)
def cylinder_cd(re: float) -> float:  # pragma: no cover - compiled
    """Cross-flow drag coefficient of a circular cylinder, Sucker & Brauer (1975):
    C_n = 1.18 + 6.8 Re^-0.89 + 1.96 Re^-0.5 - 0.0004 Re / (1 + 3.64e-7 Re^2), 1e-4 < Re < 2e5."""
    re = max(re, 1e-4)
    return 1.18 + 6.8 * re ** -0.89 + 1.96 * re ** -0.5 - 0.0004 * re / (1.0 + 3.64e-7 * re * re)


@njit(cache=True)
def sphere_cd(re: float) -> float:  # pragma: no cover - compiled
    """Sphere drag coefficient, Morrison (2013), Re up to 1e6:
    24/Re + 2.6 (Re/5) / (1 + (Re/5)^1.52) + 0.411 (Re/2.63e5)^-7.94 / (1 + (Re/2.63e5)^-8)
    + 0.25 (Re/1e6) / (1 + Re/1e6)."""
    re = max(re, 1e-4)
    x = re / 2.63e5
    return (24.0 / re + 2.6 * (re / 5.0) / (1.0 + (re / 5.0) ** 1.52)
            + 0.411 * x ** -7.94 / (1.0 + x ** -8.0) + 0.25 * (re / 1e6) / (1.0 + re / 1e6))


@njit(cache=True)
def skin_cf(re_l: float) -> float:  # pragma: no cover - compiled
    """Mean skin-friction coefficient over a laminar boundary layer of length Re_L (Blasius):
    C_f = 1.328 / sqrt(Re_L), capped at 2 (Re_L < 0.44: creeping flow)."""
    return min(1.328 / math.sqrt(max(re_l, 1e-12)), 2.0)


@njit(cache=True)
def drag_kernel(vel, tangents, lengths, diam, clay_node, clay_w, clay_d, rho, nu, length, out):  # pragma: no cover
    """Add the air drag to ``out`` (3, n + 1), N.

    Args:
        vel: (3, n + 1) node velocities, m/s. tangents: (3, n) unit element axes. lengths: (n,) m.
        diam: (n,) element diameters, m. clay_node (W,), clay_w (W,), clay_d (W,): the lumps
            (node i and i + 1 by the lever rule, diameter m). rho kg/m^3, nu m^2/s: the air.
        length: the string's length, m (the skin friction's boundary-layer length).

    Per element, at its mid velocity v (split half to each node): normal drag
    -0.5 rho C_n(|v_n| d / nu) d l |v_n| v_n (:func:`cylinder_cd`) and tangential skin friction
    -0.5 rho C_f(|v_t| L / nu) pi d l |v_t| v_t (:func:`skin_cf`). Per lump, at its interpolated
    velocity: -0.5 rho C_d(|v| D / nu) pi D^2 / 4 |v| v (:func:`sphere_cd`), split by the lever rule.
    """
    if rho <= 0.0:
        return
    n = lengths.shape[0]
    for e in range(n):
        vx = 0.5 * (vel[0, e] + vel[0, e + 1])
        vy = 0.5 * (vel[1, e] + vel[1, e + 1])
        tx, ty = tangents[0, e], tangents[1, e]
        vt = vx * tx + vy * ty
        nx, ny = vx - vt * tx, vy - vt * ty
        vn = math.sqrt(nx * nx + ny * ny)
        d, le = diam[e], lengths[e]
        fn = -0.5 * rho * cylinder_cd(vn * d / nu) * d * le * vn
        ft = -0.5 * rho * skin_cf(abs(vt) * length / nu) * math.pi * d * le * abs(vt) * vt
        fx = fn * nx + ft * tx
        fy = fn * ny + ft * ty
        out[0, e] += 0.5 * fx
        out[1, e] += 0.5 * fy
        out[0, e + 1] += 0.5 * fx
        out[1, e + 1] += 0.5 * fy
    for k in range(clay_node.shape[0]):
        i, w, dk = clay_node[k], clay_w[k], clay_d[k]
        vx = (1 - w) * vel[0, i] + w * vel[0, i + 1]
        vy = (1 - w) * vel[1, i] + w * vel[1, i + 1]
        v = math.sqrt(vx * vx + vy * vy)
        f = -0.5 * rho * sphere_cd(v * dk / nu) * math.pi * dk * dk / 4 * v
        out[0, i] += (1 - w) * f * vx
        out[1, i] += (1 - w) * f * vy
        out[0, i + 1] += w * f * vx
        out[1, i + 1] += w * f * vy


# ------------------------------------------------------------------------------- damping
@njit(cache=True)
def _damp_rotation(omega, J, c, dt, free0, c_g, w_hand):  # pragma: no cover - compiled
    """Implicit junction dashpots on the in-plane angular velocities omega[0]: solve
    (J + dt D) w' = J w by Thomas' algorithm, D the dashpots' Laplacian (c (n - 1,) N m s). Element 0
    is held (the rigid clamp) unless ``free0``; then it is an unknown too, with the grasp's dashpot
    c_g N m s to the hand's rate w_hand rad/s."""
    n = J.shape[0]
    if n < 2:
        return
    s0 = 0 if free0 else 1
    a = np.zeros(n)
    b = np.zeros(n)
    cc = np.zeros(n)
    r = np.zeros(n)
    for e in range(s0, n):
        if e >= 1:
            b[e] = J[e] + dt * c[e - 1]
        else:
            b[e] = J[e] + dt * c_g
        r[e] = J[e] * omega[0, e]
        if e == 0:
            r[e] += dt * c_g * w_hand
        elif e - 1 >= s0:
            a[e] = -dt * c[e - 1]
        else:
            r[e] += dt * c[e - 1] * omega[0, 0]
        if e < n - 1:
            b[e] += dt * c[e]
            cc[e] = -dt * c[e]
    for e in range(s0 + 1, n):
        m = a[e] / b[e - 1]
        b[e] -= m * cc[e - 1]
        r[e] -= m * r[e - 1]
    omega[0, n - 1] = r[n - 1] / b[n - 1]
    for e in range(n - 2, s0 - 1, -1):
        omega[0, e] = (r[e] - cc[e] * omega[0, e + 1]) / b[e]


@njit(cache=True)
def _grasp_torque(director, torques, pose, t0, h, time, k):  # pragma: no cover - compiled
    """Add the grasp spring's couple -k (theta_0 - phi_h) (wrapped to a half turn) about d1 = +z to
    element 0's torque (theta_0 the angle of its d3)."""
    i = _sample(t0, h, pose.shape[0], time)
    th = math.atan2(director[2, 1, 0], director[2, 0, 0])
    d = (th - pose[i, 2] + math.pi) % (2 * math.pi) - math.pi
    torques[0, 0] -= k * d


@njit(cache=True)
def _damp_stretch(vel, tangents, mass, c, dt):  # pragma: no cover - compiled
    """Implicit axial dashpots on the in-plane node velocities (node 0 held): solve
    (M + dt K) v' = M v, K the sum over elements of c_e t t^T on (v_{e+1} - v_e), by block
    (2 x 2) Thomas' algorithm. c: (n,) N s / m."""
    n = tangents.shape[1]                   # elements; unknowns: nodes 1..n
    B = np.zeros((n + 1, 2, 2))
    C = np.zeros((n + 1, 2, 2))             # coupling of node i to node i + 1 (= that of i + 1 to i)
    R = np.zeros((n + 1, 2))
    for i in range(1, n + 1):
        B[i, 0, 0] = mass[i]
        B[i, 1, 1] = mass[i]
        R[i, 0] = mass[i] * vel[0, i]
        R[i, 1] = mass[i] * vel[1, i]
    for e in range(n):
        tx, ty = tangents[0, e], tangents[1, e]
        k00, k01, k11 = dt * c[e] * tx * tx, dt * c[e] * tx * ty, dt * c[e] * ty * ty
        for i in (e, e + 1):
            if i >= 1:
                B[i, 0, 0] += k00
                B[i, 0, 1] += k01
                B[i, 1, 0] += k01
                B[i, 1, 1] += k11
        if e >= 1:
            C[e, 0, 0] = -k00
            C[e, 0, 1] = -k01
            C[e, 1, 0] = -k01
            C[e, 1, 1] = -k11
        else:                                # node 0 is held: its term goes to the right side
            R[1, 0] += k00 * vel[0, 0] + k01 * vel[1, 0]
            R[1, 1] += k01 * vel[0, 0] + k11 * vel[1, 0]
    for i in range(2, n + 1):               # forward elimination: B_i -= C_{i-1} B_{i-1}^-1 C_{i-1} (C symmetric)
        b00, b01, b10, b11 = B[i - 1, 0, 0], B[i - 1, 0, 1], B[i - 1, 1, 0], B[i - 1, 1, 1]
        det = b00 * b11 - b01 * b10
        i00, i01, i10, i11 = b11 / det, -b01 / det, -b10 / det, b00 / det
        c00, c01, c10, c11 = C[i - 1, 0, 0], C[i - 1, 0, 1], C[i - 1, 1, 0], C[i - 1, 1, 1]
        m00, m01 = c00 * i00 + c10 * i10, c00 * i01 + c10 * i11      # m = C^T B^-1
        m10, m11 = c01 * i00 + c11 * i10, c01 * i01 + c11 * i11
        B[i, 0, 0] -= m00 * c00 + m01 * c10
        B[i, 0, 1] -= m00 * c01 + m01 * c11
        B[i, 1, 0] -= m10 * c00 + m11 * c10
        B[i, 1, 1] -= m10 * c01 + m11 * c11
        r0, r1 = R[i - 1, 0], R[i - 1, 1]
        R[i, 0] -= m00 * r0 + m01 * r1
        R[i, 1] -= m10 * r0 + m11 * r1
    for i in range(n, 0, -1):
        r0, r1 = R[i, 0], R[i, 1]
        if i < n:
            r0 -= C[i, 0, 0] * vel[0, i + 1] + C[i, 0, 1] * vel[1, i + 1]
            r1 -= C[i, 1, 0] * vel[0, i + 1] + C[i, 1, 1] * vel[1, i + 1]
        det = B[i, 0, 0] * B[i, 1, 1] - B[i, 0, 1] * B[i, 1, 0]
        vel[0, i] = (B[i, 1, 1] * r0 - B[i, 0, 1] * r1) / det
        vel[1, i] = (B[i, 0, 0] * r1 - B[i, 1, 0] * r0) / det


# ------------------------------------------------------------------------------- classes
_PLUGINS: dict = {}


def plugin_classes() -> tuple[type, type, type]:
    """(HandClamp, AirDrag, CordDamping): the PyElastica plug-ins, made once on first use
    (:func:`_hand_clamp`, :func:`_air_drag`, :func:`_cord_damping`; see the module docstring);
    ``_PLUGINS["grasp"]`` is the GraspSpring (:func:`_grasp_spring`)."""
    if not _PLUGINS:
        _PLUGINS.update(clamp=_hand_clamp(), drag=_air_drag(), damping=_cord_damping(), grasp=_grasp_spring())
    return _PLUGINS["clamp"], _PLUGINS["drag"], _PLUGINS["damping"]


def _hand_clamp() -> type:
    """The clamp class, a ``elastica.ConstraintBase``."""
    from elastica import ConstraintBase

    class HandClamp(ConstraintBase):
        """Clamp node 0 and element 0 to the hand (a time-varying ``elastica.OneEndFixedBC``).

        ``constrain_values`` sets node 0 to (x, y, 0) and element 0's directors to :func:`directors`
        (phi_h) at the sample of the owner's :class:`HandPath` nearest the time; ``constrain_rates``
        sets node 0's velocity to the hand's and element 0's angular velocity to (dphi_h/dt, 0, 0) in
        its own frame (d1 = +z). Use as ``sim.constrain(rod).using(HandClamp, clamp=owner)``, where
        ``owner.hand`` is the :class:`HandPath` (swapped between settling and the motion).
        """

        def __init__(self, *, clamp, held: bool = True, **kwargs):
            super().__init__(**kwargs)
            self._owner = clamp
            self._held = bool(held)

        def constrain_values(self, system, time) -> None:
            hand = self._owner.hand
            _clamp_values(system.position_collection, system.director_collection, hand.pose, hand.t0, hand.h,
                          float(time), self._held)

        def constrain_rates(self, system, time) -> None:
            hand = self._owner.hand
            _clamp_rates(system.velocity_collection, system.omega_collection, hand.vel, hand.t0, hand.h, float(time),
                         self._held)

    return HandClamp


def _air_drag() -> type:
    """The air-drag class, a ``elastica.NoForces``."""
    from elastica import NoForces

    class AirDrag(NoForces):
        """Air drag on the rod (:func:`drag_kernel`) in still air.

        Args:
            material: the rod's :class:`~.material.RodMaterial` (diameters, clay). rho: air density,
                kg/m^3. mu: air viscosity, Pa s.
        """

        def __init__(self, material: RodMaterial, rho: float, mu: float):
            super().__init__()
            self.diam = 2 * np.asarray(material.radius, float)
            self.clay = (material.clay_node, material.clay_w, material.clay_d)
            self.rho = float(rho)
            self.nu = float(mu) / max(float(rho), 1e-12)
            self.length = float(material.length)

        def apply_forces(self, system, time=0.0) -> None:
            drag_kernel(system.velocity_collection, system.tangents, system.lengths, self.diam, *self.clay,
                        self.rho, self.nu, self.length, system.external_forces)

    return AirDrag


def _cord_damping() -> type:
    """The internal-damping class, a ``elastica.DamperBase``."""
    from elastica import DamperBase

    class CordDamping(DamperBase):
        """The cord's internal (Kelvin-Voigt) damping, applied implicitly after each step.

        Bending: a dashpot eta / l_v (``bending_damping`` eta, N m^2 s; couple eta d(kappa)/dt) at
        every junction between elements, on their in-plane angular velocities. Stretch: a dashpot
        eta_a / l on every element's axial strain rate (eta_a = AXIAL_LOSS EA / omega_1). Each is the
        exact backward-Euler step of its dashpots alone (a linear solve), so it is stable at any
        step; element 0 and node 0 are the clamp's and stay as it set them. Neither dashpot acts on
        a rigid motion of the rod (they see only differences).

        Args:
            material: the rod's :class:`~.material.RodMaterial`. time_step: the step, s.
        """

        def __init__(self, material: RodMaterial, time_step: float, clamp=None, **kwargs):
            super().__init__(**kwargs)
            rod = self._system
            self.J = np.ascontiguousarray(rod.mass_second_moment_of_inertia[0, 0, :])
            self.c_bend = np.ascontiguousarray(material.eta_bend, float)
            self.c_axial = np.ascontiguousarray(material.eta_axial, float)
            self.dt = float(time_step)
            self.free0 = material.grasp != "rigid"
            self.c_grasp = float(material.c_grasp)
            self._owner = clamp

        def dampen_rates(self, system, time) -> None:
            if self.free0:
                hand = self._owner.hand
                w = hand.vel[_sample(hand.t0, hand.h, hand.vel.shape[0], float(time)), 2]
                _damp_rotation(system.omega_collection, self.J, self.c_bend, self.dt, True, self.c_grasp, w)
            elif self.c_bend.size and self.c_bend.max() > 0:
                _damp_rotation(system.omega_collection, self.J, self.c_bend, self.dt, False, 0.0, 0.0)
            _damp_stretch(system.velocity_collection, system.tangents, system.mass, self.c_axial, self.dt)

    return CordDamping


def _grasp_spring() -> type:
    """The grasp spring class, a ``elastica.NoForces``: the couple of a ``clamp`` grasp."""
    from elastica import NoForces

    class GraspSpring(NoForces):
        """The compliant clamp's couple on element 0 (:func:`_grasp_torque`), k N m/rad, towards
        the gripper axis phi_h of ``clamp.hand`` (its dashpot is :class:`CordDamping`'s)."""

        def __init__(self, k: float, clamp):
            super().__init__()
            self.k = float(k)
            self._owner = clamp

        def apply_torques(self, system, time=0.0) -> None:
            hand = self._owner.hand
            _grasp_torque(system.director_collection, system.external_torques, hand.pose, hand.t0, hand.h,
                          float(time), self.k)

    return GraspSpring
