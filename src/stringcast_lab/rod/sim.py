"""The rod simulation: :class:`RodSim` (one PyElastica rod, clamped to a hand) and
:func:`simulate_rod` (a lab trial's physics, the same contract as :func:`.physics.simulate`)."""
from __future__ import annotations

import math
import time

import numpy as np

from stringcast.core import ArmSpec
from ..mjcf import StringPhysics
from ..recording import Recording, command_arrays
from ..servo import hand_trajectory, servo_lag
from .material import CORD_E_AXIAL, G_ACC, RodMaterial, rod_material
from .plugins import _PLUGINS, HandPath, directors, plugin_classes
from .statics import hanging_nodes, rod_equilibrium

REFINEMENTS = 2
"""How many times :func:`simulate_rod` halves a diverged run's step and runs it again."""


_SIMULATOR: list = []


def _simulator():
    """A new PyElastica system collection with the modules the lab uses (constraints, forcing,
    damping); its class is made once, PyElastica imported then (see :mod:`.plugins`)."""
    if not _SIMULATOR:
        import elastica as ea

        class Simulator(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):
            """PyElastica's system collection with constraints, forcing and damping."""

        _SIMULATOR.append(Simulator)
    return _SIMULATOR[0]()


def build_rod(mat: RodMaterial):
    """A straight ``elastica.CosseratRod`` hanging along -y from the origin with ``mat``'s
    per-element stiffness (shear_matrix diag(GA, GA, EA)), junction stiffness (bend_matrix
    diag(EI, EI, GJ), halves in series), node masses (clay included) and inertias."""
    import elastica as ea

    n = mat.n
    rod = ea.CosseratRod.straight_rod(
        n, np.zeros(3), np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0]), mat.length,
        mat.radius.copy(), mat.lam / (math.pi * mat.radius ** 2),
        youngs_modulus=CORD_E_AXIAL, shear_modulus=CORD_E_AXIAL / 3)
    rod.shear_matrix[:] = 0.0
    rod.bend_matrix[:] = 0.0
    rod.mass_second_moment_of_inertia[:] = 0.0
    rod.inv_mass_second_moment_of_inertia[:] = 0.0
    for i, v in enumerate((mat.GA, mat.GA, mat.EA)):
        rod.shear_matrix[i, i, :] = v
    for i, v in enumerate((mat.junction_EI, mat.junction_EI, mat.junction_GJ)):
        rod.bend_matrix[i, i, :] = v
    for i, v in enumerate((mat.J, mat.J, 2 * mat.J)):
        rod.mass_second_moment_of_inertia[i, i, :] = v
        rod.inv_mass_second_moment_of_inertia[i, i, :] = 1.0 / v
    rod.mass[:] = mat.node_mass
    return rod


