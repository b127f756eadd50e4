"""Benchmark ``first_shot``: a campaign's first execution alone, per method variant and lab physics.

The first motion is the only one planned before anything is known of the string: the method's
first parameter set decides it, and a first shot that hits ends the campaign at one execution
(issue 27's ``mean_ours`` <= 1.8 needs more of them). For each physics (``lab.physics``), string
type (with its paper target), seed and variant, the first motion is planned as the workflow's
``plan_first`` rule plans it (:func:`stringcast.plan.planning.run_first_plan`, ``motion.seed`` =
the seed) and played by the virtual lab without filming (``lab.render: false``) with the executor
seed the loop benchmark's first execution has (seed x 1000 + 1), so a case is the loop
benchmark's first shot exactly (``benchmarks.loop_methods.method_config``). The lab's verdict
(``ground_truth.json``: hit, closest approach) is read here, by the benchmark only.

Variants: ``paper`` and ``ours`` (benchmarks.loop_methods' ``METHODS``), and ``NAME=FILE``: FILE's
settings merged over ours (a candidate change to ours, judged before a loop run).

Figures per variant and physics: hits, hit rate, the median and each case's closest approach (mm),
and against the first variant the paired change of the closest approach (median, and the cases
closer / farther). ``results/bench/first_shot.json`` (or ``--out NAME``) with the library versions.

Run: ``python -m benchmarks.first_shot [--physics mujoco elastica] [--types 1 2 ...] [--seeds 0 1 2]
[--variant ours --variant NAME=FILE ...] [--family] [--jobs 2] [--work DIR] [--out NAME]``.
"""
from __future__ import annotations

import argparse
import copy
import multiprocessing
import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import yaml

from benchmarks.common import header, play_on_lab, write
from benchmarks.loop import PHYSICS
from benchmarks.loop_methods import METHODS, method_config
from benchmarks.loop_summary import PAPER_TARGET


def variant_config(config: dict, variant: str, overlay: dict | None, seed: int, physics: str,
                   family: bool = False) -> dict:
    """The config of one case: a built-in method (``overlay`` None) or ours with ``overlay`` merged over it;
    ``family``: the lab's string material drawn from ``seed`` as the loop benchmark's ``--family`` draws it."""
    from stringcast.core import merge_config

    if overlay is None:
        return method_config(config, variant, seed, physics, "state", family)
    cfg = method_config(config, "ours", seed, physics, "state", family)
    return merge_config(cfg, copy.deepcopy(overlay))


def first_shot(case: tuple) -> dict:
    """Plan and play one case's first motion; its record (the lab's closest approach and hit)."""
    physics, k, seed, variant, overlay, work, family = case
    from stringcast.core import load_config, read_json, resolve_campaign, settings_from_config, stage_kwargs
    from stringcast.api import run_first_plan

    cfg = variant_config(load_config(), variant, overlay, seed, physics, family)
    name = f"{'family_' if family else ''}{physics}_{variant}_s{k}_seed{seed}"
    d = Path(work) / name
    truth_path = d / "trial_1" / "ground_truth.json"
    t0 = time.perf_counter()
    if not truth_path.exists():
        campaign = resolve_campaign({"string": k, "target": PAPER_TARGET[k], "setup": "default", "seed": seed},
                                    cfg, name)
        settings = settings_from_config(cfg)
        plan = run_first_plan(campaign, d / "motion.csv", d / "motion.json", 0,
                              **stage_kwargs(run_first_plan, settings))
        play_on_lab(d / "motion.csv", d / "trial_1", campaign, settings.executor, cfg, seed * 1000 + 1)
        predicted = float(plan.d_min) * 1000
    else:
        predicted = float(read_json(d / "motion.json")["closest_approach_mm"])
    truth = read_json(truth_path)
    return {"physics": physics, "string": k, "target": PAPER_TARGET[k], "seed": seed, "variant": variant,
            "hit": bool(truth["hit"]), "closest_mm": float(truth["closest_approach_mm"]),
            "predicted_mm": predicted, "seconds": time.perf_counter() - t0}


