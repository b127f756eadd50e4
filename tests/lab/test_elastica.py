"""The lab's second physics (``lab.physics: elastica``): the string as a PyElastica Cosserat rod.

Sanity against analytic results (the hanging stretch, a weighted string's pendulum period,
energy that only decays without drive), the clamp following the hand, the air-drag
correlations, and a tiny trial writing the same files as the MuJoCo lab. Small rods (10-15
elements), a second or less of simulated time each.
"""
import ast
import copy
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("elastica")

from stringcast.core import ConfigError  # noqa: E402
from stringcast.core.arm import hand_pose  # noqa: E402
from stringcast_lab import StringPhysics, run_trial  # noqa: E402
from stringcast_lab.rod import RodSim, rod_material, simulate_rod  # noqa: E402
from stringcast_lab.rod.material import CORD_E_AXIAL, G_ACC  # noqa: E402
from stringcast_lab.rod.plugins import HandPath, cylinder_cd, drag_kernel, skin_cf, sphere_cd  # noqa: E402
from stringcast_lab.trial import lab_physics  # noqa: E402

from tests.lab.test_lab import Q0, _tiny, _wrist_flick  # noqa: E402

DOWN = -math.pi / 2


def _phys(**kw) -> StringPhysics:
    """A 0.3 m cord of 15 elements with a 10 g clay lump at its tip (the default cord's values)."""
    d = dict(length=0.3, n_links=15, density=0.02, diameter=0.003, bending_EI=2e-5, bending_damping=2e-7,
             grasp_stiffness=0.0, grasp_damping=0.0, weights=((0.3, 0.01, 0.016),))
    d.update(kw)
    return StringPhysics(**d)


def _tilted(sim: RodSim, grasp, theta: float) -> np.ndarray:
    """Nodes of the rod held straight down by the clamp for its first element, then straight at
    ``theta`` rad from the vertical (a released pendulum)."""
    l, n = sim.mat.l, sim.mat.n
    nodes = np.empty((n + 1, 2))
    nodes[0] = grasp
    nodes[1] = grasp + [0.0, -l]
    nodes[2:] = nodes[1] + np.outer(np.arange(1, n) * l, [math.sin(theta), -math.cos(theta)])
    return nodes


# ------------------------------------------------------------------------------- statics
def test_hangs_straight_down_with_its_static_stretch():
    """Released unstretched, the rod settles straight below the grasp, each element stretched by
    the weight below it over EA (the top one by g (lam (L - l/2) + M) / EA), the tip that much
    more than L below; the exact equilibrium the lab starts from is the same state."""
    phys = _phys()
    sim = RodSim(phys)
    pose = np.array([0.5, 0.2, DOWN])
    sim.reset_hanging(pose, exact=False)                  # straight, unstretched
    sim.step(int(0.6 / sim.dt))
    nodes = sim.nodes()
    assert sim.max_speed() < 1e-4
    assert np.abs(nodes[:, 0] - pose[0]).max() < 1e-9      # straight down
    EA = CORD_E_AXIAL * math.pi * phys.diameter ** 2 / 4
    L, lam, M, l = phys.length, phys.density, 0.01, phys.link_length
    top = np.linalg.norm(nodes[1] - nodes[0]) / l - 1
    assert top == pytest.approx(G_ACC * (lam * (L - l / 2) + M) / EA, rel=0.01)
    s = (np.arange(phys.n_links) + 0.5) * l
    stretch = np.sum(l * G_ACC * (lam * (L - s) + M) / EA)
    assert 1e-6 < stretch < 1e-4                            # a braid barely stretches under 16 g
    assert pose[1] - nodes[-1, 1] - L == pytest.approx(stretch, rel=0.01)
    exact = RodSim(phys)
    assert exact.reset_hanging(pose) < 1e-9                 # residual force, N
    assert np.abs(exact.nodes() - nodes).max() < 1e-7              # of a 5 um stretch


