"""The loop benchmark's methods and variants, as config overlays (:mod:`benchmarks.loop`).

* ``METHODS``: ``paper`` (``config/paper.yaml``, read at import: the file ``--method paper`` and
  ``snakemake --configfile`` use) and ``ours`` (the settings' defaults, no overlay).
* ``VARIANTS``: ours with one setting changed, run only by name and left out of loop.json, to A/B
  that setting on the same code and campaigns (:mod:`benchmarks.loop_ab` pairs them with ours):
  ``ours_no_residual`` plans without the residual correction (and so without its gate on
  perturbations), the weak class of the family being threads (issue 52); ``ours_always_perturb``
  perturbs the played motion (+-0.5 rad/s) after any miss, as the paper does, instead of a wider
  perturbation or a new motion after a miss over 45 mm; ``ours_paper_w`` fits with the paper's tip
  weighting w = 0.1 (the threads' next-motion error, docs/method.md); ``ours_isotropic_drag`` fits
  with the paper's air drag on the whole velocity (``model.drag: isotropic``); ``ours_grasp_flip``
  adds 30 % to CMA-ES's budget (after the first look) for a last run in the other basin of the hand
  spring (``estimation.cmaes_grasp_flip``); ``ours_grasp_basins`` adds to that flip a robust
  planner's ensemble that holds both basins when they near-tie (``estimation.top_grasp_basins``);
  ``ours_wide_bending`` lets the bending springs k_h and k_sh reach 100 times Table 2's top (the stiff
  ropes of the family, docs/method.md); ``ours_halving`` runs a blown-up candidate again at half the
  step, once (``model.blowup_halvings``: the stiff ropes' fits blow up at dt = 1e-4 s, docs/method.md);
  ``ours_taut`` prefers first and new plans whose model string is taut at the hit
  (``motion.taut_chord_share``: slack ones miss, docs/method.md); ``ours_paper_drag_range`` searches the
  quadratic drag C_c2 over Table 2's whole range, from 1e-6 (ours from 1e-3: the thread's drag lost
  on the flat decades, docs/method.md; until stop 74 ours was this and the floor the variant
  ``ours_drag_floor``); ``ours_paper_mass_range`` keeps the relative masses from 0.1, as the paper's
  method (ours from 0.01: a thread's point is 1/3000 of a 10 g weight, docs/method.md; until stop 75
  ours was this and 0.01 the variant ``ours_mass_floor``).
* :func:`method_config`: the config one campaign runs with (method, seed, physics, mode, material).
"""
from __future__ import annotations

import copy

import yaml

from benchmarks.common import ROOT

PAPER_CONFIG = ROOT / "config" / "paper.yaml"
METHODS = {
    "paper": yaml.safe_load(PAPER_CONFIG.read_text()),   # one place for the paper's settings
    "ours": {},                                           # ours: the settings' defaults
}
VARIANTS = {
    # ours with one setting changed (merged over ours), run only by name (--only, loop.smk's
    # methods=...) and left out of loop.json: an A/B of that setting on the same code and campaigns
    "ours_no_residual": {"motion": {"residual_correction": False}},
    "ours_always_perturb": {"motion": {"replan_miss_mm": 0.0}},
    "ours_paper_w": {"evaluation": {"w": 0.1}},
    "ours_isotropic_drag": {"model": {"drag": "isotropic"}},
    "ours_grasp_flip": {"estimation": {"cmaes_grasp_flip": 0.3}},
    "ours_grasp_basins": {"estimation": {"cmaes_grasp_flip": 0.3, "top_grasp_basins": True}},
    "ours_wide_bending": {"model": {"ranges": {"k_h": [1.0e-3, 1.0e+3], "k_sh": [1.0e-4, 1.0e+2]}}},
    "ours_halving": {"model": {"blowup_halvings": 1}},
    "ours_taut": {"motion": {"taut_chord_share": 0.95}},
    "ours_paper_drag_range": {"model": {"ranges": {"C_c2": [1.0e-6, 10.0]}}},
    "ours_paper_mass_range": {"model": {"ranges": {"mu": [0.1, 100.0]}}},
}


def material_of(seed: int) -> dict:
    """A family run's ``lab.material``: the draw ``seed`` of class ``KINDS[seed % 5]`` (every class
    among any five consecutive seeds; :mod:`stringcast_lab.materials`)."""
    from stringcast_lab.materials import KINDS

    return {"seed": int(seed), "class": KINDS[int(seed) % len(KINDS)]}


def method_config(config: dict, method: str, seed: int, physics: str = "mujoco", mode: str = "video",
                  family: bool = False) -> dict:
    """The config a run uses: ``config`` (as loaded) with the method's overlay, the seed,
    ``lab.physics``, in the state mode ``lab.render: false``, and in a family run ``lab.material``
    (:func:`material_of`).

    Raises:
        KeyError: unknown method (not in ``METHODS`` or ``VARIANTS``).
    """
    from stringcast.core import merge_config

    overlays = [METHODS[method]] if method in METHODS else [METHODS["ours"], VARIANTS[method]]
    cfg = copy.deepcopy({k: v for k, v in config.items() if k != "_path"})
    for overlay in overlays:
        merge_config(cfg, overlay)
    cfg.setdefault("estimation", {})["seed"] = int(seed)   # the config file may leave a section to its defaults
    cfg.setdefault("motion", {})["seed"] = int(seed)
    cfg["lab"] = dict(cfg.get("lab") or {}, physics=physics)
    if mode == "state":
        cfg["lab"]["render"] = False
    if family:
        cfg["lab"]["material"] = material_of(seed)
    return cfg
