"""Benchmark ``next_step``: the later steps of stored loop runs, each re-planned with a variant and played
by the lab, paired with what the loop played there.

A change to the planner is judged here step by step, before a loop run. The virtual lab is deterministic
in the motion it plays (its seed moves the joint log's noise, the trigger and the camera, not the
string: docs/method.md, "The least change of the played motion"), so a step re-planned to the motion the
loop played has the loop's outcome without a second run, and a changed motion is judged by the same
physics. A step is trial k of a loop run (``loop_*`` under ``--work``, method ``--method``) with a next
motion (``results/<campaign>/trial_<k>/motion.json``, its ``origin`` in ``--origins``) and the lab's
verdict on it (``data/<campaign>/trial_<k+1>/ground_truth.json``, read here, by the benchmark only). It is
re-planned as the workflow's ``plan`` rule plans it (:func:`stringcast.api.run_plan`: seed k, the
trial's params.json, tracks.parquet and joints.csv, the played motion.json), with the run's own config
and the variant's settings merged over it; a changed motion is played by the virtual lab without
filming, with the loop's executor seed (the campaign's seed x 1000 + k + 1). Each step is judged alone:
what a changed step would have changed later in its campaign is the loop benchmark's question.

Figures per lab (physics, default cord or drawn materials), origin and in all: steps, the loop's hits,
the variant's hits, steps gained and lost, motions changed, and the median closest approach of each.
``results/bench/next_step.json`` (or ``--out NAME``) with every step's row and the library versions.

Run: ``python -m benchmarks.next_step --work DIR [DIR ...] --variant NAME=FILE [--method ours]
[--origins perturbation wide_perturbation new] [--jobs 2] [--keep DIR] [--out NAME]``.
"""
from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import yaml

from benchmarks.common import header, play_on_lab, write
from benchmarks.loop import RUN_NAME

ORIGINS = ("perturbation", "wide_perturbation", "new")


def find_steps(works: list[Path], method: str, origins: tuple) -> list[dict]:
    """Every step of the loop runs under ``works`` of ``method``: {run, name, k, physics, family, origin,
    played closest approach mm and hit, target radius mm}, ordered by run and k. Runs whose names are
    not the loop benchmark's, and trials without a next motion or a verdict on it, are passed over."""
    steps = []
    for work in works:
        for run in sorted(Path(work).glob("loop_*")):
            m = RUN_NAME.match(run.name)
            if not m or m["method"] != method:
                continue
            for plan in sorted((run / "results" / run.name).glob("trial_*/motion.json"),
                               key=lambda p: int(p.parent.name.split("_")[1])):
                k = int(plan.parent.name.split("_")[1])
                truth = run / "data" / run.name / f"trial_{k + 1}" / "ground_truth.json"
                if not truth.exists():
                    continue
                doc, verdict = (json.loads(p.read_text()) for p in (plan, truth))
                if doc.get("origin") not in origins:
                    continue
                steps.append({"run": str(run), "name": run.name, "k": k, "physics": m["physics"],
                              "family": bool(m["family"]), "origin": doc["origin"],
                              "played_mm": float(verdict["closest_approach_mm"]), "played_hit": bool(verdict["hit"]),
                              "radius_mm": float(doc["target"]["radius_mm"])})
    return steps


def replan_step(case: tuple) -> dict:
    """Re-plan one step with the variant's settings and judge it (module doc): the step's row with the
    variant's closest approach mm, hit, predicted closest approach mm and whether its motion changed."""
    step, overlay, out = case
    from stringcast.api import run_plan
    from stringcast.core import load_config, merge_config, read_json, resolve_campaign, settings_from_config

    t0 = time.perf_counter()
    run, name, k = Path(step["run"]), step["name"], step["k"]
    res, data = run / "results" / name / f"trial_{k}", run / "data" / name
    cfg = merge_config({a: b for a, b in load_config(run / "config" / "config.yaml").items() if a != "_path"},
                       overlay or {})
    doc = yaml.safe_load((data / "campaign.yaml").read_text())
    campaign = resolve_campaign(doc, cfg, name)
    settings = settings_from_config(cfg)
    d = Path(out) / f"{name}_t{k}"
    d.mkdir(parents=True, exist_ok=True)
    plan = run_plan(res / "params.json", data / f"trial_{k}" / "motion.json", campaign, d / "motion.csv",
                    d / "motion.json", k, res / "tracks.parquet", data / f"trial_{k}" / "joints.csv",
                    model=settings.model, motion=settings.motion)
    played = data / f"trial_{k + 1}"
    changed = (d / "motion.csv").read_bytes() != (played / "motion.csv").read_bytes()
    truth = played / "ground_truth.json"
    if changed:
        truth = d / "trial" / "ground_truth.json"
        if not truth.exists():
            play_on_lab(d / "motion.csv", d / "trial", campaign, settings.executor, cfg,
                        int(doc.get("seed", 0)) * 1000 + k + 1)
    verdict = read_json(truth)
    return step | {"changed": changed, "variant_mm": float(verdict["closest_approach_mm"]),
                   "variant_hit": bool(verdict["hit"]), "predicted_mm": float(plan.d_min) * 1000,
                   "seconds": time.perf_counter() - t0}