def test_settles_still_from_any_gripper_angle():
    """The lab's settling (exact equilibrium, then free dynamics): at rest, the grasp at the hand,
    element 0 along the gripper axis, the weighted tip lowest."""
    sim = RodSim(_phys())
    pose = np.array([0.6, 0.1, -0.3])
    assert sim.settle(pose, 0.05) < 1e-8
    nodes = sim.nodes()
    assert nodes[0] == pytest.approx(pose[:2], abs=1e-12)
    d3 = sim.rod.director_collection[2, :2, 0]
    assert d3 == pytest.approx([math.cos(pose[2]), math.sin(pose[2])], abs=1e-12)
    assert np.argmin(nodes[:, 1]) == len(nodes) - 1


def test_the_hanging_rod_does_not_depend_on_the_hands_turn_count():
    """phi_h is the arm's joint sum, unwrapped: a gripper 22 deg left of down is 4.32 rad as often as
    -1.96 rad. The rod hangs alike from both, and from neither with a loop: below the clamped element
    every node lies lower than the one before (at 4.32 rad the start once wound it by -338 deg)."""
    phys = _phys(weights=())
    shapes = []
    for phi in (DOWN - 0.4, DOWN - 0.4 + 2 * math.pi, DOWN + 1.2, DOWN + 1.2 - 2 * math.pi):
        sim = RodSim(phys)
        assert sim.reset_hanging(np.array([0.5, 0.2, phi])) < 1e-9
        nodes = sim.nodes()
        assert np.all(np.diff(nodes[1:, 1]) < 0)
        shapes.append(nodes)
    assert np.abs(shapes[0] - shapes[1]).max() < 1e-9
    assert np.abs(shapes[2] - shapes[3]).max() < 1e-9


# ------------------------------------------------------------------------------- dynamics
def _bessel_period(L: float, lam: float, M: float) -> float:
    """Fundamental period, s, of a heavy string of length L m, lam kg/m, pinned at its top with a
    point mass M kg at its bottom (small swings): f = A J0(x) + B Y0(x), x = 2 w sqrt(z'/g), z' the
    height above the tip plus M / lam; f = 0 at the top, -M w^2 f = M g f' at the mass."""
    from scipy.optimize import brentq
    from scipy.special import j0, j1, y0, y1

    a, g = M / lam, G_ACC

    def det(w):
        xt, xa, k = 2 * w * math.sqrt((L + a) / g), 2 * w * math.sqrt(a / g), w / math.sqrt(g * a)
        return (j0(xt) * (-k * y1(xa) + w * w / g * y0(xa)) - y0(xt) * (-k * j1(xa) + w * w / g * j0(xa)))

    ws = np.linspace(0.2, 2.5 * math.sqrt(g / L), 500)
    v = np.array([det(w) for w in ws])
    i = int(np.nonzero(np.sign(v[:-1]) != np.sign(v[1:]))[0][0])
    return 2 * math.pi / brentq(det, ws[i], ws[i + 1])


def test_weighted_string_swings_with_the_analytic_period():
    """A 0.2 m cord with 10 g at its tip, released 0.1 rad from hanging: the centre of mass crosses
    the vertical with the period of a heavy string with an end mass (Bessel functions), its free
    length L - l below the clamped first element, within 1.5 % (the full length L would be 4 %
    off: the clamp holds the first element along the gripper)."""
    phys = _phys(length=0.2, n_links=10, bending_EI=2e-6, bending_damping=2e-8, weights=((0.2, 0.01, 0.016),))
    sim = RodSim(phys)
    sim.reset_hanging([0.0, 0.0, DOWN])
    sim.set_nodes(_tilted(sim, np.zeros(2), 0.1))
    m = sim.rod.mass
    ts, xs = [], []
    every = int(round(0.002 / sim.dt))
    while sim.time < 1.3:
        sim.step(every)
        ts.append(sim.time)
        xs.append(np.sum(m * sim.rod.position_collection[0]) / m.sum())
    ts, xs = np.array(ts), np.array(xs)
    c = np.nonzero(np.sign(xs[:-1]) != np.sign(xs[1:]))[0]
    crossings = ts[c] - xs[c] * (ts[c + 1] - ts[c]) / (xs[c + 1] - xs[c])
    assert len(crossings) >= 3
    period = 2 * np.mean(np.diff(crossings))
    free = phys.length - phys.link_length
    expect = _bessel_period(free, phys.density, 0.01)
    assert period == pytest.approx(expect, rel=0.015)      # +0.6 % measured


