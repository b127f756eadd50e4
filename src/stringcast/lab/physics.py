"""The virtual lab's physics: a MuJoCo capsule chain swung by a lagging planar arm.

This is the stand-in for the real string, so it is deliberately *not* the string
model of ``STRING_MODEL.md`` (and shares no code with it):

* The string is a serial chain of ``lab.links_per_point * n_points`` rigid
  capsules joined by hinges about z (the swing plane is z = 0). Links are rigid
  and there is no slide joint: the string is inextensible (cotton/nylon cord
  stretches well under 1 % at the few newtons of a cast, and a slide joint per
  link would double the degrees of freedom of an O(n^3) chain).
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

Integrator: MuJoCo's semi-implicit Euler (joint damping implicit) at
``lab.timestep_s`` (5e-5 s): DESIGN.md measured implicitfast 15-35x slower on
such chains.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..config import ArmSpec, Campaign, ConfigError
from .air import C_FRICTION, drag_kernel
from .servo import hand_trajectory, servo_lag

#: Defaults for ``lab.strings.<type>`` keys (SI after conversion).
STRING_DEFAULTS = {
    "density_g_per_m": 20.0,       # cord linear density
    "diameter_mm": 3.0,            # cord diameter (drag, drawing)
    "bending_EI": 2.0e-5,          # N m^2
    "bending_damping": 2.0e-7,     # N m^2 s (hinge damping = value / link length)
    "grasp_stiffness": 5.0e-3,     # N m / rad, hinge at the gripper
    "grasp_damping": 2.0e-5,       # N m s / rad
    "clay_diameter_mm": 16.0,      # a 10 g clay lump
    "pipe_diameter_mm": 8.0,       # light plastic pipe
    "pipe_density_g_per_m": 40.0,  # pipe mass per length, added to the cord's
}

_DRIVER_ARMATURE = (200.0, 200.0, 20.0)   # kg, kg, kg m^2 on slide x, slide y, hinge z
_DRIVER_BANDWIDTH_HZ = 60.0               # PD bandwidth of the driver
DRAG_EVERY = 2                            # air drag re-evaluated every 2 steps (0.1 ms)


@dataclass(frozen=True)
class StringPhysics:
    """The hidden physical string of the lab (SI units).

    Attributes:
        length: m. n_links: capsules in the chain. density: kg/m. diameter: m.
        bending_EI: N m^2. bending_damping: N m^2 s.
        grasp_stiffness: N m/rad. grasp_damping: N m s/rad.
        weights: ((at_m, mass_kg, diameter_m), ...) clay lumps along the string.
        pipes: ((from_m, to_m, density_kg_per_m, diameter_m), ...) rigid pipes.
        air_density: kg/m^3. air_viscosity: Pa s.
    """

    length: float
    n_links: int
    density: float
    diameter: float
    bending_EI: float
    bending_damping: float
    grasp_stiffness: float
    grasp_damping: float
    weights: tuple = ()
    pipes: tuple = ()
    air_density: float = 1.2
    air_viscosity: float = 1.8e-5

    def __post_init__(self):
        if self.n_links < 2:
            raise ConfigError("lab: a string needs at least 2 links")
        for name in ("length", "density", "diameter"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"lab string: {name} must be positive")
        for name in ("bending_EI", "bending_damping", "grasp_stiffness", "grasp_damping"):
            if getattr(self, name) < 0:
                raise ConfigError(f"lab string: {name} must not be negative")
        for at, mass, dia in self.weights:
            if not (0 <= at <= self.length + 1e-9 and mass > 0 and dia > 0):
                raise ConfigError(f"lab string: bad weight at {at} m, mass {mass} kg")
        for a, b, rho, dia in self.pipes:
            if not (0 <= a < b <= self.length + 1e-9):
                raise ConfigError(f"lab string: bad pipe span {a}-{b} m")

    @property
    def link_length(self) -> float:
        return self.length / self.n_links

    @property
    def mass(self) -> float:
        """Total mass of string, weights and pipes, kg."""
        return (self.density * self.length + sum(w[1] for w in self.weights)
                + sum((b - a) * rho for a, b, rho, _ in self.pipes))

    @classmethod
    def from_campaign(cls, campaign: Campaign, config: Mapping) -> "StringPhysics":
        """Physical values for the campaign's string: ``lab.strings`` (default, then its type)."""
        lab = config.get("lab", {}) or {}
        table = lab.get("strings", {}) or {}
        vals = dict(STRING_DEFAULTS)
        vals.update(table.get("default", {}) or {})
        if campaign.string_id is not None:
            vals.update(table.get(str(campaign.string_id), {}) or {})
        if "damping" in vals:
            import warnings

            warnings.warn("lab.strings: key 'damping' is not used (its unit was undefined); "
                          "set bending_damping (N m^2 s) instead", stacklevel=2)
            vals.pop("damping")
        unknown = set(vals) - set(STRING_DEFAULTS)
        if unknown:
            raise ConfigError(f"lab.strings: unknown keys {sorted(unknown)} (known: {sorted(STRING_DEFAULTS)})")
        s = campaign.string
        n_links = int(lab.get("links_per_point", 3)) * s.n_points
        clay = vals["clay_diameter_mm"] / 1000
        pipe_d = vals["pipe_diameter_mm"] / 1000
        pipe_rho = vals["pipe_density_g_per_m"] / 1000
        air = lab.get("air", {}) or {}
        return cls(
            length=s.length, n_links=n_links, density=vals["density_g_per_m"] / 1000,
            diameter=vals["diameter_mm"] / 1000, bending_EI=float(vals["bending_EI"]),
            bending_damping=float(vals["bending_damping"]),
            grasp_stiffness=float(vals["grasp_stiffness"]), grasp_damping=float(vals["grasp_damping"]),
            weights=tuple((float(at), float(m), clay) for at, m in s.weights),
            pipes=tuple((float(a), float(b), pipe_rho, pipe_d) for a, b in s.stiff_sections),
            air_density=float(air.get("density_kg_m3", 1.2)),
            air_viscosity=float(air.get("viscosity_pa_s", 1.8e-5)),
        )