def summarize(rows: list[dict]) -> dict:
    """Per lab ("mujoco default", "elastica family", ...) and in all, per origin and in all: steps, the
    loop's and the variant's hits, gained, lost, changed, and each one's median closest approach (mm)."""
    def figures(rs: list[dict]) -> dict:
        return {"steps": len(rs), "played_hits": sum(r["played_hit"] for r in rs),
                "variant_hits": sum(r["variant_hit"] for r in rs),
                "gained": sum(r["variant_hit"] and not r["played_hit"] for r in rs),
                "lost": sum(r["played_hit"] and not r["variant_hit"] for r in rs),
                "changed": sum(r["changed"] for r in rs),
                "played_mm_median": float(np.median([r["played_mm"] for r in rs])),
                "variant_mm_median": float(np.median([r["variant_mm"] for r in rs]))}

    labs = {"all": rows}
    for r in rows:
        labs.setdefault(f"{r['physics']} {'family' if r['family'] else 'default'}", []).append(r)
    out = {}
    for lab, rs in labs.items():
        per = {"all": figures(rs)}
        per |= {o: figures([r for r in rs if r["origin"] == o]) for o in ORIGINS if any(r["origin"] == o for r in rs)}
        out[lab] = per
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, nargs="+", required=True, help="loop work folders (their loop_* runs)")
    ap.add_argument("--variant", required=True, help="NAME=FILE: FILE's settings merged over each run's config")
    ap.add_argument("--method", default="ours", help="the runs' method (the run name's last part)")
    ap.add_argument("--origins", nargs="+", default=list(ORIGINS), choices=ORIGINS)
    ap.add_argument("--jobs", type=int, default=2, help="steps re-planned side by side (processes)")
    ap.add_argument("--keep", type=Path, help="keep each step's plan and play here (a later run reuses the played)")
    ap.add_argument("--out", default="next_step", help="results/bench/<OUT>.json")
    a = ap.parse_args()
    name, _, path = a.variant.partition("=")
    if not path:
        raise SystemExit(f"--variant {a.variant}: NAME=FILE expected")
    overlay = yaml.safe_load(Path(path).read_text()) or {}
    steps = find_steps(a.work, a.method, tuple(a.origins))
    if not steps:
        raise SystemExit(f"no step of method {a.method} with origin in {a.origins} under {[str(w) for w in a.work]}")
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")   # the steps run side by side, one core each
    with tempfile.TemporaryDirectory(prefix="bench_next_step_") as tmp:
        out = Path(a.keep or tmp)
        rows = []
        with ProcessPoolExecutor(max(1, a.jobs), mp_context=multiprocessing.get_context("spawn")) as pool:
            for r in pool.map(replan_step, [(s, overlay, str(out)) for s in steps]):
                rows.append(r)
                print(f"  {r['name']} trial {r['k']} ({r['origin']}): played {r['played_mm']:.1f} mm, {name} "
                      f"{r['variant_mm']:.1f} mm{' (same motion)' if not r['changed'] else ''}", flush=True)
    doc = header("next_step", False) | {"variant": {name: overlay}, "method": a.method, "origins": a.origins,
                                        "work": [str(w) for w in a.work], "summary": summarize(rows), "steps": rows}
    path = write(a.out, doc)
    for lab, per in doc["summary"].items():
        for origin, s in per.items():
            print(f"{lab:17s} {origin:17s} {s['steps']:3d} steps: hits {s['played_hits']} -> {s['variant_hits']} "
                  f"(+{s['gained']} -{s['lost']}, {s['changed']} changed)")
    print(f"-> {path}")


if __name__ == "__main__":
    main()
