"""Benchmark ``inertia``: the inertial-response check over the lab's string family, both engines.

The fit verdict names the recording, not the model, as the cause of a failed fit when the tracked
string does not tilt under the grasp's acceleration as a hanging string does
(:mod:`stringcast.estimate.inertia`, ``inertia_share`` under
:data:`stringcast.estimate.verdict.INERTIA_SHARE_MAX`). This benchmark states what the share is on
strings that do obey gravity and inertia: for each engine (``lab.physics``) and each draw i =
0..N-1, a material of class ``KINDS[i % 5]`` drawn with seed i (:func:`stringcast_lab.materials.draw_material`),
string type ``1 + i % 7`` (its weights and pipes) at target ``1 + i % 4``, ours' first motion for it
(:func:`stringcast.plan.planning.run_first_plan`, seed i) played by the engine with 0.3 s of rest
before and 0.6 s after; the lab's points at the model's mass points, sampled at 1 kHz with 1 mm of
Gaussian noise, against the FK of the lab's joint angles at 500 Hz.

results/bench/inertia.json: per run the engine, class, type, target, ``inertia_share``,
``rotation_coupling``, ``swing_period_s``, ``fit_r2``, ``excitation``; per engine and overall the
smallest and largest share and coupling over the runs whose share is stated; the threshold the
verdict uses; library versions.

Run: ``python -m benchmarks.inertia [--quick] [--draws N] [--physics mujoco elastica]``
(default 20 draws per engine; ``--quick``: 5, MuJoCo only).
"""
from __future__ import annotations

import argparse
import copy
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.common import ROOT, header, write

NOISE_M = 0.001
"""Gaussian noise on each tracked coordinate, m (the tracking's 0.5-3 mm median error)."""
FRAME_S, JOINT_S = 1e-3, 2e-3
"""The camera's frame period and the joint log's period, s."""


def _motion(campaign, settings, seed: int, work: Path) -> tuple[np.ndarray, np.ndarray]:
    """Ours' first motion for ``campaign`` with 0.3 s of rest before and 0.6 s of hold after: (t, q)."""
    from stringcast.core import stage_kwargs
    from stringcast.api import run_first_plan

    run_first_plan(campaign, work / "motion.csv", work / "motion.json", seed=seed,
                   **stage_kwargs(run_first_plan, settings))
    m = pd.read_csv(work / "motion.csv")
    q = m[[c for c in m.columns if c.startswith("q")]].to_numpy(float)
    t = m["t_s"].to_numpy(float)
    step = float(np.median(np.diff(t)))
    pre, post = np.arange(1, int(0.3 / step) + 1) * step, np.arange(1, int(0.6 / step) + 1) * step
    t_cmd = np.r_[0.0, pre, t[1:] + pre[-1], t[-1] + pre[-1] + post]
    q_cmd = np.vstack([np.repeat(q[:1], len(pre) + 1, 0), q[1:], np.repeat(q[-1:], len(post), 0)])
    return t_cmd, q_cmd


def one_run(physics: str, i: int, config: dict, work: Path) -> dict:
    """Draw i on ``physics`` (module doc): the run's identity and :func:`string_response`'s figures."""
    from stringcast.core import hand_pose, merge_config, resolve_campaign, settings_from_config
    from stringcast.api import string_response
    from stringcast_lab.materials import KINDS, apply_material, draw_material
    from stringcast_lab.mjcf import StringPhysics
    from stringcast_lab.trial import lab_physics

    kind, stype, target = KINDS[i % len(KINDS)], 1 + i % 7, 1 + i % 4
    material = draw_material(i, kind)
    cfg = apply_material(merge_config(copy.deepcopy(config), {"lab": {"physics": physics}}), material)
    campaign = resolve_campaign({"string": stype, "target": target}, cfg, f"inertia_{physics}_{i}")
    settings = settings_from_config(cfg)
    run_dir = work / f"{physics}_{i}"
    run_dir.mkdir(parents=True, exist_ok=True)
    t_cmd, q_cmd = _motion(campaign, settings, i, run_dir)
    lab = cfg.get("lab") or {}
    t0 = time.perf_counter()
    rec = lab_physics(lab)(StringPhysics.from_campaign(campaign, cfg), campaign.arm, t_cmd, q_cmd,
                           float(lab.get("timestep_s", 5e-5)), float(lab.get("servo_lag_s", 0.008)), 0.3)
    sim_s = time.perf_counter() - t0
    n = campaign.string.n_points
    sites = np.round(np.arange(1, n + 1) * (rec.points.shape[1] - 1) / n).astype(int)
    ft = np.arange(rec.t[0], rec.t[-1], FRAME_S)
    pts = np.stack([np.stack([np.interp(ft, rec.t, rec.points[:, s, j]) for j in (0, 1)], -1) for s in sites], 1)
    pts = pts + np.random.default_rng(i).normal(0.0, NOISE_M, pts.shape)
    tj = np.arange(rec.t[0], rec.t[-1], JOINT_S)
    qj = np.stack([np.interp(tj, rec.t, rec.q_arm[:, j]) for j in range(rec.q_arm.shape[1])], -1)
    fig = string_response(ft, pts, np.ones(pts.shape[:2], bool), tj, hand_pose(campaign.arm, qj))
    return {"physics": physics, "draw": i, "class": kind, "grasp": material.grasp, "string": stype,
            "target": target, "sim_s": sim_s} | fig


