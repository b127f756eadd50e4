"""The Cosserat rod's material, element by element, from a :class:`~stringcast_lab.mjcf.StringPhysics`.

:class:`RodMaterial` turns what the string *is* (length, g/m, diameter, the configured bending EI
and damping, clay lumps, plastic pipes) into the per-element stiffnesses and inertias of a
PyElastica ``CosseratRod`` of ``phys.n_links`` elements, and the explicit time step they allow.
The values and their sources are in the package docstring (:mod:`stringcast_lab.rod`).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from ..mjcf import StringPhysics

G_ACC = 9.81                  # m/s^2, along -y
CORD_E_AXIAL = 1.0e9          # Pa, a 2-3 mm braided nylon/polyester cord's effective axial modulus
CORD_NU = 0.5                 # G = E_bend / (2 (1 + nu)) for the braid's cross-section
SHEAR_ALPHA = 27.0 / 28.0     # Timoshenko's coefficient of a solid circle (PyElastica's value)
AXIAL_LOSS = 0.03             # Kelvin-Voigt loss factor of stretch at the first axial mode
PIPE_E = 0.25e9               # Pa, low-density polyethylene tubing
PIPE_RHO = 920.0              # kg/m^3, LDPE
PIPE_NU = 0.45
PIPE_SHEAR_ALPHA = 0.5        # Timoshenko's coefficient of a thin-walled tube
PIPE_MODE_MAX = 1.25          # a pipe's modes may be this much faster than the cord's axial one
STEP_SAFETY = 0.5             # dt = STEP_SAFETY * 2 / omega_max (Verlet is stable below 2 / omega)
STRAIN_FLOOR = 5e-4           # a drawn EA is built no stiffer than a cast strains by this (chains, ropes)
OMEGA_ROT_MIN = 1.0e5         # rad/s: an element's rotation modes are slowed to max(axial, this), no lower


@dataclass(frozen=True)
class RodMaterial:
    """Per-element material of the rod (n elements, n + 1 nodes, n - 1 junctions), SI.

    Attributes:
        n: elements. length: rest length of the string, m. l: rest element length, m.
        lam: (n,) mass per length, kg/m (cord + the share of pipe the element covers).
        radius: (n,) outer radius, m (the pipe's where a pipe covers most of the element).
        EA: (n,) axial stiffness, N. GA: (n,) shear stiffness alpha G A, N.
        EI: (n,) bending stiffness, N m^2. GJ: (n,) twist stiffness, N m^2.
        J: (n,) rotational inertia of the element about its bending axes, kg m^2 (polar: 2 J).
        node_mass: (n + 1,) lumped masses (half of each neighbouring element, plus clay), kg.
        clay_node: (W,) int, clay_w: (W,) the lever weight of node clay_node + 1, clay_d: (W,) m.
        eta_bend: (n - 1,) junction dashpots eta / l_voronoi, N m s (from ``bending_damping``).
        eta_axial: (n,) element dashpots, N s / m (AXIAL_LOSS at the first axial mode).
        pipe_ei: EI of the pipes as built, N m^2 (0 without pipes); pipe_capped: it was capped.
        dt_max: the largest stable step, s (:func:`stable_step`).
        grasp: ``rigid`` (element 0 held along the gripper: ``lab.strings``' cord), ``clamp``
            (element 0 on a torsional spring k_grasp N m/rad and dashpot c_grasp N m s/rad to the
            gripper axis) or ``pivot`` (free, c_grasp only). rot_scaled: elements whose rotary
            inertia was raised (:func:`_floor_rotary_inertia`).
    """

    n: int
    length: float
    l: float
    lam: np.ndarray
    radius: np.ndarray
    EA: np.ndarray
    GA: np.ndarray
    EI: np.ndarray
    GJ: np.ndarray
    J: np.ndarray
    node_mass: np.ndarray
    clay_node: np.ndarray
    clay_w: np.ndarray
    clay_d: np.ndarray
    eta_bend: np.ndarray
    eta_axial: np.ndarray
    pipe_ei: float
    pipe_capped: bool
    dt_max: float
    grasp: str = "rigid"
    k_grasp: float = 0.0
    c_grasp: float = 0.0
    rot_scaled: int = 0

    @property
    def junction_EI(self) -> np.ndarray:
        """(n - 1,) bending stiffness at the junctions: the two half elements in series, N m^2."""
        return 2.0 / (1.0 / self.EI[:-1] + 1.0 / self.EI[1:])

    @property
    def junction_GJ(self) -> np.ndarray:
        """(n - 1,) twist stiffness at the junctions (in series, as :attr:`junction_EI`), N m^2."""
        return 2.0 / (1.0 / self.GJ[:-1] + 1.0 / self.GJ[1:])

    def summary(self) -> dict:
        """The material for ``ground_truth.json`` (JSON-able)."""
        return {"elements": self.n, "dt_max_s": self.dt_max, "cord_E_axial_pa": CORD_E_AXIAL,
                "cord_EA_n": float(self.EA.min()), "cord_GA_n": float(self.GA.min()),
                "cord_EI": float(self.EI.min()), "axial_loss": AXIAL_LOSS,
                "pipe_EI": self.pipe_ei, "pipe_capped": self.pipe_capped, "grasp": self.grasp,
                "rotary_inertia_raised": self.rot_scaled}


def _tube(outer_d: float, lam: float) -> tuple[float, float]:
    """(inner radius, wall area) of an LDPE tube of outer diameter ``outer_d`` m and ``lam`` kg/m."""
    r_o = outer_d / 2
    area = lam / PIPE_RHO
    r_i2 = r_o * r_o - area / math.pi
    if r_i2 < 0:                  # heavier than a solid LDPE rod of that diameter: call it solid
        return 0.0, math.pi * r_o * r_o
    return math.sqrt(r_i2), area


def rod_material(phys: StringPhysics) -> RodMaterial:
    """The rod's per-element material (see :class:`RodMaterial`; values: the package docstring).

    The cord: EA = CORD_E_AXIAL pi d^2 / 4; EI = ``phys.bending_EI``; its shear and twist modulus
    G = E_b / (2 (1 + CORD_NU)) with E_b = EI / (pi d^4 / 64) the modulus its bending shows.
    A pipe (LDPE tube, wall from its g/m) adds its EA, EI, alpha G A and G J to the elements it
    covers more than half of, and its mass to every element it touches (by overlap). A clay lump
    is a point mass split between its two nearest nodes by the lever rule (centre of mass kept),
    its own inertia 2/5 m r^2 given to the neighbouring elements.

    Raises:
        ConfigError: from :class:`StringPhysics` only (it is validated when built).
    """
    n, L = phys.n_links, phys.length
    l = L / n
    r_c = phys.diameter / 2
    A_c, I_c = math.pi * r_c ** 2, math.pi * r_c ** 4 / 4
    EI_c = max(phys.bending_EI, 1e-12)
    G_c = (EI_c / I_c) / (2 * (1 + CORD_NU))
    s0 = np.arange(n) * l
    lam = np.full(n, phys.density)
    radius = np.full(n, r_c)
    EA = np.full(n, CORD_E_AXIAL * A_c if phys.axial_EA is None else min(phys.axial_EA, phys.cast_tension / STRAIN_FLOOR))
    GA = np.full(n, SHEAR_ALPHA * G_c * A_c)
    EI = np.full(n, EI_c)
    GJ = np.full(n, G_c * 2 * I_c)
    J_len = phys.density * r_c ** 2 / 4 * np.ones(n)          # kg m, per length, about a bending axis
    pipe_ei = 0.0
    covered = np.zeros(n, bool)
    for a, b, rho_p, dia_p in phys.pipes:
        r_i, area = _tube(dia_p, rho_p)
        r_o = dia_p / 2
        overlap = np.clip(np.minimum(b, s0 + l) - np.maximum(a, s0), 0.0, None) / l
        lam += rho_p * overlap
        J_len += rho_p * overlap * (r_o ** 2 + r_i ** 2) / 4
        cov = overlap > 0.5
        covered |= cov
        I_p = math.pi * (r_o ** 4 - r_i ** 4) / 4
        G_p = PIPE_E / (2 * (1 + PIPE_NU))
        pipe_ei = PIPE_E * I_p
        radius[cov] = r_o
        EA[cov] += PIPE_E * area
        GA[cov] += PIPE_SHEAR_ALPHA * G_p * area
        EI[cov] += pipe_ei
        GJ[cov] += G_p * 2 * I_p
    pipe_capped = _cap_pipes(covered, lam, EA, GA, EI, GJ, J_len, l)
    if pipe_capped:
        pipe_ei = float(EI[covered].max() - EI_c)
    grasp = phys.grasp or "rigid"
    k_g = phys.grasp_stiffness if grasp == "clamp" else 0.0
    rot_scaled = _floor_rotary_inertia(covered, lam, EA, GA, EI, GJ, J_len, l, k_g)
    node_mass = np.zeros(n + 1)
    node_mass[:-1] += lam * l / 2
    node_mass[1:] += lam * l / 2
    J = J_len * l
    clay_node, clay_w, clay_d = _clay(phys, n, l, node_mass, J)
    c_axial = np.sqrt(EA.min() / lam.max())
    omega_1 = math.pi / 2 * c_axial / L                      # first axial mode, clamped-free
    if phys.axial_damping is None:
        eta_axial = AXIAL_LOSS * EA / omega_1 / l
    else:                                                    # eta_a d(eps)/dt, eps = dl / l
        eta_axial = np.full(n, phys.axial_damping / l)
    eta_bend = np.full(n - 1, phys.bending_damping / l)
    dt = stable_step(l, lam, EA, GA, EI, GJ, J_len)
    if grasp != "rigid":                                     # element 0 on the grasp spring
        dt = min(dt, STEP_SAFETY * 2 / math.sqrt((k_g + 4 * EI[0] / l) / J[0]))
    return RodMaterial(n, L, l, lam, radius, EA, GA, EI, GJ, J, node_mass, clay_node, clay_w, clay_d,
                       eta_bend, eta_axial, float(pipe_ei), pipe_capped, dt, grasp, float(k_g),
                       float(phys.grasp_damping) if grasp != "rigid" else 0.0, rot_scaled)


def _floor_rotary_inertia(covered, lam, EA, GA, EI, GJ, J_len, l, k_grasp) -> int:
    """Raise, in place, a cord element's rotary inertia per length J_len where its rotation modes
    (bending-rotation (2/l) sqrt(EI/J), twist, shear-rotation sqrt(GA/J), and on element 0 the grasp
    spring sqrt(k_g / (J l))) would be faster than omega_cap = max(the axial wave 2 sqrt(EA/lam) / l,
    OMEGA_ROT_MIN): rotary inertia scaling, the standard device of explicit rod and shell codes
    (the rotations of a string's cross-sections carry a negligible share of its kinetic energy; a
    thin thread's would otherwise set a step of ~1e-7 s). Never active on ``lab.strings``' cords
    (their rotation modes are below both). Returns how many elements were raised."""
    omega_cap = np.maximum(2 * np.sqrt(EA / lam) / l, OMEGA_ROT_MIN)
    need = np.maximum.reduce([GA / omega_cap ** 2, 4 * EI / (l * omega_cap) ** 2, 2 * GJ / (l * omega_cap) ** 2])
    need[0] = max(need[0], 2 * k_grasp / (l * omega_cap[0] ** 2))
    raise_ = ~covered & (need > J_len)
    J_len[raise_] = need[raise_]
    return int(raise_.sum())


def _cap_pipes(covered, lam, EA, GA, EI, GJ, J_len, l) -> bool:
    """Cap, in place, a pipe element's EI, GJ and GA where its bending, twist or shear mode would be
    more than PIPE_MODE_MAX times faster than the cord's own axial mode (the pipe would then set the
    explicit step). Returns whether anything was capped (and warns)."""
    if not covered.any():
        return False
    cord = ~covered
    c2 = (EA[cord] / lam[cord]).max() if cord.any() else (EA / lam).max()
    omega_ax = PIPE_MODE_MAX * 2 * math.sqrt(c2) / l
    ei_max = J_len * (omega_ax * l / 2) ** 2                  # bending-rotation: (2/l) sqrt(EI/J) = omega_ax
    ga_max = J_len * omega_ax ** 2                            # shear-rotation: sqrt(GA/J) = omega_ax
    capped = covered & ((EI > ei_max) | (GA > ga_max) | (GJ > 2 * ei_max))
    if capped.any():
        EI[capped] = np.minimum(EI[capped], ei_max[capped])
        GJ[capped] = np.minimum(GJ[capped], 2 * ei_max[capped])
        GA[capped] = np.minimum(GA[capped], ga_max[capped])
        warnings.warn(f"lab (elastica): a pipe's stiffness was capped to EI {EI[capped].max():.3g} N m^2 so "
                      "that the explicit step stays the cord's", stacklevel=3)
    return bool(capped.any())


def _clay(phys: StringPhysics, n: int, l: float, node_mass: np.ndarray, J: np.ndarray):
    """Add the clay lumps to ``node_mass`` (lever rule) and their own inertia to ``J``, in place.
    Returns (node index, lever weight of the next node, diameter) per lump."""
    idx, ws, ds = [], [], []
    for at, m, dia in phys.weights:
        x = min(max(at / l, 0.0), float(n))
        i = min(int(math.floor(x + 1e-9)), n - 1)
        w = x - i
        node_mass[i] += (1 - w) * m
        node_mass[i + 1] += w * m
        own = 0.4 * m * (dia / 2) ** 2
        elems = [e for e in (i - 1, i) if 0 <= e < n] if w < 0.5 else [e for e in (i, i + 1) if 0 <= e < n]
        for e in elems:
            J[e] += own / len(elems)
        idx.append(i)
        ws.append(w)
        ds.append(dia)
    return np.array(idx, dtype=np.int64), np.array(ws, float), np.array(ds, float)


def stable_step(l: float, lam, EA, GA, EI, GJ, J_len) -> float:
    """The explicit (position Verlet) step the rod allows, s: STEP_SAFETY * 2 / omega_max.

    omega_max over the elements' fastest modes: axial 2 sqrt(EA / lam) / l (the axial wave
    crossing an element; dt = 0.5 l / c), bending-rotation (2 / l) sqrt(EI / J'), twist
    (2 / l) sqrt(GJ / 2 J') and shear-rotation sqrt(GA / J'), J' the rotational inertia per
    length (a thin cord turns its elements fast against shear).
    """
    lam, EA, GA, EI, GJ, J_len = (np.asarray(v, float) for v in (lam, EA, GA, EI, GJ, J_len))
    omega = np.concatenate([2 * np.sqrt(EA / lam) / l, 2 / l * np.sqrt(EI / J_len),
                            2 / l * np.sqrt(GJ / (2 * J_len)), np.sqrt(GA / J_len)])
    return float(STEP_SAFETY * 2 / omega.max())