def test_energy_only_decays_without_drive():
    """Released 0.8 rad from hanging with the hand still: the total energy (kinetic, gravity,
    elastic) never rises, and air drag and damping take a share of the swing's in 0.4 s more than
    ten times what the integrator wobbles; without air and bending damping the swing keeps it."""
    def swing(phys):
        sim = RodSim(phys)
        sim.reset_hanging([0.0, 0.0, DOWN])
        rest = sim.energy()["total"]
        sim.set_nodes(_tilted(sim, np.zeros(2), 0.8))
        e = [sim.energy()["total"]]
        every = int(round(0.004 / sim.dt))
        while sim.time < 0.4:
            sim.step(every)
            e.append(sim.energy()["total"])
        return np.array(e) - rest

    e = swing(_phys())
    free = swing(_phys(bending_damping=0.0, air_density=0.0))
    assert e[0] > 0.005                                     # J above the hanging rest state
    assert np.all(np.diff(e) <= 1e-6 * e[0])
    assert e[-1] < 0.985 * e[0]                             # 2.4 % in 0.4 s (air, mostly)
    assert np.ptp(free) < 0.001 * free[0]                   # 0.02 %: the integrator's own wobble


def test_clamp_follows_the_hand():
    """Driven by a hand that moves and turns: node 0 is the hand's point to micrometres and
    element 0's axis d3 its gripper angle phi_h at every sample; the cord's first element is
    along it within the shear its load allows (some degrees: the discrete clamp's compliance)."""
    sim = RodSim(_phys())
    p0 = np.array([0.5, 0.2, -1.2])
    sim.reset_hanging(p0)
    h, f = sim.dt / 2, 3.0
    t = np.arange(int(0.25 / h) + 2) * h
    s, c = np.sin(2 * math.pi * f * t), np.cos(2 * math.pi * f * t)
    w = 2 * math.pi * f
    pose = p0 + np.column_stack([0.08 * s, 0.04 * (1 - c), 0.8 * s])
    vel = np.column_stack([0.08 * w * c, 0.04 * w * s, 0.8 * w * c])
    sim.hand = HandPath(0.0, h, pose, vel)
    every = int(round(0.005 / sim.dt))
    worst_tangent = 0.0
    while sim.time < 0.25:
        sim.step(every)
        i = sim.hand.index(sim.time)
        assert sim.nodes()[0] == pytest.approx(pose[i, :2], abs=1e-6)
        phi = pose[i, 2]
        assert sim.rod.director_collection[2, :2, 0] == pytest.approx([math.cos(phi), math.sin(phi)], abs=1e-9)
        d = np.diff(sim.nodes()[:2], axis=0)[0]
        worst_tangent = max(worst_tangent, abs(math.remainder(math.atan2(d[1], d[0]) - phi, 2 * math.pi)))
    assert sim.max_speed() > 0.3                            # it was really swung
    assert worst_tangent < math.radians(10)                # element 0's shear: GA = 11 N, ~1 N across


def _weighted_flick():
    """(phys, arm, t_cmd, q_cmd): a 0.15 m rod with a weight at its tip, the UR5e's wrist flick."""
    from stringcast.core import ArmSpec, load_config

    cfg = load_config(Path(__file__).resolve().parents[2] / "config" / "config.yaml")
    arm = ArmSpec.from_config("a", cfg["arms"]["ur5e_planar"])
    t_cmd, q_cmd, _ = _wrist_flick()
    return _phys(length=0.15, n_links=10, weights=((0.15, 0.005, 0.016),)), arm, t_cmd, q_cmd


