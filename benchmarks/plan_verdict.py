"""Benchmark ``plan_verdict``: does the plan stage's verdict say how sure a planned hit is?

Every planned motion of stored loop runs (``loop_*`` under ``--work``, methods ``--methods``) that the lab
played: the first motion (``results/<campaign>/first_motion/motion.json``, judged by trial 1) and each next
motion (``trial_<k>/motion.json``, judged by trial k + 1), with the lab's verdict on it
(``data/<campaign>/trial_<k>/ground_truth.json``, read here, by the benchmark only). The plan's verdict is
:func:`stringcast.plan.verdict.plan_verdict` of the motion.json's own fields (the one motion.json carries
since the verdict exists; recomputed, so runs made before it count alike). The same motion played in two
runs (two methods that planned alike) counts once.

Figures per verdict status and per rule (first, new, failed fit, predicted miss, a residual correction
beyond or within the target's radius, no correction), over all labs and per lab (physics, default cord
or drawn materials): steps, hits, the hit rate and its 95 % Wilson interval; ``rows``: every step.
``results/bench/plan_verdict.json`` (or ``--out NAME``) with the library versions.

Run: ``python -m benchmarks.plan_verdict --work DIR [DIR ...] [--methods ours ...] [--out NAME]``.
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from benchmarks.common import header, write
from benchmarks.loop import RUN_NAME
from stringcast.plan.verdict import BASES, RESIDUAL_WARN_RADII, plan_basis, plan_verdict

def rule(doc: dict) -> str:
    """What a stored motion.json's plan rests on (:func:`~stringcast.plan.verdict.plan_basis`)."""
    return plan_basis(doc.get("origin") or "", bool(doc.get("hit_predicted", True)),
                      float(doc["target"]["radius_mm"]) / 1000, doc.get("residual_correction"),
                      (doc.get("failed_fit") or {}) if doc.get("planned_on_failed_fit") else None)


def verdict_of(doc: dict) -> str:
    """The plan verdict's status for a stored motion.json (:func:`~stringcast.plan.verdict.plan_verdict`)."""
    miss = doc.get("played_observed_miss_mm")
    return plan_verdict(doc.get("origin") or "", bool(doc.get("hit_predicted")), float(doc["closest_approach_mm"]) / 1000,
                        float(doc["target"]["radius_mm"]) / 1000, doc.get("residual_correction"),
                        bool(doc.get("slack_at_predicted_hit")), doc.get("failed_fit"),
                        float("nan") if miss is None else float(miss) / 1000).status


def find_plans(works: list[Path], methods: tuple) -> list[dict]:
    """Every played plan of the runs under ``works`` (module doc): {name, physics, family, type, seed, k
    (the execution the plan was played as), origin, status, rule, residual_mm, predicted_mm, played_mm,
    hit}; a motion played alike in two runs once."""
    rows, seen = [], set()
    for work in works:
        for run in sorted(Path(work).glob("loop_*")):
            m = RUN_NAME.match(run.name)
            if not m or m["method"] not in methods:
                continue
            res, data = run / "results" / run.name, run / "data" / run.name
            plans = [(1, res / "first_motion" / "motion.json")] + [
                (int(p.parent.name.split("_")[1]) + 1, p) for p in res.glob("trial_*/motion.json")]
            for k, plan in sorted(plans):
                truth = data / f"trial_{k}" / "ground_truth.json"
                if not (plan.exists() and truth.exists()):
                    continue
                doc, lab = (json.loads(p.read_text()) for p in (plan, truth))
                key = (m["physics"], bool(m["family"]), m["type"], m["seed"], k, round(float(lab["closest_approach_mm"]), 3))
                if key in seen:
                    continue
                seen.add(key)
                rows.append({"name": run.name, "physics": m["physics"], "family": bool(m["family"]),
                             "type": int(m["type"]), "seed": int(m["seed"]), "k": k, "origin": doc.get("origin") or "",
                             "status": verdict_of(doc), "rule": rule(doc),
                             "residual_mm": (doc.get("residual_correction") or {}).get("median_mm"),
                             "predicted_mm": float(doc["closest_approach_mm"]),
                             "played_mm": float(lab["closest_approach_mm"]), "hit": bool(lab["hit"])})
    return rows


def wilson(hits: int, n: int, z: float = 1.96) -> list[float] | None:
    """The 95 % Wilson score interval of a hit rate (None without a step)."""
    if n == 0:
        return None
    p, d = hits / n, 1 + z * z / n
    c, h = (p + z * z / (2 * n)) / d, z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return [c - h, c + h]


def rates(rows: list[dict]) -> dict:
    """Steps, hits, hit rate and its interval, per status and per rule."""
    def cell(sel):
        hits = sum(r["hit"] for r in sel)
        return {"steps": len(sel), "hits": hits, "rate": hits / len(sel) if sel else None,
                "ci95": wilson(hits, len(sel))}
    return {"all": cell(rows),
            "status": {s: cell([r for r in rows if r["status"] == s]) for s in ("ok", "warn", "fail")},
            "rule": {u: cell([r for r in rows if r["rule"] == u]) for u in BASES}}


def summarize(rows: list[dict]) -> dict:
    """:func:`rates` over all labs and per lab (``<physics> default`` / ``<physics> family``)."""
    labs = sorted({(r["physics"], r["family"]) for r in rows})
    return {"all": rates(rows), **{f"{p} {'family' if f else 'default'}":
                                   rates([r for r in rows if (r["physics"], r["family"]) == (p, f)]) for p, f in labs}}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, nargs="+", required=True, help="folders holding loop_* runs")
    ap.add_argument("--methods", nargs="+", default=["ours"], help="the runs' methods counted (default: ours)")
    ap.add_argument("--out", default="plan_verdict", help="results/bench/<out>.json")
    args = ap.parse_args(argv)
    rows = find_plans(args.work, tuple(args.methods))
    doc = {**header("plan_verdict", False), "work": [str(w) for w in args.work], "methods": args.methods,
           "residual_warn_radii": RESIDUAL_WARN_RADII, "labs": summarize(rows), "rows": rows}
    for lab, fig in doc["labs"].items():
        cells = [(k, c) for k, c in (*fig["status"].items(), *fig["rule"].items()) if c["steps"]]
        print(f"{lab}: " + ", ".join(f"{k} {c['hits']}/{c['steps']}" for k, c in cells))
    print(f"-> {write(args.out, doc)}")


if __name__ == "__main__":
    main()