class RodSim:
    """One string as a PyElastica Cosserat rod, clamped to a hand, under gravity and air drag.

    Args:
        phys: the string. dt: the step, s (default: the material's stable step).
        material: its :func:`~.material.rod_material` if already made.

    Attributes:
        mat: the :class:`~.material.RodMaterial`. rod: the ``elastica.CosseratRod``.
        hand: the :class:`~.plugins.HandPath` the clamp follows (replace it to drive the rod).
        time: the simulation time, s. steps: steps taken.

    Raises:
        ValueError: a dt above the material's stable step.
    """

    def __init__(self, phys: StringPhysics, dt: float | None = None, material: RodMaterial | None = None):
        self.phys = phys
        self.mat = material or rod_material(phys)
        self.dt = float(dt or self.mat.dt_max)
        if self.dt > self.mat.dt_max * (1 + 1e-9):
            raise ValueError(f"RodSim: dt {self.dt:.3g} s is above the stable {self.mat.dt_max:.3g} s")
        import elastica as ea

        HandClamp, AirDrag, CordDamping = plugin_classes()
        self.hand = HandPath.hold((0.0, 0.0, -math.pi / 2))
        self.rod = build_rod(self.mat)
        sim = self.sim = _simulator()
        sim.append(self.rod)
        sim.constrain(self.rod).using(HandClamp, clamp=self, held=self.mat.grasp == "rigid")
        sim.add_forcing_to(self.rod).using(ea.GravityForces, acc_gravity=np.array([0.0, -G_ACC, 0.0]))
        sim.add_forcing_to(self.rod).using(AirDrag, self.mat, phys.air_density, phys.air_viscosity)
        if self.mat.grasp == "clamp":
            sim.add_forcing_to(self.rod).using(_PLUGINS["grasp"], self.mat.k_grasp, self)
        sim.dampen(self.rod).using(CordDamping, material=self.mat, time_step=self.dt, clamp=self)
        sim.finalize()
        self.stepper = ea.PositionVerlet()
        self.time = 0.0
        self.steps = 0

    def reset_hanging(self, pose, exact: bool = True) -> float:
        """Put the rod at rest hanging from the hand pose (x, y, phi_h) held still, time 0:
        :func:`~.statics.hanging_nodes` (inextensible, then stretched), refined to the rod's own
        equilibrium by :func:`~.statics.rod_equilibrium` unless ``exact`` is False (then the
        inextensible shape, unstretched). Returns the largest residual force, N (nan if not exact)."""
        pose = np.asarray(pose, float)
        self.set_nodes(hanging_nodes(self.mat, pose[:2], pose[2], stretch=exact))
        resid = rod_equilibrium(self.rod, self.mat, pose, self.nodes()) if exact else float("nan")
        self.hand = HandPath.hold(pose)
        self.time = 0.0
        return resid

    def set_nodes(self, nodes: np.ndarray) -> None:
        """Place the rod at rest on (n + 1, 2) node positions, m, each element's directors along it."""
        rod = self.rod
        rod.position_collection[:2] = np.asarray(nodes, float).T
        rod.position_collection[2] = 0.0
        d = np.diff(nodes, axis=0)
        for e, phi in enumerate(np.arctan2(d[:, 1], d[:, 0])):
            rod.director_collection[..., e] = directors(phi)
        rod.velocity_collection[:] = 0.0
        rod.omega_collection[:] = 0.0

    def step(self, n: int = 1) -> None:
        """Take ``n`` steps of dt (PyElastica's ``PositionVerlet``)."""
        for _ in range(int(n)):
            self.time = self.stepper.step(self.sim, self.time, self.dt)
        self.steps += int(n)

    def settle(self, pose, duration_s: float = 0.3, speed_tol: float = 1e-3) -> float:
        """:meth:`reset_hanging` at ``pose`` (x, y, phi_h), then ``duration_s`` of free dynamics with
        the hand held; time back to 0. Returns the largest node speed left, m/s (a warning above
        ``speed_tol``)."""
        self.reset_hanging(pose)
        self.step(int(round(duration_s / self.dt)))
        self.time = 0.0
        speed = self.max_speed()
        if speed > speed_tol:
            import warnings

            warnings.warn(f"lab (elastica): the string is still moving at {speed:.2g} m/s after settling", stacklevel=2)
        return speed

    def nodes(self) -> np.ndarray:
        """(n + 1, 2) world (x, y) of the nodes, m (node k at rest arc k l; node 0 the grasp)."""
        return self.rod.position_collection[:2].T.copy()

    def max_speed(self) -> float:
        """Largest node speed, m/s."""
        return float(np.hypot(*self.rod.velocity_collection[:2]).max())

    def energy(self) -> dict:
        """The rod's energies, J: ``kinetic`` (translation + rotation), ``gravity`` (sum m g y),
        ``elastic`` (bending, twist, shear and stretch), ``total``. PyElastica's ``CosseratRod``
        energy methods, strains recomputed at the current state."""
        rod = self.rod
        rod.compute_internal_forces_and_torques(self.time)
        kin = float(rod.compute_translational_energy() + rod.compute_rotational_energy())
        grav = float(G_ACC * np.sum(rod.mass * rod.position_collection[1]))
        ela = float(rod.compute_bending_energy() + rod.compute_shear_energy())
        return {"kinetic": kin, "gravity": grav, "elastic": ela, "total": kin + grav + ela}


