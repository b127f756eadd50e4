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

``realised_step`` (docs/method.md, "The realised step of a perturbation"): for each perturbation (narrow or
wide) played as execution k >= 2, how far the lab's tip moved of the way the plan meant it to: its closest
approach to the target (the lab's tip path, ``ground_truth.parquet``, in the lab's hit window) moved from
a_{k-1} to a_k where the plan aimed from a_{k-1} at the target, so the gain is
(a_k - a_{k-1}) . (t - a_{k-1}) / |t - a_{k-1}|^2 (1: the string moved as the model said; a secant, as
Broyden's update measures a Jacobian along its step). Its quartiles over all such steps, and over those that
follow a missed perturbation, with the correlation between consecutive steps' gains; and ``aim_replay``, a
first-order replay of aiming beyond the target (the realised shift scaled with the aim): the hits of a
fixed aim of 1.25 and 1.5 times the step and of 1 / the previous step's gain (clipped below at 0.5, 0.67
and 0.8, at most 1), against the hits as played.

Run: ``python -m benchmarks.plan_verdict --work DIR [DIR ...] [--methods ours ...] [--out NAME]``.
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

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


def lab_closest_point(truth_json: Path, lab: dict) -> np.ndarray | None:
    """The lab's tip at its closest approach to the target within the lab's hit window, mm relative to the
    target (2,), from the trial's ``ground_truth.parquet`` beside ``truth_json`` (``lab``: that json, read);
    None without that file."""
    path = truth_json.with_suffix(".parquet")
    if not path.exists():
        return None
    df = pd.read_parquet(path, columns=["t_s", "point", "x_m", "y_m"])
    tip = df[df["point"] == df["point"].max()]
    lo, hi = lab.get("hit_window_s") or (-np.inf, np.inf)
    tip = tip[(tip["t_s"] >= lo) & (tip["t_s"] <= hi)]
    if tip.empty:
        return None
    xy = tip[["x_m", "y_m"]].to_numpy() * 1000 - np.asarray(lab["target_mm"][:2], float)
    return xy[int(np.argmin(np.hypot(xy[:, 0], xy[:, 1])))]


def realised_gain(before: np.ndarray | None, after: np.ndarray | None) -> float | None:
    """How far a perturbation moved the tip's closest approach of the way to the target (module doc):
    before, after (2,) mm relative to the target; None where either is unknown or before is on the target."""
    if before is None or after is None or not np.hypot(*before) > 0:
        return None
    planned = -np.asarray(before, float)
    return float((np.asarray(after, float) - before) @ planned / (planned @ planned))


def find_plans(works: list[Path], methods: tuple) -> list[dict]:
    """Every played plan of the runs under ``works`` (module doc): {name, run (its folder), physics, family, type, seed, k
    (the execution the plan was played as), origin, status, rule, residual_mm, predicted_mm, played_mm,
    hit, radius_mm, and for a perturbation played as k >= 2 its realised_gain with the lab's closest points
    before_mm and after_mm (else None)}; a motion played alike in two runs once."""
    rows, seen = [], set()
    for work in works:
        for run in sorted(Path(work).glob("loop_*")):
            m = RUN_NAME.match(run.name)
            if not m or m["method"] not in methods:
                continue
            res, data = run / "results" / run.name, run / "data" / run.name
            plans = [(1, res / "first_motion" / "motion.json")] + [
                (int(p.parent.name.split("_")[1]) + 1, p) for p in res.glob("trial_*/motion.json")]
            points: dict[int, np.ndarray | None] = {}
            for k, plan in sorted(plans):
                truth = data / f"trial_{k}" / "ground_truth.json"
                if not (plan.exists() and truth.exists()):
                    continue
                doc, lab = (json.loads(p.read_text()) for p in (plan, truth))
                points[k] = lab_closest_point(truth, lab)
                key = (m["physics"], bool(m["family"]), m["type"], m["seed"], k, round(float(lab["closest_approach_mm"]), 3))
                if key in seen:
                    continue
                seen.add(key)
                rows.append({"name": run.name, "run": str(run), "physics": m["physics"], "family": bool(m["family"]),
                             "type": int(m["type"]), "seed": int(m["seed"]), "k": k, "origin": doc.get("origin") or "",
                             "status": verdict_of(doc), "rule": rule(doc),
                             "residual_mm": (doc.get("residual_correction") or {}).get("median_mm"),
                             "predicted_mm": float(doc["closest_approach_mm"]),
                             "played_mm": float(lab["closest_approach_mm"]), "hit": bool(lab["hit"]),
                             "radius_mm": float(doc["target"]["radius_mm"]),
                             "realised_gain": None, "before_mm": None, "after_mm": None})
                gain = realised_gain(points.get(k - 1), points[k]) \
                    if k >= 2 and doc.get("origin") in ("perturbation", "wide_perturbation") else None
                if gain is not None:
                    rows[-1].update(realised_gain=gain, before_mm=points[k - 1].tolist(), after_mm=points[k].tolist())
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


