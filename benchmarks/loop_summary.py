"""loop.json from the loop benchmark's runs (benchmarks/loop.py; docs/results.md, "Benchmark
records"): its figures per physics (:func:`summarize`), the video check (:func:`video_check`),
the whole document (:func:`document`), its figure (loop.png, :func:`figure`) and its table
(loop.md, :func:`markdown`).

A run is a finished campaign's record (``run.json``, :func:`benchmarks.loop.run_one`). A run
without a hit (or one that failed) counts as ``CAP`` executions in the means: a lower bound.

Intervals are 95 % percentile bootstraps over the campaigns, stratified by string type: each
resample draws, for every type, as many campaigns (seeds) as that type has, with replacement, and
averages the type means, the same estimator as the mean itself (``RESAMPLES`` resamples, seeded
by ``SEED``, so a table is reproducible). The paired difference resamples the per-campaign
differences ours minus the paper's method over the (type, seed) campaigns both methods ran.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks.common import header

CAP = 8
PAPER_TABLE3 = {1: 2, 2: 2, 3: 2, 4: 2, 5: 3, 6: 2, 7: 2}          # executions, paper Table 3
PAPER_TARGET = {1: 1, 2: 1, 3: 2, 4: 3, 5: 3, 6: 3, 7: 4}          # docs/results.md, string types
LABELS = {"paper": "paper_method", "ours": "ours"}
NAMES = {"paper": "the paper's method", "ours": "ours"}
GOALS = {"all_hit_ours": True, "max_ours": CAP, "mean_ours": 1.8, "paired_diff_ci95_hi_below": 0.0,
         "video_check_relative_difference_max": 0.2, "prediction_error_ours_below_paper_method": True}
"""Issue 27's "Done when", per physics."""
RESAMPLES = 10_000
SEED = 0


def executions(rec: dict) -> int:
    """Executions to a hit; a run with no hit (or a failure) counts as ``CAP``."""
    return int(rec["executions"]) if rec["hit"] else CAP


def bootstrap_ci(by_type: dict, resamples: int = RESAMPLES, seed: int = SEED) -> list[float] | None:
    """95 % interval of the mean of the type means (module doc).

    Args:
        by_type: {type: values (S_t,)}, one value per campaign; types without values are left out.

    Returns:
        [lo, hi], or None without any value. A type with one campaign adds no spread: with one
        seed per type the interval is the mean itself.
    """
    groups = [np.asarray(v, float) for v in by_type.values() if len(v)]
    if not groups:
        return None
    rng = np.random.default_rng(seed)
    means = np.mean([g[rng.integers(0, len(g), (resamples, len(g)))].mean(axis=1) for g in groups], axis=0)
    lo, hi = np.percentile(means, [2.5, 97.5])
    return [float(lo), float(hi)]


def prediction_steps(rec: dict) -> list[float]:
    """The run's next-motion prediction errors, mm, one per loop step with a figure (a step whose
    model blew up counts as inf; a step without a figure is left out)."""
    out = []
    for step in rec.get("prediction") or []:
        if step.get("blew_up"):
            out.append(float("inf"))
        elif step.get("median_mm") is not None:
            out.append(float(step["median_mm"]))
    return out


def _median(values: list[float]) -> float | None:
    """The median (inf allowed: it sorts last), or None for no value."""
    return float(np.median(values)) if values else None


def per_string(runs: list[dict], types: list[int], methods: list[str]) -> dict:
    """Executions per seed per method, with hits and means, and the paper's Table 3, per type."""
    per = {}
    for k in types:
        row = {"paper_table3": PAPER_TABLE3[k], "target": PAPER_TARGET[k]}
        for m in methods:
            rs = sorted((r for r in runs if r["string"] == k and r["method"] == m), key=lambda r: r["seed"])
            row[LABELS[m]] = [executions(r) for r in rs]
            row[f"{LABELS[m]}_hit"] = [bool(r["hit"]) for r in rs]
            row[f"{LABELS[m]}_mean"] = float(np.mean(row[LABELS[m]])) if rs else None
        per[str(k)] = row
    return per