def test_simulate_rod_records_the_lagged_hand():
    """simulate_rod's Recording: sites = nodes every lab.timestep_s, site 0 at the lagged arm's
    hand, the first element along its gripper axis, the joints those of the servo."""
    phys, arm, t_cmd, q_cmd = _weighted_flick()
    rec = simulate_rod(phys, arm, t_cmd, q_cmd, 5e-5, 0.008, settle_s=0.02)
    assert rec.physics == "elastica" and rec.points.shape == (len(rec.t), 11, 2)
    assert rec.t[1] - rec.t[0] == pytest.approx(5e-5) and rec.t[-1] == pytest.approx(t_cmd[-1], abs=5e-5)
    hand = hand_pose(arm, rec.q_arm)
    assert np.abs(rec.points[:, 0] - hand[:, :2]).max() < 1e-6
    first = rec.points[:, 1] - rec.points[:, 0]
    off = np.abs(np.remainder(np.arctan2(first[:, 1], first[:, 0]) - hand[:, 2] + math.pi, 2 * math.pi) - math.pi)
    assert off.max() < math.radians(5)
    assert np.ptp(rec.points[:, -1, 0]) > 0.02               # the flick moved the tip
    assert rec.settle_speed < 1e-8 and rec.detail["timestep_s"] <= rec.detail["dt_max_s"]
    assert rec.detail["refinements"] == 0                   # the stable step held


# ------------------------------------------------------------------------------- material, air
def test_material_from_the_string_description(config):
    """Masses add up (cord, pipe, clay), the pipe is stiffer than the cord by orders of magnitude,
    the clay sits on the nodes by the lever rule, and the step is half the axial wave's crossing."""
    from stringcast.core import resolve_campaign

    for sid in (2, 5):
        phys = StringPhysics.from_campaign(resolve_campaign({"string": sid, "target": 1}, config), config)
        mat = rod_material(phys)
        assert mat.node_mass.sum() == pytest.approx(phys.mass, rel=1e-12)
        assert mat.dt_max <= 0.5 * mat.l / math.sqrt(mat.EA.min() / mat.lam.max()) * 1.0001
        assert 2e-6 < mat.dt_max < 5e-5
    assert mat.EI.max() > 1000 * phys.bending_EI and not mat.pipe_capped
    covered = mat.EI > phys.bending_EI
    arc = (np.arange(mat.n) + 0.5) * mat.l
    (a, b, _, _), = phys.pipes
    assert np.all((arc[covered] > a) & (arc[covered] < b))
    phys2 = StringPhysics.from_campaign(resolve_campaign({"string": 2, "target": 1}, config), config)
    mat2 = rod_material(phys2)
    k = int(round(0.12 / mat2.l))                           # the clay at 120 mm falls on a node
    assert mat2.node_mass[k] == pytest.approx(mat2.lam[0] * mat2.l + 0.01)


def test_air_drag_correlations_and_directions():
    """Sucker-Brauer's cylinder (Cd 9.9 at Re 1, 1.45 at 100, 1.18 at 1e5), Morrison's sphere
    (24 / Re in creeping flow, 0.39-0.42 at Re 1e4); a straight cord moved broadside feels
    0.5 rho Cd d L v^2 against the motion, moved along its axis only a little skin friction."""
    assert cylinder_cd(1.0) == pytest.approx(9.94, abs=0.01)
    assert cylinder_cd(100.0) == pytest.approx(1.449, abs=0.005)
    assert cylinder_cd(1e5) == pytest.approx(1.175, abs=0.005)
    assert sphere_cd(0.01) == pytest.approx(2400, rel=0.01)
    assert 0.38 < sphere_cd(1e4) < 0.42
    n, L, d, v, rho, nu = 10, 0.3, 0.003, 4.0, 1.2, 1.5e-5
    tangents = np.tile([[1.0], [0.0], [0.0]], (1, n))
    lengths = np.full(n, L / n)
    none = (np.zeros(0, np.int64), np.zeros(0), np.zeros(0))
    forces = []
    for axis in (1, 0):
        vel = np.zeros((3, n + 1))
        vel[axis] = v
        out = np.zeros((3, n + 1))
        drag_kernel(vel, tangents, lengths, np.full(n, d), *none, rho, nu, L, out)
        forces.append(out.sum(axis=1))
    expect = 0.5 * rho * cylinder_cd(v * d / nu) * d * L * v * v
    assert -forces[0][1] == pytest.approx(expect, rel=1e-12) and forces[0][0] == 0.0
    along = 0.5 * rho * skin_cf(v * L / nu) * math.pi * d * L * v * v
    assert -forces[1][0] == pytest.approx(along, rel=1e-12) and along < 0.05 * expect


