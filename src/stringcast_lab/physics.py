"""The virtual lab's physics: a MuJoCo capsule chain swung by a lagging planar arm.

This is the stand-in for the real string, so it is deliberately *not* the string
model of ``docs/string_model.md`` (and shares no code with it):

* The string is a serial chain of ``lab.links_per_point * n_points`` rigid
  capsules joined by hinges about z (the swing plane is z = 0). Links are rigid
  and there is no slide joint: the string is inextensible (cotton/nylon cord
  stretches well under 1 % at the few newtons of a cast, and a slide joint per
  link would double the degrees of freedom of an O(n^3) chain). A drawn material
  (:mod:`.materials`) that a cast strains over 0.5 % gets a slide per link
  (:func:`.mjcf.slide_spring`), and the step is cut to ``lab.timestep_s`` / k from
  the chain's stiffest mode (:meth:`ChainSim.refine`; k = 1 for ``lab.strings``).
* Bending: each hinge is a torsional spring/damper, k = EI / l_link and
  d = eta / l_link (EI in N m^2, eta in N m^2 s, l_link the link length), so the
  string's bending is independent of how finely it is cut.
* Mass: the string's linear density on every capsule; each clay weight is a
  sphere geom with its own mass on the link that holds its arc position; a
  plastic pipe adds its mass per length to the links it covers and makes them
  one rigid body (no hinges inside the pipe). A real pipe's EI (~0.1 N m^2) is
  thousands of times the cord's and cannot be resolved by an explicit step, so
  rigid is the honest limit.
* Air: the standard cable (Morison-type) drag, applied as body forces every
  ``DRAG_EVERY`` steps: on each link, normal drag 0.5 rho C_n(Re) d l |v_n| v_n
  with C_n = 1 + 10 Re^(-2/3) (White's fit for a cylinder in cross-flow) and
  tangential skin friction 0.5 rho C_f pi d l |v_t| v_t (C_f = 0.02); on each
  clay lump, sphere drag with Clift-Gauvin's C_d(Re). MuJoCo's own fluid
  models were not used: its ellipsoid model treats each short capsule as a
  separate blunt body, which puts ~70 % of the broadside drag on motion
  *along* the string (measured), ten times too much for a cord. No contacts.
* The grasp: the first link hangs from a *driver* body (slide x, slide y, hinge z
  at the grasp point, angle = hand angle phi_h) through a hinge with its own
  stiffness/damping, whose rest angle is along the gripper axis. The driver has
  a large armature and is pushed by feed-forward + PD generalized forces so it
  follows the lagged arm's hand pose (``arm.hand_pose``) to micrometres while
  the string's reaction acts on it physically.
* The arm's servo lag: each joint follows its command through a critically
  damped 2nd-order filter, q'' = w^2 (u - q) - 2 w q', w = 2 / lab.servo_lag_s
  (so a ramp lags by servo_lag_s); the command u is the controller's set-points
  interpolated linearly (as servoJ does).

The string's description and MJCF are :mod:`stringcast_lab.mjcf`.

Integrator: MuJoCo's semi-implicit Euler (joint damping implicit) at
``lab.timestep_s`` (5e-5 s): the starting design measured implicitfast 15-35x slower on
such chains.
"""
from __future__ import annotations

import math
import numpy as np

from stringcast.core import ArmSpec
from .air import C_FRICTION, drag_kernel
from .mjcf import DRIVER_ARMATURE, G_ACC, V_CAST, StringPhysics, build_mjcf, link_diameter, weight_link
from .recording import Recording, command_arrays
from .servo import hand_trajectory, servo_lag

_DRIVER_BANDWIDTH_HZ = 60.0               # PD bandwidth of the driver
DRAG_EVERY = 2                            # air drag re-evaluated every 2 steps (0.1 ms)
STEP_SAFETY = 0.5                         # the step keeps omega_max dt <= 2 STEP_SAFETY