def summarize(rows: list[dict], variants: list[str]) -> dict:
    """Per physics and variant: hits, rate, median closest approach; paired against variants[0]."""
    out = {}
    for physics in sorted({r["physics"] for r in rows}):
        base = {(r["string"], r["seed"]): r["closest_mm"] for r in rows
                if r["physics"] == physics and r["variant"] == variants[0]}
        out[physics] = {}
        for v in variants:
            rs = [r for r in rows if r["physics"] == physics and r["variant"] == v]
            if not rs:
                continue
            d = np.array([r["closest_mm"] for r in rs])
            delta = np.array([r["closest_mm"] - base[(r["string"], r["seed"])] for r in rs
                              if (r["string"], r["seed"]) in base])
            out[physics][v] = {"cases": len(rs), "hits": int(sum(r["hit"] for r in rs)),
                               "hit_rate": float(np.mean([r["hit"] for r in rs])),
                               "closest_mm_median": float(np.median(d)),
                               "within_45_mm": int(np.sum(d <= 45.0)),
                               f"vs_{variants[0]}": None if v == variants[0] or not len(delta) else {
                                   "closest_mm_change_median": float(np.median(delta)),
                                   "closer": int(np.sum(delta < 0)), "farther": int(np.sum(delta > 0))}}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--physics", nargs="+", default=list(PHYSICS), choices=PHYSICS)
    ap.add_argument("--types", nargs="+", type=int, default=sorted(PAPER_TARGET))
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--variant", action="append", default=None,
                    help="paper, ours, or NAME=FILE (FILE's settings over ours); repeatable, the first is the base")
    ap.add_argument("--jobs", type=int, default=2, help="cases played side by side (processes)")
    ap.add_argument("--work", type=Path, help="keep each case here (a later run reuses the played ones)")
    ap.add_argument("--out", default="first_shot", help="results/bench/<OUT>.json")
    ap.add_argument("--family", action="store_true", help="each seed also draws the string's material (issue 52)")
    a = ap.parse_args()
    variants, overlays = [], {}
    for spec in a.variant or ["ours"]:
        name, _, path = spec.partition("=")
        if not path and name not in METHODS:
            raise SystemExit(f"--variant {spec}: not a method ({', '.join(METHODS)}) or NAME=FILE")
        overlays[name] = yaml.safe_load(Path(path).read_text()) if path else None
        variants.append(name)
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")   # the cases run side by side, one core each
    with tempfile.TemporaryDirectory(prefix="bench_first_shot_") as tmp:
        work = Path(a.work or tmp)
        cases = [(p, k, s, v, overlays[v], str(work), a.family) for p in a.physics for s in a.seeds for k in a.types
                 for v in variants]
        rows = []
        with ProcessPoolExecutor(max(1, a.jobs), mp_context=multiprocessing.get_context("spawn")) as pool:
            for r in pool.map(first_shot, cases):
                rows.append(r)
                print(f"  {r['physics']} type {r['string']} seed {r['seed']} {r['variant']}: "
                      f"{'HIT' if r['hit'] else 'miss'} {r['closest_mm']:.0f} mm (planned {r['predicted_mm']:.0f} mm)",
                      flush=True)
    rows.sort(key=lambda r: (r["physics"], r["variant"], r["string"], r["seed"]))
    doc = header("first_shot", False) | {"variants": {v: overlays[v] for v in variants}, "physics": a.physics,
                                         "types": a.types, "seeds": a.seeds, "family": a.family, "summary": summarize(rows, variants),
                                         "cases": rows}
    path = write(a.out, doc)
    for physics, per in doc["summary"].items():
        for v, s in per.items():
            print(f"{physics} {v}: {s['hits']}/{s['cases']} hits, median closest {s['closest_mm_median']:.0f} mm, "
                  f"{s['within_45_mm']} within 45 mm" + (f"; vs {variants[0]}: {s[f'vs_{variants[0]}']}"
                                                        if s.get(f"vs_{variants[0]}") else ""))
    print(f"-> {path}")


if __name__ == "__main__":
    main()