def simulate_rod(phys: StringPhysics, arm: ArmSpec, t_cmd: np.ndarray, q_cmd: np.ndarray, timestep: float,
                 servo_lag_s: float, settle_s: float = 0.3, progress: bool = False) -> Recording:
    """Settle the rod at q_cmd[0], then swing it through the commanded joint motion.

    The same contract as :func:`stringcast_lab.physics.simulate`: the hand is the lagged arm's
    (:func:`~stringcast_lab.servo.servo_lag`, :func:`~stringcast_lab.servo.hand_trajectory`, on the
    rod's half-step clock), the rod steps at dt = timestep / k (k the fewest whole steps per sample
    within the stable step), and the nodes are recorded every ``timestep`` s.

    The stable step (:func:`~stringcast_lab.rod.material.stable_step`) is the undamped wave
    limit; a fast swing of a damped, weighted rod can still blow up at it (seen once in stop 47's
    140 loop campaigns: type 7, seed 7, at t = 1.21 s). A diverged run is therefore run again from the
    start at half the step, up to ``REFINEMENTS`` times; the recording's ``detail`` says how
    many steps per sample it took (``steps_per_sample``) and how many restarts (``refinements``).

    Args:
        phys: the string (``phys.n_links`` elements). arm: the planar arm.
        t_cmd: (K,) s, q_cmd: (K, J) rad, the controller's set-points.
        timestep: the recording interval, s (``lab.timestep_s``). servo_lag_s: the servo's lag, s.
        settle_s: free dynamics at the first pose after the static equilibrium, s.

    Returns:
        A :class:`~stringcast_lab.recording.Recording` (physics "elastica") from t_cmd[0] to
        t_cmd[-1], points (N, n_links + 1, 2) = the nodes.

    Raises:
        ValueError: bad shapes or t_cmd not increasing (:func:`~stringcast_lab.recording.command_arrays`).
        FloatingPointError: the simulation diverged at every step tried.
    """
    t_cmd, q_cmd = command_arrays(t_cmd, q_cmd, arm.n_joints, "simulate_rod")
    mat = rod_material(phys)
    k0 = max(1, math.ceil(timestep / mat.dt_max - 1e-9))
    for refinement in range(REFINEMENTS + 1):
        try:
            rec = _swing(phys, mat, arm, t_cmd, q_cmd, timestep, k0 * 2 ** refinement, servo_lag_s, settle_s,
                         progress)
        except FloatingPointError as err:
            if refinement == REFINEMENTS:
                raise FloatingPointError(f"{err}, also at {REFINEMENTS} halvings of the step") from err
            continue
        rec.detail["refinements"] = refinement
        return rec


def _swing(phys: StringPhysics, mat: RodMaterial, arm: ArmSpec, t_cmd: np.ndarray, q_cmd: np.ndarray, timestep: float,
           k: int, servo_lag_s: float, settle_s: float, progress: bool) -> Recording:
    """:func:`simulate_rod` at k rod steps per recorded sample. Raises FloatingPointError: it diverged."""
    sim = RodSim(phys, timestep / k, mat)
    n = int(math.floor((t_cmd[-1] - t_cmd[0]) / timestep + 1e-9)) + 1
    t = t_cmd[0] + timestep * np.arange(n)
    h = sim.dt / 2                                      # the clamp is set at whole and half steps
    q_h, _, _ = servo_lag(t_cmd, q_cmd, servo_lag_s, t_cmd[0] + h * np.arange(2 * k * (n - 1) + 1))
    pose, vel, _ = hand_trajectory(arm, q_h, h)
    speed = sim.settle(pose[0], settle_s)
    sim.hand = HandPath(t[0], h, pose, vel)
    sim.time = float(t[0])
    pts = np.empty((n, mat.n + 1, 2))
    pts[0] = sim.nodes()
    it = range(1, n)
    if progress:
        from tqdm import tqdm
        it = tqdm(it, desc="physics (elastica)", unit="sample", mininterval=1.0, leave=False, disable=None)
    wall0, steps0 = time.perf_counter(), sim.steps
    for i in it:
        sim.step(k)
        sim.time = float(t[i])
        pts[i] = sim.nodes()
        if i % 200 == 0 and not np.isfinite(pts[i]).all():
            raise FloatingPointError(f"lab physics (elastica) diverged at t = {t[i]:.4f} s")
    wall = time.perf_counter() - wall0
    if not np.isfinite(pts).all():
        raise FloatingPointError("lab physics (elastica) diverged (non-finite positions)")
    detail = {"timestep_s": sim.dt, "steps_per_sample": k, **mat.summary()}
    return Recording(t, pts, q_h[::2 * k], speed, (sim.steps - steps0) / max(wall, 1e-9),
                     physics="elastica", detail=detail)