def paired(runs: list[dict], methods: list[str]) -> tuple[dict, list[tuple]]:
    """Each method's executions per campaign, {method: {(type, seed): executions}}, and the campaigns
    (type, seed) every method finished, sorted: the like-for-like comparison."""
    done = {m: {(r["string"], r["seed"]): executions(r) for r in runs if r["method"] == m} for m in methods}
    return done, sorted(set.intersection(*(set(d) for d in done.values())))


def summarize(runs: list[dict], types: list[int], methods: list[str]) -> dict:
    """One physics' entry of loop.json (docs/results.md): per_string; per method ``campaigns``, the mean
    (type means averaged), max, all-hit flag, first-shot hit rate and the median next-motion prediction
    error over every loop step, ``fit_skill_*`` (the fit check's skill, median and 10th percentile over every
    fit), and the campaigns that ended in an error (``failed_*``, [type, seed];
    counted as ``CAP`` without a hit); ``mean_ours_ci95``; and over the campaigns both methods ran,
    ``paired_campaigns``, ``paired_mean_*`` and ``paired_diff_ci95`` (ours minus the paper's)."""
    per = per_string(runs, types, methods)
    out = {"per_string": per, "campaigns_per_method": {}}
    for m in methods:
        lab, mine = LABELS[m], [r for r in runs if r["method"] == m]
        means = [per[str(k)][f"{lab}_mean"] for k in types if per[str(k)][f"{lab}_mean"] is not None]
        allx = [x for k in types for x in per[str(k)][lab]]
        steps = [e for r in mine for e in prediction_steps(r)]
        out["campaigns_per_method"][lab] = len(mine)
        out[f"mean_{lab}"] = float(np.mean(means)) if means else None
        out[f"mean_{lab}_ci95"] = bootstrap_ci({k: per[str(k)][lab] for k in types})
        out[f"max_{lab}"] = int(max(allx)) if allx else None
        out[f"all_hit_{lab}"] = bool(allx) and all(h for k in types for h in per[str(k)][f"{lab}_hit"])
        out[f"first_shot_hit_rate_{lab}"] = (float(np.mean([bool(r["hit"]) and r["executions"] == 1 for r in mine]))
                                             if mine else None)
        out[f"prediction_error_mm_{lab}"] = _median(steps)
        out[f"prediction_steps_{lab}"] = len(steps)
        skills = [x for r in mine for x in (r.get("fit_skill") or []) if x is not None]
        out[f"fit_skill_{lab}"] = ({"median": float(np.median(skills)), "p10": float(np.percentile(skills, 10)),
                                    "fits": len(skills)} if skills else None)
        # a campaign that ended in an error counts as CAP executions without a hit: named, never silent
        out[f"failed_{lab}"] = sorted([int(r["string"]), int(r["seed"])] for r in mine if r["error"])
    out["paper_table3_mean"] = float(np.mean([PAPER_TABLE3[k] for k in types]))
    out["paired_diff_ci95"] = None
    if len(methods) > 1:  # the campaigns (type, seed) every method finished: a like-for-like comparison
        done, both = paired(runs, methods)
        out["paired_campaigns"] = len(both)
        for m in methods:
            out[f"paired_mean_{LABELS[m]}"] = float(np.mean([done[m][c] for c in both])) if both else None
        if {"ours", "paper"} <= set(methods):
            diff = {k: [done["ours"][c] - done["paper"][c] for c in both if c[0] == k] for k in types}
            out["paired_diff_ci95"] = bootstrap_ci(diff)
    for lab in LABELS.values():   # issue 27's keys are there for a method not run, as null
        for key in ("mean_{}", "mean_{}_ci95", "max_{}", "all_hit_{}", "first_shot_hit_rate_{}",
                    "prediction_error_mm_{}"):
            out.setdefault(key.format(lab), None)
    return out