class ChainSim:
    """A MuJoCo chain driven at the grasp (one :class:`StringPhysics`).

    Attributes:
        model, data: the ``mujoco.MjModel`` / ``MjData``.
        n_sites: n_links + 1 points along the string (arc k * l_link), site 0 the grasp.
    """

    def __init__(self, phys: StringPhysics, timestep: float):
        import mujoco

        self.phys = phys
        self.mujoco = mujoco
        self.model = mujoco.MjModel.from_xml_string(build_mjcf(phys, timestep))
        self.data = mujoco.MjData(self.model)
        self.n_sites = phys.n_links + 1
        self.dt = float(self.model.opt.timestep)
        self.hinge_dofs = np.arange(3, self.model.nv)
        arm = np.asarray(DRIVER_ARMATURE)
        w = 2 * math.pi * _DRIVER_BANDWIDTH_HZ
        self._A = arm
        self._kp = arm * w * w
        self._kd = arm * 2 * w
        self._setup_drag()
        self._n = 0

    # -- air drag --------------------------------------------------------------
    def _setup_drag(self) -> None:
        """Drag elements: one cylinder per link (midpoint, axis = link x) and one sphere per weight."""
        import mujoco

        phys, m = self.phys, self.model
        ll = phys.link_length
        bid = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"link{k}") for k in range(phys.n_links)]
        cyl_b = np.array(bid, dtype=np.int64)
        cyl_p = np.tile([ll / 2, 0.0, 0.0], (phys.n_links, 1))
        cyl_d = np.array([link_diameter(phys, k) for k in range(phys.n_links)])
        sph_b = np.array([bid[weight_link(phys, at)] for at, _, _ in phys.weights], dtype=np.int64)
        sph_p = np.array([[at - weight_link(phys, at) * ll, 0.0, 0.0] for at, _, _ in phys.weights]).reshape(-1, 3)
        sph_d = np.array([dia for _, _, dia in phys.weights], dtype=float)
        self._cyl = (cyl_b, cyl_p, cyl_d)
        self._sph = (sph_b, sph_p, sph_d)
        self._root = int(m.body_rootid[bid[0]])
        self._nu = phys.air_viscosity / max(phys.air_density, 1e-12)   # kinematic viscosity

    def apply_drag(self) -> None:
        """Set ``xfrc_applied`` to the air drag of the current state (see the module docstring)."""
        d = self.data
        cb, cp, cd = self._cyl
        sb, sp, sd = self._sph
        drag_kernel(d.xpos, d.xmat, d.cvel, d.subtree_com[self._root], d.xipos, cb, cp, cd,
                     self.phys.link_length, sb, sp, sd, self.phys.air_density, self._nu, C_FRICTION,
                     d.xfrc_applied)

    # -- the step the material allows ---------------------------------------
    def omega_max(self) -> float:
        """The chain's fastest linear mode under a cast, rad/s, hanging straight down.

        Generalized eigenvalues of (K, M) over the string's joints (driver held): M MuJoCo's
        joint-space mass matrix, K the joints' springs (hinges EI / l, grasp, slides) plus the
        gravity Hessian scaled from g to g + V_CAST^2 / L (the geometric stiffness of a cast's
        tension, :attr:`~.mjcf.StringPhysics.cast_tension`), by central differences of
        ``qfrc_bias``."""
        import mujoco
        from scipy.linalg import eigh

        m, d = self.model, self.data
        self.reset_hanging(np.array([0.0, 0.0, -math.pi / 2]))
        q0 = d.qpos.copy()
        nv = m.nv
        full = np.zeros((nv, nv))
        mujoco.mj_fullM(m, d, full)
        mass = full[3:, 3:]
        stiff = np.zeros((nv, nv))
        for j in range(m.njnt):
            stiff[m.jnt_dofadr[j], m.jnt_dofadr[j]] = m.jnt_stiffness[j]
        h = 1e-6
        for i in range(3, nv):
            col = []
            for sgn in (1.0, -1.0):
                d.qpos[:] = q0
                d.qpos[i] += sgn * h
                mujoco.mj_forward(m, d)
                col.append(d.qfrc_bias.copy())
            stiff[:, i] += (col[0] - col[1]) / (2 * h) * (1 + V_CAST ** 2 / (self.phys.length * G_ACC))
        d.qpos[:] = q0
        mujoco.mj_forward(m, d)
        k = stiff[3:, 3:]
        w2 = eigh(0.5 * (k + k.T), mass, eigvals_only=True)
        return float(math.sqrt(max(float(w2.max()), 0.0)))

    def refine(self, timestep: float) -> int:
        """Set the chain's step to ``timestep`` / k, k the fewest whole steps per ``timestep`` with
        omega_max dt <= 2 STEP_SAFETY (:meth:`omega_max`; semi-implicit Euler is stable below 2).
        Returns k (1 for every ``lab.strings`` type: their step stays ``lab.timestep_s``)."""
        k = max(1, math.ceil(timestep * self.omega_max() / (2 * STEP_SAFETY) - 1e-9))
        if k > 1:
            self.model.opt.timestep = timestep / k
            self.dt = float(self.model.opt.timestep)
        return k

    def step(self, pose: np.ndarray, vel: np.ndarray, acc: np.ndarray) -> None:
        """One MuJoCo step with the driver pushed towards the hand pose (x, y, phi_h) and air drag."""
        if self._n % DRAG_EVERY == 0:
            self.apply_drag()
        self._n += 1
        self.drive(pose, vel, acc)
        self.mujoco.mj_step(self.model, self.data)

    # -- state ---------------------------------------------------------------
    def reset_hanging(self, pose: np.ndarray) -> None:
        """Place the driver at ``pose`` (x, y, phi_h) at rest with the string straight down.

        The first hinge turns the first link to -y the short way, within half a turn: its spring is
        linear in the angle, so from -pi/2 - phi_h unwrapped (phi_h = 4.3 rad, the arm's joint sum)
        the chain started wound by -338 deg and :meth:`equilibrium` kept that loop."""
        d = self.data
        self.mujoco.mj_resetData(self.model, d)
        d.qpos[:3] = pose
        d.qpos[3] = (-math.pi / 2 - pose[2] + math.pi) % (2 * math.pi) - math.pi  # first link along -y
        self.mujoco.mj_forward(self.model, d)

    def sites(self) -> np.ndarray:
        """(n_sites, 2) world (x, y) of the string points for the current state, m."""
        return self.data.site_xpos[:, :2].copy()

    def drive(self, pose: np.ndarray, vel: np.ndarray, acc: np.ndarray) -> None:
        """Set the driver's generalized force for one step: feed-forward + PD to the hand pose."""
        d = self.data
        d.qfrc_applied[:3] = (self._A * acc + self._kp * (pose - d.qpos[:3])
                              + self._kd * (vel - d.qvel[:3]))

    def equilibrium(self, pose: np.ndarray) -> float:
        """Put the string at its static equilibrium hanging from the hand pose (x, y, phi_h).

        Minimises the potential energy (gravity + hinge springs, MuJoCo's
        ``mj_energyPos``) over the hinge angles with L-BFGS-B; the gradient is
        qfrc_bias - qfrc_passive at zero velocity. Starts from the string hanging
        straight down. Returns the largest residual generalized force, N m.
        """
        from scipy.optimize import minimize

        import mujoco

        m, d = self.model, self.data
        self.reset_hanging(pose)

        def fun(x):
            d.qpos[3:] = x
            d.qvel[:] = 0.0
            mujoco.mj_forward(m, d)
            mujoco.mj_energyPos(m, d)
            return float(d.energy[0]), (d.qfrc_bias[3:] - d.qfrc_passive[3:]).copy()

        res = minimize(fun, d.qpos[3:].copy(), jac=True, method="L-BFGS-B",
                       options={"gtol": 1e-12, "ftol": 1e-15, "maxiter": 5000})
        fun(res.x)
        return float(np.abs(res.jac).max())

    def settle(self, pose: np.ndarray, duration_s: float = 0.3, speed_tol: float = 1e-3) -> float:
        """Bring the string to rest hanging from a fixed hand pose.

        :meth:`equilibrium`, then ``duration_s`` of free dynamics with the hand
        held (so the state is a true rest state of the integrator, driver
        included). Returns the final largest point speed, m/s (a warning is
        issued if it is above ``speed_tol``).
        """
        self.equilibrium(pose)
        zero = np.zeros(3)
        for _ in range(int(duration_s / self.dt)):
            self.step(pose, zero, zero)
        self.data.time = 0.0
        speed = self.max_speed()
        if speed > speed_tol:
            import warnings

            warnings.warn(f"lab: the string is still moving at {speed:.2g} m/s after settling", stacklevel=2)
        return speed

    def max_speed(self) -> float:
        """Largest linear speed of any string site, m/s."""
        import mujoco

        vel = np.zeros(6)
        best = 0.0
        for i in range(self.model.nsite):
            mujoco.mj_objectVelocity(self.model, self.data, mujoco.mjtObj.mjOBJ_SITE, i, vel, 0)
            best = max(best, float(np.hypot(vel[3], vel[4])))
        return best

    def energy(self) -> tuple[float, float]:
        """(potential, kinetic) energy of the whole model, J (MuJoCo's energy flag)."""
        self.mujoco.mj_energyPos(self.model, self.data)
        self.mujoco.mj_energyVel(self.model, self.data)
        return float(self.data.energy[0]), float(self.data.energy[1])