def _rigid_joint(phys: StringPhysics, k: int) -> bool:
    """True if the hinge at the start of link k (k >= 1) lies strictly inside a pipe."""
    s = k * phys.link_length
    return any(a + 1e-9 < s < b - 1e-9 for a, b, _, _ in phys.pipes)


def _link_diameter(phys: StringPhysics, k: int) -> float:
    """Outer diameter of link k: the pipe's where a pipe covers most of the link, else the cord's."""
    s0, s1 = k * phys.link_length, (k + 1) * phys.link_length
    d = phys.diameter
    for a, b, _, dia in phys.pipes:
        if min(b, s1) - max(a, s0) > 0.5 * phys.link_length:
            d = max(d, dia)
    return d


def _weight_link(phys: StringPhysics, at: float) -> int:
    """The link that carries a weight at arc length ``at``."""
    return int(min(phys.n_links - 1, max(0, math.floor(at / phys.link_length + 1e-9))))


def build_mjcf(phys: StringPhysics, timestep: float) -> str:
    """The MJCF text of driver + chain.

    Bodies ``link0..`` (each capsule along its local +x from its hinge), sites
    ``s0..s{n_links}`` at every link start and the tip (arc length k * l_link).
    Gravity is -9.81 along world y.
    """
    ll = phys.link_length
    k_hinge = phys.bending_EI / ll
    d_hinge = phys.bending_damping / ll
    xs = [
        '<mujoco model="stringcast_lab">',
        '  <compiler angle="radian" autolimits="true"/>',
        f'  <option timestep="{timestep:.9g}" integrator="Euler" gravity="0 -9.81 0">',
        '    <flag contact="disable" energy="enable"/>',
        '  </option>',
        '  <worldbody>',
        '    <body name="driver">',
        f'      <joint name="drv_x" type="slide" axis="1 0 0" armature="{_DRIVER_ARMATURE[0]:g}"/>',
        f'      <joint name="drv_y" type="slide" axis="0 1 0" armature="{_DRIVER_ARMATURE[1]:g}"/>',
        f'      <joint name="drv_phi" type="hinge" axis="0 0 1" armature="{_DRIVER_ARMATURE[2]:g}"/>',
        '      <inertial pos="0 0 0" mass="1e-3" diaginertia="1e-7 1e-7 1e-7"/>',
    ]
    indent = "      "
    depth = 0
    for k in range(phys.n_links):
        s0, s1 = k * ll, (k + 1) * ll
        pos = "0 0 0" if k == 0 else f"{ll:.9g} 0 0"
        rigid = k > 0 and _rigid_joint(phys, k)
        # Inside a pipe the body gets no joint: MuJoCo welds it to its parent.
        xs.append(f'{indent}<body name="link{k}" pos="{pos}">')
        if not rigid:
            if k == 0:
                xs.append(f'{indent}  <joint name="grasp" type="hinge" axis="0 0 1" '
                          f'stiffness="{phys.grasp_stiffness:.6g}" damping="{phys.grasp_damping:.6g}"/>')
            else:
                xs.append(f'{indent}  <joint name="h{k}" type="hinge" axis="0 0 1" '
                          f'stiffness="{k_hinge:.6g}" damping="{d_hinge:.6g}"/>')
        mass = phys.density * ll
        for a, b, rho, _ in phys.pipes:
            mass += rho * max(0.0, min(b, s1) - max(a, s0))
        rad = _link_diameter(phys, k) / 2
        xs.append(f'{indent}  <geom type="capsule" fromto="0 0 0 {ll:.9g} 0 0" size="{rad:.6g}" '
                  f'mass="{mass:.9g}"/>')
        xs.append(f'{indent}  <site name="s{k}" pos="0 0 0"/>')
        for at, m, dia in phys.weights:
            if _weight_link(phys, at) == k:
                xs.append(f'{indent}  <geom type="sphere" pos="{at - s0:.9g} 0 0" size="{dia / 2:.6g}" '
                          f'mass="{m:.9g}"/>')
        if k == phys.n_links - 1:
            xs.append(f'{indent}  <site name="s{k + 1}" pos="{ll:.9g} 0 0"/>')
        indent += "  "
        depth += 1
    for _ in range(depth):
        indent = indent[:-2]
        xs.append(f"{indent}</body>")
    xs += ["    </body>", "  </worldbody>", "</mujoco>"]
    return "\n".join(xs)


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
        arm = np.asarray(_DRIVER_ARMATURE)
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
        cyl_d = np.array([_link_diameter(phys, k) for k in range(phys.n_links)])
        sph_b = np.array([bid[_weight_link(phys, at)] for at, _, _ in phys.weights], dtype=np.int64)
        sph_p = np.array([[at - _weight_link(phys, at) * ll, 0.0, 0.0] for at, _, _ in phys.weights]).reshape(-1, 3)
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

    def step(self, pose: np.ndarray, vel: np.ndarray, acc: np.ndarray) -> None:
        """One MuJoCo step with the driver pushed towards the hand pose (x, y, phi_h) and air drag."""
        if self._n % DRAG_EVERY == 0:
            self.apply_drag()
        self._n += 1
        self.drive(pose, vel, acc)
        self.mujoco.mj_step(self.model, self.data)

    # -- state ---------------------------------------------------------------
    def reset_hanging(self, pose: np.ndarray) -> None:
        """Place the driver at ``pose`` (x, y, phi_h) at rest with the string straight down."""
        d = self.data
        self.mujoco.mj_resetData(self.model, d)
        d.qpos[:3] = pose
        d.qpos[3] = -math.pi / 2 - pose[2]  # first link points along -y
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

            warnings.warn(f"lab: the string is still moving at {speed:.2g} m/s after settling")
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