# ------------------------------------------------------------------------------- the lab
def test_trial_on_elastica_writes_the_mujoco_files(config, tmp_path):
    """``lab.physics: elastica`` films the same files as the MuJoCo lab, its ground truth naming
    the physics; the grasp is at the hand; an unknown physics is a ConfigError naming the key."""
    campaign, cfg = _tiny(config)
    t_cmd, q_cmd, t0 = _wrist_flick()
    runs = {}
    for name in ("mujoco", "elastica"):
        c = copy.deepcopy(cfg)
        c["lab"]["physics"] = name
        truth = run_trial(t_cmd, q_cmd, campaign, c, tmp_path / name, seed=5, motion_start_s=t0)
        runs[name] = truth
    files = {name: sorted(p.name for p in (tmp_path / name).iterdir()) for name in runs}
    assert files["elastica"] == files["mujoco"]
    import pandas as pd

    gts = {name: pd.read_parquet(tmp_path / name / "ground_truth.parquet") for name in runs}
    assert list(gts["elastica"].columns) == list(gts["mujoco"].columns)
    assert len(gts["elastica"]) == len(gts["mujoco"])
    truth = runs["elastica"]
    assert truth["physics"] == "elastica" and runs["mujoco"]["physics"] == "mujoco"
    assert set(truth) == set(runs["mujoco"])
    g0 = gts["elastica"].query("frame == 0 and point == 0")[["x_m", "y_m"]].to_numpy()[0]
    assert g0 == pytest.approx(hand_pose(campaign.arm, Q0)[:2], abs=1e-4)
    tips = [gts[name].query("point == 5")[["x_m", "y_m"]].to_numpy() for name in runs]
    assert np.abs(tips[0] - tips[1]).max() < 0.05            # the same string, another physics
    bad = copy.deepcopy(cfg)
    bad["lab"]["physics"] = "bogus"
    with pytest.raises(ConfigError, match="lab.physics.*mujoco.*elastica"):
        run_trial(t_cmd, q_cmd, campaign, bad, tmp_path / "bogus", seed=5, motion_start_s=t0)
    with pytest.raises(ConfigError, match="lab.physics"):
        lab_physics({"physics": "MuJoCo"})


def test_rod_shares_no_code_with_the_chain_or_the_model():
    """The rod imports from the lab only the string's description (mjcf.StringPhysics), the arm's
    servo, the Recording container and its set-point check: nothing of the MuJoCo chain
    (physics, air, the MJCF builders), nothing of the string model, and not MuJoCo itself."""
    import stringcast_lab.rod as rod

    allowed = {("stringcast_lab.mjcf", "StringPhysics"), ("stringcast_lab.recording", "Recording"),
               ("stringcast_lab.recording", "command_arrays"),
               ("stringcast_lab.servo", "hand_trajectory"), ("stringcast_lab.servo", "servo_lag")}
    for f in Path(rod.__file__).parent.glob("*.py"):
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Import):
                assert not any(a.name.split(".")[0] in ("mujoco", "stringcast") for a in node.names), f.name
            elif isinstance(node, ast.ImportFrom):
                mod = node.module or ""
                if node.level >= 2:                         # from ..x import y: the lab's modules
                    mod = "stringcast_lab." + mod
                elif node.level == 1:
                    continue                                # the rod package's own modules
                assert mod.split(".")[0] != "mujoco", f.name
                if mod.startswith("stringcast_lab"):
                    for a in node.names:
                        assert (mod, a.name) in allowed, f"{f.name} imports {a.name} from {mod}"
                elif mod.startswith("stringcast."):
                    assert mod == "stringcast.core", f"{f.name} imports {mod}"