def simulate(phys: StringPhysics, arm: ArmSpec, t_cmd: np.ndarray, q_cmd: np.ndarray,
             timestep: float, servo_lag_s: float, settle_s: float = 0.3, progress: bool = False) -> Recording:
    """Settle the string at q_cmd[0], then swing it through the commanded joint motion.

    Args:
        phys: the string. arm: the planar arm (forward kinematics).
        t_cmd: (K,) s from 0, q_cmd: (K, J) rad, the controller's set-points.
        timestep: MuJoCo step, s. servo_lag_s: see :func:`servo_lag`.

    Returns:
        A :class:`Recording` from t_cmd[0] to t_cmd[-1] at every step.

    Raises:
        ValueError: bad shapes or t_cmd not increasing (:func:`~stringcast_lab.recording.command_arrays`).
        FloatingPointError: the simulation diverged.
    """
    import time

    t_cmd, q_cmd = command_arrays(t_cmd, q_cmd, arm.n_joints, "simulate")
    sim = ChainSim(phys, timestep)
    dt = sim.dt
    n = int(math.floor((t_cmd[-1] - t_cmd[0]) / dt + 1e-9)) + 1
    k = sim.refine(dt)                  # sub-steps per recorded step (1: the step is lab.timestep_s)
    t_fine = t_cmd[0] + sim.dt * np.arange(n * k)
    t = t_fine[::k]
    q, _, _ = servo_lag(t_cmd, q_cmd, servo_lag_s, t_fine)
    pose, vel, acc = hand_trajectory(arm, q, sim.dt)
    speed = sim.settle(pose[0], settle_s)
    pts = np.empty((n, sim.n_sites, 2))
    d = sim.data
    sx = d.site_xpos
    it = range(n)
    if progress:
        from tqdm import tqdm
        it = tqdm(it, desc="physics", unit="step", mininterval=1.0, leave=False, disable=None)
    t0 = time.perf_counter()
    for i in it:
        j = i * k
        sim.step(pose[j], vel[j], acc[j])   # positions are computed at the start of the step: t[i]
        pts[i] = sx[:, :2]
        for j in range(i * k + 1, i * k + k):
            sim.step(pose[j], vel[j], acc[j])
        if i % 2000 == 0 and not np.isfinite(d.qacc).all():
            raise FloatingPointError(f"lab physics diverged at t = {t[i]:.4f} s")
    wall = time.perf_counter() - t0
    if not np.isfinite(pts).all():
        raise FloatingPointError("lab physics diverged (non-finite positions)")
    detail = {"timestep_s": sim.dt, "steps_per_sample": k, "stretches": phys.stretches}
    return Recording(t, pts, q[::k], speed, n * k / max(wall, 1e-9), physics="mujoco", detail=detail)