@dataclass(frozen=True)
class Recording:
    """String points on the physics time grid.

    Attributes:
        t: (N,) s, controller-clock times of the samples (even, step dt).
        points: (N, S, 2) world (x, y) of the S = n_links + 1 sites, m (site k at arc k * l_link).
        q_arm: (N, J) the lagged (true) arm joint angles, rad.
        settle_speed: the largest point speed left after settling, m/s.
        steps_per_s: MuJoCo steps per wall second while recording.
    """

    t: np.ndarray
    points: np.ndarray
    q_arm: np.ndarray
    settle_speed: float
    steps_per_s: float

    def __post_init__(self):
        n = len(self.t)
        if self.points.ndim != 3 or self.points.shape[0] != n or self.points.shape[2] != 2:
            raise ValueError(f"Recording: points must be ({n}, S, 2), got {self.points.shape}")
        if self.q_arm.shape[0] != n:
            raise ValueError(f"Recording: q_arm must have {n} rows, got {self.q_arm.shape}")

    def at(self, times: np.ndarray) -> np.ndarray:
        """(len(times), S, 2) site positions linearly interpolated in time, m."""
        times = np.asarray(times, float)
        dt = self.t[1] - self.t[0]
        f = np.clip((times - self.t[0]) / dt, 0, len(self.t) - 1 - 1e-9)
        i = np.floor(f).astype(int)
        w = (f - i)[:, None, None]
        return self.points[i] * (1 - w) + self.points[i + 1] * w

    def arm_at(self, times: np.ndarray) -> np.ndarray:
        """(len(times), J) lagged joint angles at ``times``, rad (linear interpolation)."""
        times = np.asarray(times, float)
        return np.stack([np.interp(times, self.t, self.q_arm[:, j]) for j in range(self.q_arm.shape[1])], axis=1)


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
        ValueError: bad shapes; FloatingPointError: the simulation diverged.
    """
    import time

    t_cmd = np.asarray(t_cmd, float)
    q_cmd = np.asarray(q_cmd, float)
    if q_cmd.ndim != 2 or q_cmd.shape != (len(t_cmd), arm.n_joints):
        raise ValueError(f"q_cmd must be ({len(t_cmd)}, {arm.n_joints}), got {q_cmd.shape}")
    sim = ChainSim(phys, timestep)
    dt = sim.dt
    n = int(math.floor((t_cmd[-1] - t_cmd[0]) / dt + 1e-9)) + 1
    t = t_cmd[0] + dt * np.arange(n)
    q, _, _ = servo_lag(t_cmd, q_cmd, servo_lag_s, t)
    pose, vel, acc = hand_trajectory(arm, q, dt)
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
        sim.step(pose[i], vel[i], acc[i])   # positions are computed at the start of the step: t[i]
        pts[i] = sx[:, :2]
        if i % 2000 == 0 and not np.isfinite(d.qacc).all():
            raise FloatingPointError(f"lab physics diverged at t = {t[i]:.4f} s")
    wall = time.perf_counter() - t0
    if not np.isfinite(pts).all():
        raise FloatingPointError("lab physics diverged (non-finite positions)")
    return Recording(t, pts, q, speed, n / max(wall, 1e-9))
