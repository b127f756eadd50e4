"""The lab's strings as a family: :func:`draw_material` draws one string material (seeded).

Five material classes, each a consistent combination (:data:`MATERIAL_CLASSES`, the ONE table
of the family's ranges; sources in docs/lab_physics.md, "The family of materials"):

* ``thread``: twisted continuous-filament thread (polyester, nylon, cotton), 0.3-0.8 mm.
* ``cord``: braided or twisted fibre cord, 1.5-4 mm.
* ``rope``: laid or braided fibre rope, 5-12 mm.
* ``elastic``: rubber-cored elastic (shock) cord, 2-5 mm, that stretches tens of per cent
  under a cast.
* ``chain``: a small bead (ball) chain, 2.4-4.5 mm: near-inextensible, nearly free to bend.

A class fixes which quantities go together; within it the diameter d, the envelope's bulk density
rho_b (mass over pi d^2 / 4), the effective bending modulus E_b (on pi d^4 / 64), the specific
axial modulus M (N/tex, the textile unit: EA = M x tex, tex = g per km), and time constants of
the bending, axial and grasp dashpots are drawn log-uniformly and independently. So
lam = rho_b pi d^2 / 4, EI = E_b pi d^4 / 64 and EA = M 1e6 lam come out correlated as a real
string's: a thick string is heavy and stiff. The grasp: with probability :data:`PIVOT_SHARE` a
free pivot (a string tied to a ring or hook), else a clamp whose root stiffness is the cord's
bending over a free length c d beyond the jaws, k_g = EI / (c d), c drawn; damping = stiffness x
a time constant (on a pivot, the time constant times the clamp's stiffness it would have).

The pipeline never reads a draw: a config names it in ``lab.material`` (``seed``, optional
``class``), and :meth:`~stringcast_lab.mjcf.StringPhysics.from_campaign` builds the string from it.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from collections.abc import Mapping

import numpy as np

from stringcast.core import ConfigError

#: The family's ranges, per class: (low, high) each, drawn log-uniformly.
#: d_mm: diameter; rho_b: bulk density of the envelope, kg/m^3; E_b: effective bending modulus, Pa;
#: M: specific axial modulus, N/tex; tau_b, tau_g: bending and grasp dashpot time constants, s
#: (eta = EI tau_b, c_g = k_g tau_g); loss_a: axial loss factor at the first axial mode of a
#: REF_LENGTH_M string (eta_a = loss_a EA / omega_1, omega_1 = pi/2 sqrt(EA/lam) / REF_LENGTH_M);
#: grip: the clamp's free length over d; share: the class's share of draws.
MATERIAL_CLASSES: dict[str, dict] = {
    "thread":  {"d_mm": (0.3, 0.8), "rho_b": (700.0, 1100.0), "E_b": (2e7, 3e8), "M": (2.0, 6.0),
                "tau_b": (3e-3, 3e-2), "loss_a": (0.01, 0.1), "tau_g": (1e-3, 1e-2), "grip": (0.5, 5.0),
                "share": 0.2},
    "cord":    {"d_mm": (1.5, 4.0), "rho_b": (600.0, 960.0), "E_b": (2e6, 2e7), "M": (0.15, 0.65),
                "tau_b": (3e-3, 3e-2), "loss_a": (0.01, 0.1), "tau_g": (1e-3, 1e-2), "grip": (0.5, 5.0),
                "share": 0.25},
    "rope":    {"d_mm": (5.0, 12.0), "rho_b": (600.0, 960.0), "E_b": (3e6, 2e7), "M": (0.3, 2.0),
                "tau_b": (3e-3, 3e-2), "loss_a": (0.01, 0.1), "tau_g": (1e-3, 1e-2), "grip": (0.5, 5.0),
                "share": 0.2},
    "elastic": {"d_mm": (2.0, 5.0), "rho_b": (900.0, 1150.0), "E_b": (1e6, 5e6), "M": (1e-3, 4e-3),
                "tau_b": (3e-3, 3e-2), "loss_a": (0.05, 0.2), "tau_g": (1e-3, 1e-2), "grip": (0.5, 5.0),
                "share": 0.2},
    "chain":   {"d_mm": (2.4, 4.5), "rho_b": (1000.0, 1800.0), "E_b": (5e4, 5e5), "M": (2.0, 10.0),
                "tau_b": (1e-2, 1e-1), "loss_a": (0.01, 0.1), "tau_g": (1e-3, 1e-2), "grip": (0.5, 5.0),
                "share": 0.15},
}
KINDS = tuple(MATERIAL_CLASSES)
PIVOT_SHARE = 0.3          # share of draws whose string hangs from a free pivot
REF_LENGTH_M = 0.5         # the string length the axial loss factor is stated at
GRASPS = ("clamp", "pivot")


@dataclass(frozen=True)
class Material:
    """One drawn string material (SI unless the name says otherwise).

    Attributes:
        seed: the draw's seed. kind: its class (:data:`KINDS`).
        density_g_per_m: linear density, g/m. diameter_mm: mm.
        bending_EI: N m^2. bending_damping: Kelvin-Voigt eta on the curvature rate, N m^2 s.
        axial_EA: N. axial_damping: eta_a on the axial strain rate, N s.
        grasp: ``clamp`` (leaves the gripper along its axis) or ``pivot`` (hangs from a free pivot).
        grasp_stiffness: N m/rad (0 on a pivot). grasp_damping: N m s/rad.

    Raises:
        ConfigError: a value out of the family's ranges (:func:`material_ranges`), an unknown
        kind or grasp, or a pivot with stiffness.
    """

    seed: int
    kind: str
    density_g_per_m: float
    diameter_mm: float
    bending_EI: float
    bending_damping: float
    axial_EA: float
    axial_damping: float
    grasp: str
    grasp_stiffness: float
    grasp_damping: float

    def __post_init__(self):
        if self.kind not in MATERIAL_CLASSES:
            raise ConfigError(f"material: unknown class {self.kind!r} (known: {list(KINDS)})")
        if self.grasp not in GRASPS:
            raise ConfigError(f"material: grasp {self.grasp!r} is not one of {list(GRASPS)}")
        for name, (lo, hi) in material_ranges(self.kind).items():
            v = getattr(self, name)
            if not (math.isfinite(v) and lo * (1 - 1e-9) <= v <= hi * (1 + 1e-9)):
                raise ConfigError(f"material ({self.kind}): {name} = {v:.4g} is outside [{lo:.4g}, {hi:.4g}]")
        if self.grasp == "pivot" and self.grasp_stiffness != 0:
            raise ConfigError("material: a pivot has no grasp stiffness")

    def strings_entry(self) -> dict:
        """The material as ``lab.strings`` keys (what :class:`~.mjcf.StringPhysics` reads)."""
        return {k: v for k, v in asdict(self).items() if k not in ("seed", "kind")}

    def as_dict(self) -> dict:
        """The draw as plain JSON-able values."""
        return asdict(self)


def material_ranges(kind: str) -> dict[str, tuple[float, float]]:
    """The ranges every drawn quantity of class ``kind`` lies in (derived from
    :data:`MATERIAL_CLASSES`): density_g_per_m, diameter_mm, bending_EI, axial_EA (N),
    bending_damping, axial_damping, grasp_stiffness (0 allowed: pivot), grasp_damping."""
    c = MATERIAL_CLASSES[kind]
    (d0, d1), (r0, r1), (e0, e1), (m0, m1) = (np.array(c[k]) for k in ("d_mm", "rho_b", "E_b", "M"))
    area = lambda d: math.pi * (d / 1000) ** 2 / 4                      # noqa: E731
    inertia = lambda d: math.pi * (d / 1000) ** 4 / 64                  # noqa: E731
    lam = (r0 * area(d0), r1 * area(d1))
    ei = (e0 * inertia(d0), e1 * inertia(d1))
    ea = (m0 * 1e6 * lam[0], m1 * 1e6 * lam[1])
    w = lambda ea_, lam_: math.pi / 2 * math.sqrt(ea_ / lam_) / REF_LENGTH_M   # noqa: E731
    # eta_a = loss EA / omega_1 = loss sqrt(EA lam) 2 L / pi: monotone in EA and lam
    eta_a = (c["loss_a"][0] * ea[0] / w(ea[0], lam[0]), c["loss_a"][1] * ea[1] / w(ea[1], lam[1]))
    kg = (ei[0] / (c["grip"][1] * d0 / 1000), ei[1] / (c["grip"][0] * d1 / 1000))     # k_g grows as d^3
    return {"density_g_per_m": (lam[0] * 1000, lam[1] * 1000), "diameter_mm": (float(d0), float(d1)),
            "bending_EI": ei, "axial_EA": ea,
            "bending_damping": (ei[0] * c["tau_b"][0], ei[1] * c["tau_b"][1]),
            "axial_damping": eta_a, "grasp_stiffness": (0.0, kg[1]),
            "grasp_damping": (kg[0] * c["tau_g"][0], kg[1] * c["tau_g"][1])}


def _logu(g: np.random.Generator, lo_hi) -> float:
    lo, hi = lo_hi
    return float(math.exp(g.uniform(math.log(lo), math.log(hi))))


def draw_material(seed: int, kind: str | None = None) -> Material:
    """Draw one string material of the family (module doc), reproducibly from ``seed``.

    Args:
        seed: any int; the draw's generator is ``np.random.default_rng([seed, 52])``.
        kind: force the class (one of :data:`KINDS`); None: drawn by the classes' shares.

    Returns:
        A :class:`Material`.

    Raises:
        ConfigError: an unknown ``kind``.
    """
    if kind is not None and kind not in MATERIAL_CLASSES:
        raise ConfigError(f"lab.material: unknown class {kind!r} (known: {list(KINDS)})")
    g = np.random.default_rng([int(seed), 52])
    shares = np.array([c["share"] for c in MATERIAL_CLASSES.values()])
    drawn = KINDS[int(g.choice(len(KINDS), p=shares / shares.sum()))]
    kind = kind or drawn
    c = MATERIAL_CLASSES[kind]
    d = _logu(g, c["d_mm"]) / 1000
    lam = _logu(g, c["rho_b"]) * math.pi * d * d / 4
    ei = _logu(g, c["E_b"]) * math.pi * d ** 4 / 64
    ea = _logu(g, c["M"]) * 1e6 * lam
    eta = ei * _logu(g, c["tau_b"])
    omega_1 = math.pi / 2 * math.sqrt(ea / lam) / REF_LENGTH_M
    eta_a = _logu(g, c["loss_a"]) * ea / omega_1
    k_clamp = ei / (_logu(g, c["grip"]) * d)
    c_g = k_clamp * _logu(g, c["tau_g"])
    pivot = bool(g.random() < PIVOT_SHARE)
    return Material(seed=int(seed), kind=kind, density_g_per_m=lam * 1000, diameter_mm=d * 1000, bending_EI=ei,
                    bending_damping=eta, axial_EA=ea, axial_damping=eta_a, grasp="pivot" if pivot else "clamp",
                    grasp_stiffness=0.0 if pivot else k_clamp, grasp_damping=c_g)


def lab_material(lab) -> Material | None:
    """The material ``lab.material`` names ({seed: int, class: optional str}), or None (``lab``: the lab's
    :class:`~.settings.LabSettings`, or the ``lab:`` mapping).

    Raises:
        ConfigError: ``lab.material`` is not a mapping with an integer ``seed`` (and known keys).
    """
    spec = lab.get("material") if isinstance(lab, Mapping) else lab.material
    if spec is None:
        return None
    if not isinstance(spec, Mapping) or not isinstance(spec.get("seed"), (int, np.integer)) \
            or isinstance(spec.get("seed"), bool) or set(spec) - {"seed", "class"}:
        raise ConfigError(f"lab.material: expected {{seed: <int>, class: <optional {list(KINDS)}>}}, got {spec!r}")
    return draw_material(int(spec["seed"]), spec.get("class"))


def apply_material(config: Mapping, material: Material) -> dict:
    """A copy of ``config`` whose lab builds every string of ``material`` (``lab.material``)."""
    import copy

    out = copy.deepcopy(dict(config))
    out["lab"] = {**(out.get("lab", {}) or {}), "material": {"seed": material.seed, "class": material.kind}}
    return out