def test_the_lab_imports_pyelastica_only_for_a_rod():
    """``import stringcast_lab`` (the MuJoCo lab, the trial, the rod package) leaves PyElastica
    unimported: it costs 0.5-0.9 s and only a rod needs it."""
    import subprocess
    import sys

    code = "import sys, stringcast_lab, stringcast_lab.rod; print('elastica' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_both_physics_check_the_set_points_alike():
    """The trial, the chain and the rod take the controller's set-points through one check (lab.recording)."""
    from stringcast_lab.recording import command_arrays

    t, q = command_arrays([0, 1, 2], [[0, 1], [1, 2], [2, 3]], 2, "sim")
    assert t.dtype == q.dtype == np.float64 and q.shape == (3, 2)
    with pytest.raises(ValueError, match=r"^sim: q_cmd must be \(3, 3\), got \(3, 2\)"):
        command_arrays(t, q, 3, "sim")
    with pytest.raises(ValueError, match=r"got \(6,\)"):
        command_arrays(t, q.ravel(), 2, "sim")
    with pytest.raises(ValueError, match=r"^run_trial: t_cmd must be \(K,\) strictly increasing"):
        command_arrays([0, 2, 1], q, 2, "run_trial")


def test_a_diverged_swing_is_run_again_at_half_the_step(monkeypatch):
    """simulate_rod: a run that blows up is run again from the start at half the step until it
    holds, up to REFINEMENTS times, and says so (``refinements``, ``steps_per_sample``); one that
    never holds raises.

    The blow-up is made, not hoped for: the first runs have the tip's position turned to NaN
    mid-swing (through ``RodSim.step``), as a diverged integrator leaves it. A step claimed too
    large diverges or not by rounding: 6 times the stable step held with OpenBLAS's AVX-512
    kernels and blew up with its AVX2 ones (issue 51)."""
    from stringcast_lab.rod import sim as rod_sim

    phys, arm, t_cmd, q_cmd = _weighted_flick()
    timestep, diverging = 5e-5, rod_sim.REFINEMENTS
    assert diverging >= 1
    k0 = max(1, math.ceil(timestep / rod_material(phys).dt_max - 1e-9))
    runs = []                                               # each run's RodSim, in order
    init, step = rod_sim.RodSim.__init__, rod_sim.RodSim.step

    def counted_init(self, *args, **kwargs):
        init(self, *args, **kwargs)
        runs.append(self)

    def poisoned_step(self, n=1):
        step(self, n)
        swinging = len(self.hand.pose) > 1                  # the swing's path, not the settling hold
        if swinging and self.time > 0.12 and runs.index(self) < diverging:     # the wrist turns from 0.1 s
            self.rod.position_collection[:, -1] = np.nan

    monkeypatch.setattr(rod_sim.RodSim, "__init__", counted_init)
    monkeypatch.setattr(rod_sim.RodSim, "step", poisoned_step)
    rec = simulate_rod(phys, arm, t_cmd, q_cmd, timestep, 0.008, settle_s=0.02)
    assert rec.detail["refinements"] == diverging == len(runs) - 1
    assert [r.dt for r in runs] == pytest.approx([timestep / (k0 * 2 ** i) for i in range(diverging + 1)])
    assert rec.detail["steps_per_sample"] == k0 * 2 ** diverging
    assert rec.detail["timestep_s"] == pytest.approx(timestep / (k0 * 2 ** diverging))
    assert np.isfinite(rec.points).all() and np.ptp(rec.points[:, -1, 0]) > 0.02   # the last run swung
    for fewer in range(diverging):                          # fewer halvings than the blow-ups need
        runs.clear()
        monkeypatch.setattr(rod_sim, "REFINEMENTS", fewer)
        with pytest.raises(FloatingPointError, match=f"diverged.*also at {fewer} halvings"):
            simulate_rod(phys, arm, t_cmd, q_cmd, timestep, 0.008, settle_s=0.02)
        assert len(runs) == fewer + 1                       # every step tried, then the error
