"""The virtual lab's string as MuJoCo sees it: its physical description and the MJCF chain.

:class:`StringPhysics` (SI, validated when built, from ``lab.strings.<type>`` over
:data:`STRING_DEFAULTS`) and :func:`build_mjcf` (capsule links, hinges with EI / l_link,
clay spheres, rigid pipe spans, the driver body at the grasp; a slide per link where a drawn
material stretches, :func:`slide_spring`). A drawn material (``lab.material``, :mod:`.materials`)
replaces the table's cord. How the chain is stepped,
dragged and driven is :mod:`stringcast_lab.physics`, whose docstring gives the physics.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from collections.abc import Mapping

from stringcast.core import Campaign, ConfigError

from .settings import LabSettings
from .materials import lab_material

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

#: Keys a drawn material (:mod:`.materials`) or a ``lab.strings`` entry may add; absent, the cord
#: is as it always was: inextensible in the chain, the rod's 1 GPa braid, the chain's compliant
#: grasp hinge and the rod's rigid clamp.
DRAWN_KEYS = ("axial_EA", "axial_damping", "grasp")
GRASPS = (None, "clamp", "pivot")
DRIVER_ARMATURE = (200.0, 200.0, 20.0)    # kg, kg, kg m^2 on slide x, slide y, hinge z
G_ACC = 9.81                              # m/s^2
V_CAST = 10.0                             # m/s, a cast's tip speed for the reference tension
STRETCH_MIN = 5e-3                        # the chain stretches where a cast strains the string more


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
        axial_EA: N, or None (the cord as always: the chain inextensible, the rod's 1 GPa braid).
        axial_damping: Kelvin-Voigt eta_a on the axial strain rate, N s, or None (the rod's loss
            factor rule). grasp: ``clamp`` (leaves the gripper along its axis through a hinge of
            grasp_stiffness / grasp_damping, both physics), ``pivot`` (a free pivot with
            grasp_damping), or None (as always: the chain's compliant hinge, the rod's rigid clamp).
        material: the drawn material's name (``kind (seed N)``), None for ``lab.strings``' cord.
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
    axial_EA: float | None = None
    axial_damping: float | None = None
    grasp: str | None = None
    material: str | None = None

    def __post_init__(self):
        if self.n_links < 2:
            raise ConfigError("lab: a string needs at least 2 links")
        for name in ("length", "density", "diameter"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"lab string: {name} must be positive")
        for name in ("bending_EI", "bending_damping", "grasp_stiffness", "grasp_damping"):
            if getattr(self, name) < 0:
                raise ConfigError(f"lab string: {name} must not be negative")
        for name in ("axial_EA", "axial_damping"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v >= (0 if name == "axial_damping" else 1e-300)):
                raise ConfigError(f"lab string: {name} must be positive (or absent), got {v}")
        if self.grasp not in GRASPS:
            raise ConfigError(f"lab string: grasp {self.grasp!r} is not one of {list(GRASPS)}")
        if self.grasp == "pivot" and self.grasp_stiffness != 0:
            raise ConfigError("lab string: a pivot grasp has no stiffness (grasp_stiffness 0)")
        for at, mass, dia in self.weights:
            if not (0 <= at <= self.length + 1e-9 and mass > 0 and dia > 0):
                raise ConfigError(f"lab string: bad weight at {at} m, mass {mass} kg")
        for a, b, _rho, _dia in self.pipes:
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

    @property
    def cast_tension(self) -> float:
        """A cast's reference tension at the grasp, N: the whole mass at g + V_CAST^2 / L (a string
        whirled at V_CAST m/s about the grasp, plus its weight; module doc)."""
        return self.mass * (G_ACC + V_CAST ** 2 / self.length)

    @property
    def stretches(self) -> bool:
        """True if the string stretches enough to matter: an ``axial_EA`` under which a cast's
        tension (:attr:`cast_tension`) strains it more than STRETCH_MIN. Then the MuJoCo chain gets
        a slide joint per link; else it is inextensible (as ``lab.strings``' cord always was)."""
        return self.axial_EA is not None and self.cast_tension / self.axial_EA > STRETCH_MIN

    @classmethod
    def from_campaign(cls, campaign: Campaign, config: Mapping) -> StringPhysics:
        """Physical values for the campaign's string: ``lab.strings`` (default, then its type), its
        cord replaced by the drawn material where ``lab.material`` names one
        (:func:`~.materials.lab_material`: density, diameter, bending, stretch, damping, grasp;
        clay lumps and pipes stay the table's).

        Raises:
            ConfigError: unknown keys, bad values or a bad ``lab.material``.
        """

        lab = LabSettings.from_config(config)
        table = lab.strings
        vals = dict(STRING_DEFAULTS)
        vals.update(table.get("default", {}) or {})
        if campaign.string_id is not None:
            vals.update(table.get(str(campaign.string_id), {}) or {})
        drawn = lab_material(lab)
        if drawn is not None:
            vals.update(drawn.strings_entry())
        if "damping" in vals:
            import warnings

            warnings.warn("lab.strings: key 'damping' is not used (its unit was undefined); "
                          "set bending_damping (N m^2 s) instead", stacklevel=2)
            vals.pop("damping")
        unknown = set(vals) - set(STRING_DEFAULTS) - set(DRAWN_KEYS)
        if unknown:
            raise ConfigError(f"lab.strings: unknown keys {sorted(unknown)} (known: {sorted(STRING_DEFAULTS)})")
        s = campaign.string
        n_links = lab.links_per_point * s.n_points
        clay = vals["clay_diameter_mm"] / 1000
        pipe_d = vals["pipe_diameter_mm"] / 1000
        pipe_rho = vals["pipe_density_g_per_m"] / 1000
        air = lab.air
        return cls(
            length=s.length, n_links=n_links, density=vals["density_g_per_m"] / 1000,
            diameter=vals["diameter_mm"] / 1000, bending_EI=float(vals["bending_EI"]),
            bending_damping=float(vals["bending_damping"]),
            grasp_stiffness=float(vals["grasp_stiffness"]), grasp_damping=float(vals["grasp_damping"]),
            weights=tuple((float(at), float(m), clay) for at, m in s.weights),
            pipes=tuple((float(a), float(b), pipe_rho, pipe_d) for a, b in s.stiff_sections),
            air_density=float(air.get("density_kg_m3", 1.2)),
            air_viscosity=float(air.get("viscosity_pa_s", 1.8e-5)),
            axial_EA=_opt(vals.get("axial_EA")), axial_damping=_opt(vals.get("axial_damping")),
            grasp=vals.get("grasp"), material=None if drawn is None else f"{drawn.kind} (seed {drawn.seed})",
        )


def _opt(v) -> float | None:
    return None if v is None else float(v)


def _rigid_joint(phys: StringPhysics, k: int) -> bool:
    """True if the hinge at the start of link k (k >= 1) lies strictly inside a pipe."""
    s = k * phys.link_length
    return any(a + 1e-9 < s < b - 1e-9 for a, b, _, _ in phys.pipes)


def link_diameter(phys: StringPhysics, k: int) -> float:
    """Outer diameter of link k: the pipe's where a pipe covers most of the link, else the cord's."""
    s0, s1 = k * phys.link_length, (k + 1) * phys.link_length
    d = phys.diameter
    for a, b, _, dia in phys.pipes:
        if min(b, s1) - max(a, s0) > 0.5 * phys.link_length:
            d = max(d, dia)
    return d


def weight_link(phys: StringPhysics, at: float) -> int:
    """The link that carries a weight at arc length ``at``."""
    return int(min(phys.n_links - 1, max(0, math.floor(at / phys.link_length + 1e-9))))


def slide_spring(phys: StringPhysics) -> tuple[float, float]:
    """(stiffness N/m, damping N s/m) of each link's slide joint where the string stretches
    (:attr:`StringPhysics.stretches`), else (0, 0).

    The n_s slides (at every link start but the first and those inside a pipe) share the cord's
    length L_c (L less the pipes): k = EA n_s / L_c and d = eta_a n_s / L_c, so a hanging string
    stretches by integral T(s) / EA ds exactly for a uniform string or an end mass (the discrete
    sum over the slides' tensions is that integral's trapezoid, exact for a linear T)."""
    if not phys.stretches:
        return 0.0, 0.0
    n_s = sum(1 for k in range(1, phys.n_links) if not _rigid_joint(phys, k))
    l_c = max(phys.length - sum(b - a for a, b, _, _ in phys.pipes), phys.link_length)
    eta = phys.axial_damping or 0.0
    return phys.axial_EA * n_s / l_c, eta * n_s / l_c


def build_mjcf(phys: StringPhysics, timestep: float) -> str:
    """The MJCF text of driver + chain.

    A string that stretches (:attr:`StringPhysics.stretches`) has, after each inner hinge
    ``h{k}``, a slide ``a{k}`` along the link (:func:`slide_spring`): it opens a gap between
    link k - 1's end and link k, and the sites follow. A ``pivot`` grasp is the grasp hinge with
    no stiffness.

    Bodies ``link0..`` (each capsule along its local +x from its hinge), sites
    ``s0..s{n_links}`` at every link start and the tip (arc length k * l_link).
    Gravity is -9.81 along world y.
    """
    ll = phys.link_length
    k_hinge = phys.bending_EI / ll
    d_hinge = phys.bending_damping / ll
    k_slide, d_slide = slide_spring(phys)
    xs = [
        '<mujoco model="stringcast_lab">',
        '  <compiler angle="radian" autolimits="true"/>',
        f'  <option timestep="{timestep:.9g}" integrator="Euler" gravity="0 -9.81 0">',
        '    <flag contact="disable" energy="enable"/>',
        '  </option>',
        '  <worldbody>',
        '    <body name="driver">',
        f'      <joint name="drv_x" type="slide" axis="1 0 0" armature="{DRIVER_ARMATURE[0]:g}"/>',
        f'      <joint name="drv_y" type="slide" axis="0 1 0" armature="{DRIVER_ARMATURE[1]:g}"/>',
        f'      <joint name="drv_phi" type="hinge" axis="0 0 1" armature="{DRIVER_ARMATURE[2]:g}"/>',
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
                if phys.stretches:      # after the hinge: along the link's own axis
                    xs.append(f'{indent}  <joint name="a{k}" type="slide" axis="1 0 0" '
                              f'stiffness="{k_slide:.9g}" damping="{d_slide:.9g}"/>')
        mass = phys.density * ll
        for a, b, rho, _ in phys.pipes:
            mass += rho * max(0.0, min(b, s1) - max(a, s0))
        rad = link_diameter(phys, k) / 2
        xs.append(f'{indent}  <geom type="capsule" fromto="0 0 0 {ll:.9g} 0 0" size="{rad:.6g}" '
                  f'mass="{mass:.9g}"/>')
        xs.append(f'{indent}  <site name="s{k}" pos="0 0 0"/>')
        for at, m, dia in phys.weights:
            if weight_link(phys, at) == k:
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
