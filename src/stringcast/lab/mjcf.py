"""The virtual lab's string as MuJoCo sees it: its physical description and the MJCF chain.

:class:`StringPhysics` (SI, validated when built, from ``lab.strings.<type>`` over
:data:`STRING_DEFAULTS`) and :func:`build_mjcf` (capsule links, hinges with EI / l_link,
clay spheres, rigid pipe spans, the driver body at the grasp). How the chain is stepped,
dragged and driven is :mod:`stringcast.lab.physics`, whose docstring gives the physics.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

from stringcast.core import Campaign, ConfigError

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

DRIVER_ARMATURE = (200.0, 200.0, 20.0)    # kg, kg, kg m^2 on slide x, slide y, hinge z


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