def _span(rows: list[dict], key: str) -> list[float] | None:
    vals = [r[key] for r in rows if r.get("inertia_share") is not None]
    return [float(min(vals)), float(max(vals))] if vals else None


def _line(r: dict) -> str:
    """One run's progress line: the share (or not stated) and each chord's share and r2."""
    share = r["inertia_share"]
    head = ("share not stated" if share is None else
            f"share {share:.2f}, coupling {r['rotation_coupling']:.2f}, period {r['swing_period_s']:.2f} s")
    chords = ", ".join(f"{k}: {'-' if v['inertia_share'] is None else round(v['inertia_share'], 2)} "
                       f"r2 {v['fit_r2'] or 0:.2f}" for k, v in r["per_point"].items())
    return f"{head}; per point {chords}"


def _physics_summary(rows: list[dict]) -> dict:
    """One engine's share and coupling spans, and how many of its runs state a share."""
    return {"share": _span(rows, "inertia_share"), "coupling": _span(rows, "rotation_coupling"),
            "stated": sum(r["inertia_share"] is not None for r in rows), "runs": len(rows)}


def run(quick: bool = False, draws: int | None = None, physics: tuple[str, ...] | None = None,
        work: Path | None = None) -> dict:
    """Run the draws and write results/bench/inertia.json (after every run)."""
    from stringcast.core import load_config
    from stringcast.estimate.verdict import INERTIA_SHARE_MAX

    draws = draws or (5 if quick else 20)
    physics = physics or (("mujoco",) if quick else ("mujoco", "elastica"))
    config = load_config(ROOT / "config" / "config.yaml")   # ours: the defaults
    rows: list[dict] = []
    doc: dict = {}
    with tempfile.TemporaryDirectory(prefix="bench_inertia_") as tmp:
        base = Path(work or tmp)
        for p in physics:
            for i in range(draws):
                r = one_run(p, i, config, base)
                rows.append(r)
                print(f"  {p} draw {i} ({r['class']}, {r['grasp']}, string {r['string']}): {_line(r)}", flush=True)
                per = {q: _physics_summary([x for x in rows if x["physics"] == q]) for q in physics}
                doc = header("inertia", quick) | {
                    "threshold_inertia_share": INERTIA_SHARE_MAX, "noise_mm": NOISE_M * 1000,
                    "per_physics": per, "share_span": _span(rows, "inertia_share"),
                    "coupling_span": _span(rows, "rotation_coupling"), "runs": rows,
                    "complete": len(rows) == draws * len(physics)}
                write("inertia", doc)
    return doc


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="5 draws, MuJoCo only")
    ap.add_argument("--draws", type=int, help="draws per engine (default 20)")
    ap.add_argument("--physics", nargs="+", choices=("mujoco", "elastica"))
    ap.add_argument("--work", type=Path, help="keep each draw's motion here")
    a = ap.parse_args(argv)
    doc = run(a.quick, a.draws, tuple(a.physics) if a.physics else None, a.work)
    print(f"inertia_share over the family: {doc['share_span']}; threshold {doc['threshold_inertia_share']}")


if __name__ == "__main__":
    main()