def video_check(video: list[dict], state: dict | None, state_runs: list[dict], types: list[int],
                methods: list[str]) -> dict:
    """One physics' video check: the video-mode runs' summary (:func:`summarize`) and, per method, the
    relative difference of their mean to the state mode's (``relative_difference_<label>``:
    (video - state) / state, against the state entry's mean; ``..._same_campaigns``: against the
    state mode's mean over the same (type, seed) campaigns). With one filmed seed per type the
    intervals by type have no spread; ``paired_diffs`` lists each campaign's (type, seed, ours minus the
    paper's) and ``paired_diff_ci95_pooled`` resamples the campaigns as one group."""
    out = summarize(video, types, methods)
    if {"ours", "paper"} <= set(methods):
        done, both = paired(video, ["ours", "paper"])
        diffs = [[k, s, done["ours"][(k, s)] - done["paper"][(k, s)]] for k, s in both]
        out["paired_diffs"] = diffs
        out["paired_diff_ci95_pooled"] = bootstrap_ci({"all": [d for *_, d in diffs]})
    for m in methods:
        lab = LABELS[m]
        v, s = out.get(f"mean_{lab}"), (state or {}).get(f"mean_{lab}")
        out[f"relative_difference_{lab}"] = (v - s) / s if v is not None and s else None
        by_mode = [{(r["string"], r["seed"]): executions(r) for r in rs if r["method"] == m} for rs in (video, state_runs)]
        both = set(by_mode[0]) & set(by_mode[1])
        vm, sm = (float(np.mean([d[c] for c in both])) if both else None for d in by_mode)
        out[f"relative_difference_{lab}_same_campaigns"] = (vm - sm) / sm if both and sm else None
    return out