def realised_steps(rows: list[dict]) -> dict:
    """The realised gains' quartiles over all perturbations and over those after a missed perturbation of the
    same run, and the correlation of consecutive gains (module doc)."""
    def quart(g):
        return {"steps": len(g), "quartiles": np.percentile(g, [25, 50, 75]).tolist() if g else None,
                "range": [min(g), max(g)] if g else None}
    gain = {(r["run"], r["k"]): r["realised_gain"] for r in rows if r.get("realised_gain") is not None}
    pairs = [(g, gain[(run, k + 1)]) for (run, k), g in gain.items() if (run, k + 1) in gain]
    out = {"all": quart(list(gain.values())), "after_a_missed_perturbation": quart([b for _, b in pairs])}
    out["consecutive_correlation"] = float(np.corrcoef(np.array(pairs).T)[0, 1]) if len(pairs) > 2 else None
    out["aim_replay"] = aim_replay([r for r in rows if r.get("realised_gain") is not None], gain)
    return out


def aim_replay(steps: list[dict], gain: dict) -> dict:
    """Hits of each aim rule (module doc) over all realised steps and over those after a missed
    perturbation (``gain``: (run, k) -> realised gain): {rule: {"all": hits, "after_a_miss": hits}}."""
    def hits(scale) -> dict:
        out = {"all": 0, "after_a_miss": 0}
        for r in steps:
            g = scale(gain.get((r["run"], r["k"] - 1)))
            if g is None:
                continue
            b, a = np.asarray(r["before_mm"]), np.asarray(r["after_mm"])
            hit = bool(np.hypot(*(b + g * (a - b))) <= r["radius_mm"])
            out["all"] += hit
            out["after_a_miss"] += hit if (r["run"], r["k"] - 1) in gain else 0
        return out
    rules = {"as played": lambda prev: 1.0, "1.25": lambda prev: 1.25, "1.5": lambda prev: 1.5}
    for lo in (0.5, 0.67, 0.8):
        rules[f"1 / gain, gain in [{lo}, 1]"] = lambda prev, lo=lo: 1.0 if prev is None else 1 / min(1.0, max(lo, prev))
    return {"steps": len(steps), "after_a_miss": sum((r["run"], r["k"] - 1) in gain for r in steps),
            **{name: hits(f) for name, f in rules.items()}}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, nargs="+", required=True, help="folders holding loop_* runs")
    ap.add_argument("--methods", nargs="+", default=["ours"], help="the runs' methods counted (default: ours)")
    ap.add_argument("--out", default="plan_verdict", help="results/bench/<out>.json")
    args = ap.parse_args(argv)
    rows = find_plans(args.work, tuple(args.methods))
    doc = {**header("plan_verdict", False), "work": [str(w) for w in args.work], "methods": args.methods,
           "residual_warn_radii": RESIDUAL_WARN_RADII, "labs": summarize(rows), "realised_step": realised_steps(rows), "rows": rows}
    for lab, fig in doc["labs"].items():
        cells = [(k, c) for k, c in (*fig["status"].items(), *fig["rule"].items()) if c["steps"]]
        print(f"{lab}: " + ", ".join(f"{k} {c['hits']}/{c['steps']}" for k, c in cells))
    step = doc["realised_step"]
    print(f"realised step gain: all {step['all']}, after a missed perturbation {step['after_a_missed_perturbation']}, "
          f"consecutive correlation {step['consecutive_correlation']}, aim replay {step['aim_replay']}")
    print(f"-> {write(args.out, doc)}")


if __name__ == "__main__":
    main()
