"""A lab trial's ground truth, from :func:`.trial.run_trial`'s simulation (a :class:`.recording.Recording`):
``ground_truth.json``'s verdict and physics, and ``ground_truth.parquet``'s string points."""
from __future__ import annotations

from pathlib import Path
from collections.abc import Mapping

import numpy as np
import pandas as pd

from stringcast.core import Campaign, forward_kinematics, settings_from_config, write_parquet
from .mjcf import StringPhysics


def write_points(path: Path, gt_rows: list) -> None:
    """Write ``ground_truth.parquet`` (frame, t_s, point, x_m, y_m) from the rows filmed (per frame:
    frame, t_s, point, x_m, y_m, each (n + 1,))."""
    cols = [np.concatenate(c) for c in zip(*gt_rows)]
    gt = pd.DataFrame({"frame": cols[0].astype(np.int64), "t_s": cols[1], "point": cols[2].astype(np.int64),
                       "x_m": cols[3], "y_m": cols[4]})
    write_parquet(path, gt)


def verdict(rec, campaign: Campaign, config: Mapping, motion_start_s: float, t_motion_end: float) -> dict:
    """ground_truth.json's verdict on the simulation ``rec``: hit, the tip's closest approach (mm, at s) to
    the target within the hit window [motion start, motion end ``t_motion_end`` + flight window] s, the
    target (x, y, radius) mm, the window, the motion's start and end s, and the floor clearance mm of
    the string and the arm."""
    arm = campaign.arm
    t_end = float(rec.t[-1])
    flight = settings_from_config(config).motion.flight_window_s  # the window the planner aims the hit in
    w0, w1 = float(motion_start_s), min(t_motion_end + flight, t_end)
    sel = (rec.t >= w0 - 1e-12) & (rec.t <= w1 + 1e-12)
    if not sel.any():
        sel = rec.t >= rec.t[-1]
    tip = rec.points[sel, -1]
    d = np.linalg.norm(tip - campaign.target.xy, axis=1)
    i_best = int(np.argmin(d))
    arm_pts = forward_kinematics(arm, rec.q_arm[sel][::20])
    min_y = float(min(rec.points[sel, :, 1].min(), arm_pts[:, 1:, 1].min()))
    clearance = min_y - arm.floor_y
    closest = float(d[i_best])
    hit = bool(closest <= campaign.target.radius and clearance >= 0)
    return {
        "hit": hit,
        "closest_approach_mm": closest * 1000,
        "closest_approach_t_s": float(rec.t[sel][i_best]),
        "target_mm": [campaign.target.x * 1000, campaign.target.y * 1000, campaign.target.radius * 1000],
        "hit_window_s": [w0, w1],
        "motion_start_s": float(motion_start_s),
        "motion_end_s": t_motion_end,
        "floor_clearance_mm": clearance * 1000,
    }


def physics_truth(rec, phys: StringPhysics) -> dict:
    """ground_truth.json's physics: the string's description, its largest length error (relative) over
    the simulation, the settling speed m/s, which physics ran (``physics``: mujoco | elastica), its
    steps per wall second and its own figures (``physics_detail``: time step, material)."""
    length = np.linalg.norm(np.diff(rec.points[:, :, :], axis=1), axis=2).sum(axis=1)
    return {
        "string_physics": {
            "length_m": phys.length, "n_links": phys.n_links, "mass_kg": phys.mass,
            "density_kg_m": phys.density, "diameter_m": phys.diameter, "bending_EI": phys.bending_EI,
            "bending_damping": phys.bending_damping, "grasp_stiffness": phys.grasp_stiffness,
            "grasp_damping": phys.grasp_damping, "weights": phys.weights, "pipes": phys.pipes,
            "axial_EA": phys.axial_EA, "axial_damping": phys.axial_damping, "grasp": phys.grasp,
            "material": phys.material},
        "length_error_max": float(np.max(np.abs(length - phys.length)) / phys.length),
        "settle_speed_m_s": rec.settle_speed,
        "physics": rec.physics,
        "steps_per_s": rec.steps_per_s,
        "physics_detail": rec.detail,
    }