def figure(entries: dict, methods: list[str], path: Path) -> None:
    """loop.png: executions per type, one panel per physics (Table 3, each method's mean as a bar,
    one dot per seed, red where no hit within the cap)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(entries)
    fig, axes = plt.subplots(len(names), 1, figsize=(1.2 * 7 + 3, 3.0 * len(names) + 0.8), squeeze=False)
    for ax, name in zip(axes[:, 0], names):
        _panel(ax, entries[name]["per_string"], methods)
        ax.set_title(f"{name} ({entries[name].get('mode', '?')} mode): dots one seed each (red: no hit within "
                     "the cap)", fontsize=8)
    axes[-1, 0].legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=1 + len(methods),
                       frameon=False)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _panel(ax, per: dict, methods: list[str]) -> None:
    keys = sorted(per, key=int)
    x = np.arange(len(keys))
    series = [("paper_table3", "paper, Table 3", "0.6")] + [
        (LABELS[m], {"paper": "paper's method (measured)", "ours": "ours"}[m], c) for m, c in zip(methods, ("C1", "C0"))]
    w = 0.8 / len(series)
    for i, (key, label, colour) in enumerate(series):
        xs = x - 0.4 + w * (i + 0.5)
        if key == "paper_table3":
            ax.bar(xs, [per[k][key] for k in keys], w, color=colour, label=label)
            continue
        ax.bar(xs, [per[k][f"{key}_mean"] or 0 for k in keys], w, color=colour, alpha=0.6, label=label)
        for xi, k in zip(xs, keys):
            vals, hits = per[k][key], per[k][f"{key}_hit"]
            ax.scatter([xi] * len(vals), vals, s=14, c=["k" if h else "r" for h in hits], zorder=3)
    ax.axhline(CAP, color="r", lw=0.8, ls=":")
    ax.set_xticks(x, [f"type {k}" for k in keys])
    ax.set_ylabel("executions to a hit")
    ax.set_ylim(0, CAP + 0.5)


def _f(v, fmt: str = ".2f") -> str:
    if v is None:
        return "-"
    if isinstance(v, list):
        return "[" + ", ".join(_f(x, fmt) for x in v) + "]"
    return format(v, fmt)


def table(entry: dict, methods: list[str]) -> str:
    """One physics' Markdown table: executions per seed per type (* = no hit), means, intervals,
    first-shot hit rates and next-motion prediction errors."""
    cols = ["string type", "target", "paper Table 3"] + [f"{NAMES[m]} (seeds)" for m in methods]
    lines = ["| " + " | ".join(cols) + " |", "|" + " --- |" * len(cols)]

    def cell(vals, hits):
        return ", ".join(str(v) if h else f"{v}*" for v, h in zip(vals, hits)) or "-"
    for k in sorted(entry["per_string"], key=int):
        r = entry["per_string"][k]
        lines.append(f"| {k} | {r['target']} | {r['paper_table3']} | "
                     + " | ".join(cell(r[LABELS[m]], r[f"{LABELS[m]}_hit"]) for m in methods) + " |")

    lines.append(f"| mean | | {entry['paper_table3_mean']:.2f} | "
                 + " | ".join(_f(entry.get(f"mean_{LABELS[m]}")) for m in methods) + " |")
    lines.append("| 95 % interval of the mean | | | " + " | ".join(_f(entry.get(f"mean_{LABELS[m]}_ci95"))
                                                               for m in methods) + " |")
    lines.append("| first-shot hit rate | | | " + " | ".join(_f(entry.get(f"first_shot_hit_rate_{LABELS[m]}"))
                                                         for m in methods) + " |")
    lines.append("| next-motion prediction error, mm (median over steps) | | | "
                 + " | ".join(_f(entry.get(f"prediction_error_mm_{LABELS[m]}"), ".1f") for m in methods) + " |")
    if any(entry.get(f"failed_{LABELS[m]}") for m in methods):
        lines.append("| ended in an error (type, seed; counted as 8*) | | | " + " | ".join(
            ", ".join(f"{k}/{s}" for k, s in entry.get(f"failed_{LABELS[m]}") or []) or "-" for m in methods) + " |")
    if entry.get("paired_campaigns"):
        lines.append(f"| mean over the {entry['paired_campaigns']} campaigns both methods finished | | | "
                     + " | ".join(_f(entry.get(f"paired_mean_{LABELS[m]}")) for m in methods) + " |")
    if entry.get("paired_diff_ci95") is not None:
        lines.append(f"\nOurs minus the paper's method, paired, 95 % interval: {_f(entry['paired_diff_ci95'])} "
                     "executions.")
    return "\n".join(lines) + "\n"


def document(runs: list[dict], spec, complete: bool, quick: bool, overlays: dict) -> dict:
    """loop.json (benchmarks/loop.py's module doc) from the runs so far; ``spec``: the run's
    :class:`benchmarks.loop.Spec`, ``overlays``: each method's config overlay."""
    types, methods = list(spec.types), list(spec.methods)
    doc = header("loop", quick) | {
        "cap": CAP, "complete": complete, "types": types, "seeds": list(spec.seeds),
        "methods": {m: overlays[m] for m in methods}, "physics": list(spec.physics), "mode": spec.mode}
    for p in spec.physics:
        main = [r for r in runs if _identity(r) == (p, spec.mode)]
        doc[p] = summarize(main, types, methods) | {"mode": spec.mode}
    vc = {"types": list(spec.video_types or types), "seeds": list(spec.video_seeds),
          "methods": list(spec.video_methods)}
    if spec.mode != "state" or not spec.video_seeds:
        vc["skipped"] = "the main runs are the video mode" if spec.mode == "video" else "no --video-seeds"
    for p in spec.physics if "skipped" not in vc else ():
        vids = [r for r in runs if _identity(r)[0] == p and _identity(r)[1] == "video"]
        state = [r for r in runs if _identity(r)[0] == p and _identity(r)[1] == "state"]
        vc[p] = video_check(vids, doc[p], state, vc["types"], list(spec.video_methods)) | {"mode": "video"}
    doc["video_check"] = vc
    models = {str(r["string"]): r["state_mode"]["error_model"] for r in runs if r.get("state_mode")}
    doc["state_mode"] = None if spec.mode != "state" else {
        "what": "the lab's true points at the camera's frames with the tracking's measured error, dropout and sync "
                "error drawn independently per frame and point (benchmarks/loop_state.py); no video, calibration, "
                "sync or tracking ran; the workflow's estimate, plan and predict rules ran unchanged",
        "error_model_per_type": dict(sorted(models.items()))}
    modes = sorted({_identity(r)[1] for r in runs})
    return doc | {
        "paper_table3": {str(k): v for k, v in PAPER_TABLE3.items()}, "paper_table3_mean_all": 2.14,
        "reference": {"name": "paper_table3", "mean": float(np.mean(list(PAPER_TABLE3.values())))},
        "goals": GOALS, "lab": "full-size (config/config.yaml as is, plus the method overlay and lab.physics)",
        "runs": runs,
        "seconds_per_execution_mean": {m: _mean([r.get("s_per_execution") for r in runs if _identity(r)[1] == m])
                                       for m in modes},
        "seconds_per_campaign_mean": {m: _mean([r.get("wall_s") for r in runs if _identity(r)[1] == m and not r["error"]])
                                      for m in modes},
        "git_commits": {m: sorted({r.get("git_commit") or "unrecorded" for r in runs if r["method"] == m})
                        for m in methods},
        "figure": "loop.png", "table": "loop.md",
    }


def _identity(rec: dict) -> tuple[str, str]:
    """A run's (physics, mode); runs recorded before issue 27 were MuJoCo, filmed."""
    return rec.get("physics", "mujoco"), rec.get("mode", "video")


def _mean(values) -> float | None:
    v = [x for x in values if x]
    return float(np.mean(v)) if v else None


def markdown(doc: dict, spec) -> str:
    """loop.md: a table per physics (:func:`benchmarks.loop_summary.table`), the video check and the commits."""
    total = len(spec.campaigns())
    partial = "" if doc["complete"] else f" Partial run: {len(doc['runs'])} of {total} campaigns so far."
    out = [f"Executions until the lab's tip hits (cap {CAP}; * = no hit, counted as {CAP}).{partial}\n"]
    for p in spec.physics:
        out.append(f"## {p} ({doc[p]['mode']} mode)\n\n" + table(doc[p], list(spec.methods)))
    vc = doc["video_check"]
    for p in spec.physics if "skipped" not in vc else ():
        diffs = ", ".join(f"{lab}: {vc[p].get(f'relative_difference_{lab}'):+.0%}" for lab in ("ours", "paper_method")
                          if vc[p].get(f"relative_difference_{lab}") is not None) or "-"
        pooled = ("" if vc[p].get("paired_diff_ci95_pooled") is None else "\nWith one seed per type the intervals above "
                  f"have no spread; pooled over the campaigns, ours minus the paper's: {_f(vc[p]['paired_diff_ci95_pooled'])} "
                  "(each campaign's: " + ", ".join(f"type {k} {d:+d}" for k, _, d in vc[p]["paired_diffs"]) + ").\n")
        out.append(f"## {p}, video-mode check\n\n" + table(vc[p], list(spec.video_methods))
                   + f"\nRelative difference of the video mode's mean to the state mode's: {diffs}.\n" + pooled)
    commits = "; ".join(f"{m} at " + ", ".join(c[:7] + c[40:] if len(c) >= 40 else c for c in cs)
                        for m, cs in doc["git_commits"].items() if cs)
    return "\n".join(out) + (f"\nCode that ran the campaigns: {commits}.\n" if commits else "")


def family_into(loop_json: Path, doc: dict, spec, materials: dict) -> dict:
    """loop.json with ``doc`` (a family run's document) as its ``family`` entry: per physics the summary
    (:func:`benchmarks.loop_summary.summarize`'s keys, ``fit_skill``), the draws (type, seed, material)
    and whether the family run is complete, ``materials`` (each seed's ``lab.material``) and, where the run
    filmed some, ``video_check`` (:func:`video_check` per physics); another physics' family entry (and
    filmed check) and the rest of loop.json as they were (a fresh one if none)."""
    from stringcast.core import read_json

    base = read_json(loop_json) if loop_json.exists() else header("loop", False)
    family = dict(base.get("family") or {})    # another physics' family entry stays (a run per engine)
    runs = [r for r in family.get("runs", []) if r["physics"] not in spec.physics] + doc["runs"]
    family.update({p: doc[p] | {"draws": [list(d) for d in sorted({(r["string"], r["seed"], (r.get("material") or {})
                                                                     .get("class")) for r in doc["runs"] if r["physics"] == p})]}
                   for p in spec.physics})
    family.update({"complete": doc["complete"], "mode": spec.mode, "types": list(spec.types),
                   "seeds": list(spec.seeds), "materials": materials,
                   "runs": runs, "git_commits": doc["git_commits"], "libraries": doc["libraries"]})
    if "skipped" not in doc.get("video_check", {"skipped": True}):   # the run's filmed campaigns (another
        family["video_check"] = dict(family.get("video_check") or {}) | doc["video_check"]   # engine's stay)
    base["family"] = family
    return base
