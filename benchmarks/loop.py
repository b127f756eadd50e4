"""Benchmark ``loop``: executions until the lab's tip hits, per string type, next to the paper's Table 3.

For every string type (1-7) with its paper target (docs/results.md, "String types": types 1,
2 -> target 1; 3 -> 2; 4, 5, 6 -> 3; 7 -> 4), every seed and every method, the whole loop runs
as a person would run it: :func:`stringcast.campaign.run_campaign` in a project root of its own
(the repo's Snakefile and workflow/ linked, its own config/config.yaml carrying the
method), at most ``CAP`` = 8 executions. Whether the tip hit is the *lab's* verdict
(``ground_truth.json`` of the last trial, as the campaign loop reads it to stop); the
workflow's stages never read it. The campaigns run with ``reports=False``: no HTML
reports, and the hitting trial is not processed (its E is then null), about a third
less time per run.

Methods are config overlays:

* ``paper``: ``estimation.optimizer: random_search`` (eqs. 2-3) and ``motion.planner: paper``
  (Section V), the paper's method as the config describes it.
* ``ours``: ``config/ours.yaml``, read at import (the file ``snakemake --configfile`` and
  ``stringcast campaign --method ours`` use): CMA-ES (two runs), the robust planner with the
  residual correction and the replan rules, tip weighting w = 1, the first plan with Table 2's
  largest k_s, and the hand spring's range up to 1. Each line's reason is in the file; the
  evidence, and what was tried and left out (``motion.first_ensemble``, ``robust_min_share``,
  ``estimation.joint_trials``, ...), is in docs/method.md.

A seed ``s`` sets the lab's noise (the campaign's seed: camera noise, joint noise, trigger
error) and the pipeline's own searches (``estimation.seed`` and ``motion.seed`` = ``s``), so
the seeds differ in both the lab and the method.

Per run: executions, hit, the lab's closest approach per execution (mm), E per trial
(params.json, mm), wall seconds and seconds per execution. Per type: the executions per
seed for each method and the paper's Table 3 figure; overall: ``mean_ours``,
``mean_paper_method``, ``max_ours``, ``all_hit_ours`` (every seed of every type hit within
the cap). A run without a hit counts as ``cap`` executions in the means (a lower bound).
Goal (issue 4): every type hits within 8 for every seed, and ``mean_ours`` <= 2.0 (paper 2.14).

Figure: results/bench/loop.png (executions per type: Table 3, the paper's method, ours,
one dot per seed); table: results/bench/loop.md.

Run: ``python -m benchmarks.loop [--quick] [--types 1 5] [--seeds 0 1 2] [--methods paper ours]
[--work DIR]``, one campaign after another in this process.

The campaigns are independent, so they may also run as separate jobs, side by side or on a
cluster, through ``benchmarks/loop.smk`` (Snakemake): one job per campaign
(``python -m benchmarks.loop --only TYPE SEED METHOD --work DIR``: its ``run.json`` only), then
one that gathers them into loop.json (``--finished-only``)::

    snakemake -s benchmarks/loop.smk --cores 8 --config work=/data/loop seeds="0 1 2"
    snakemake -s benchmarks/loop.smk --profile config/profiles/slurm --config work=/shared/loop

 A full run (7 types x 3 seeds x 2 methods, full-size lab) takes hours on
2 cores; ``--quick`` is types 1 and 5, seed 0, both methods. ``--work`` keeps every
campaign (data/ and results/) and its ``run.json``; a later run with the same DIR reuses
finished runs and resumes unfinished campaigns; ``--finished-only`` runs nothing and
summarizes the finished ones (``paired_mean_*``: the means over the campaigns both
methods finished). loop.json, loop.png and loop.md are
rewritten after every run (``"complete": false`` until the last), so a stopped run leaves
a consistent partial result.
"""
from __future__ import annotations

import argparse
import copy
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from benchmarks.common import BENCH_DIR, ROOT, git_commit, header, library_versions, write

CAP = 8
PAPER_TABLE3 = {1: 2, 2: 2, 3: 2, 4: 2, 5: 3, 6: 2, 7: 2}          # executions, paper Table 3
PAPER_TARGET = {1: 1, 2: 1, 3: 2, 4: 3, 5: 3, 6: 3, 7: 4}          # docs/results.md, string types
OURS_CONFIG = ROOT / "config" / "ours.yaml"
METHODS = {
    "paper": {"estimation": {"optimizer": "random_search"}, "motion": {"planner": "paper"}},
    "ours": yaml.safe_load(OURS_CONFIG.read_text()),   # one place for ours' settings
}
LABELS = {"paper": "paper_method", "ours": "ours"}


def method_config(config: dict, method: str, seed: int) -> dict:
    """The config a run uses: ``config`` (as loaded) with the method's overlay and the seed.

    Raises:
        KeyError: unknown method (not in ``METHODS``).
    """
    from stringcast.core import merge_config

    cfg = merge_config(copy.deepcopy({k: v for k, v in config.items() if k != "_path"}), METHODS[method])
    cfg.setdefault("estimation", {})["seed"] = int(seed)   # the config file may leave a section to its defaults
    cfg.setdefault("motion", {})["seed"] = int(seed)
    return cfg


def project_root(path: Path, cfg: dict) -> Path:
    """A project root at ``path``: the repo's Snakefile and workflow/ linked, ``cfg`` as
    config/config.yaml (written atomically). Returns the config file's path."""
    from stringcast.core.files import write_yaml

    (path / "config").mkdir(parents=True, exist_ok=True)
    for name in ("Snakefile", "workflow"):
        link = path / name
        if not link.exists():
            link.symlink_to(ROOT / name)
    cfg_path = path / "config" / "config.yaml"
    write_yaml(cfg_path, cfg)
    return cfg_path


def run_dir(work: Path, string_type: int, seed: int, method: str) -> Path:
    """The campaign's project folder (and campaign name) under ``work``."""
    return work / f"loop_s{string_type}_seed{seed}_{method}"


def run_one(string_type: int, seed: int, method: str, config: dict, work: Path, cores: int = 2) -> dict:
    """One campaign: string ``string_type`` at its paper target, ``method``, ``seed``, at most ``CAP``
    executions. Reuses ``work/<name>/run.json`` when a previous run finished.

    Returns a dict: executions, hit, closest_approach_mm (per execution, lab truth), E_mm (per
    trial, params.json), wall_s, s_per_execution, timings_s, git_commit and libraries (the code
    and library versions that ran it: a table may gather campaigns run at different commits,
    ``--finished-only``), error (None, or the failure)."""
    from stringcast.campaign import run_campaign
    from stringcast.core.files import DataError, read_json, write_json

    root = run_dir(work, string_type, seed, method)
    name = root.name
    done = root / "run.json"
    if done.exists():
        return read_json(done)
    cfg_path = project_root(root, method_config(config, method, seed))
    rec = {"string": string_type, "target": PAPER_TARGET[string_type], "seed": seed, "method": method,
           "campaign": name, "git_commit": git_commit(), "libraries": library_versions(), "error": None}
    t0 = time.perf_counter()
    try:
        summary = run_campaign(name, str(string_type), str(PAPER_TARGET[string_type]),
                               config_path=str(cfg_path), max_executions=CAP, cores=cores,
                               seed=seed, root=root, reports=False, keep_frames=False)
    except (RuntimeError, DataError) as exc:  # a failed workflow step or trial is a result, not the end
        rec.update(executions=None, hit=False, closest_approach_mm=[], E_mm=[], timings_s={},
                   wall_s=time.perf_counter() - t0, s_per_execution=None,
                   error=f"{type(exc).__name__}: {exc}")
        write_json(done, rec)
        return rec
    rec["wall_s"] = time.perf_counter() - t0
    trials = summary["trials"]
    rec["executions"] = len(trials)
    rec["hit"] = bool(trials[-1]["hit"])                 # the lab's verdict on the last execution
    rec["closest_approach_mm"] = [float(t["closest_approach_mm"]) for t in trials]
    rec["E_mm"] = []
    for t in trials:
        p = root / "results" / name / f"trial_{t['trial']}" / "params.json"
        e = read_json(p).get("E_mm") if p.exists() else None
        rec["E_mm"].append(None if e is None else float(e))
    rec["timings_s"] = summary["timings_s"]
    per_exec = [v for k, v in summary["timings_s"].items() if k.startswith(("execute_", "process_"))]
    rec["s_per_execution"] = float(sum(per_exec) / len(trials)) if per_exec else None
    write_json(done, rec)
    return rec


def _executions(rec: dict) -> int:
    """Executions to a hit; a run with no hit (or a failure) counts as ``CAP``."""
    return int(rec["executions"]) if rec["hit"] else CAP


def summarize(runs: list[dict], types: list[int], methods: list[str]) -> dict:
    """loop.json's summary keys (docs/results.md, "Benchmark records") from the runs: per_string
    (executions per seed per method, Table 3), means over every run (type means averaged over the
    types run), max and all-hit flags."""
    per, out = {}, {}
    for k in types:
        row = {"paper_table3": PAPER_TABLE3[k], "target": PAPER_TARGET[k]}
        for m in methods:
            rs = sorted((r for r in runs if r["string"] == k and r["method"] == m), key=lambda r: r["seed"])
            row[LABELS[m]] = [_executions(r) for r in rs]
            row[f"{LABELS[m]}_hit"] = [bool(r["hit"]) for r in rs]
            row[f"{LABELS[m]}_mean"] = float(np.mean(row[LABELS[m]])) if rs else None
        per[str(k)] = row
    out["per_string"] = per
    for m in methods:
        lab = LABELS[m]
        means = [per[str(k)][f"{lab}_mean"] for k in types if per[str(k)][f"{lab}_mean"] is not None]
        allx = [x for k in types for x in per[str(k)][lab]]
        out[f"mean_{lab}"] = float(np.mean(means)) if means else None
        out[f"max_{lab}"] = int(max(allx)) if allx else None
        out[f"all_hit_{lab}"] = bool(allx) and all(h for k in types for h in per[str(k)][f"{lab}_hit"])
    out["paper_table3_mean"] = float(np.mean([PAPER_TABLE3[k] for k in types]))
    if len(methods) > 1:  # the campaigns (type, seed) every method finished: a like-for-like comparison
        done = {m: {(r["string"], r["seed"]): _executions(r) for r in runs if r["method"] == m} for m in methods}
        both = sorted(set.intersection(*(set(d) for d in done.values())))
        out["paired_campaigns"] = len(both)
        for m in methods:
            out[f"paired_mean_{LABELS[m]}"] = float(np.mean([done[m][c] for c in both])) if both else None
    return out


def _figure(per: dict, methods: list[str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = sorted(per, key=int)
    x = np.arange(len(keys))
    series = [("paper_table3", "paper, Table 3", "0.6")] + [(LABELS[m], {"paper": "paper's method (measured)",
                                                                        "ours": "ours"}[m], c)
                                                           for m, c in zip(methods, ("C1", "C0"))]
    w = 0.8 / len(series)
    fig, ax = plt.subplots(figsize=(1.2 * len(keys) + 3, 3.6))   # the legend under the axes hides no dot
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
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=len(series), frameon=False)
    ax.set_title("dots: one seed each (red: no hit within the cap)", fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _table(doc: dict, methods: list[str]) -> str:
    cols = ["string type", "target", "paper Table 3"] + [{"paper": "paper's method (seeds)", "ours": "ours (seeds)"}[m]
                                                         for m in methods]
    lines = ["| " + " | ".join(cols) + " |", "|" + " --- |" * len(cols)]

    def cell(vals, hits):
        return ", ".join(str(v) if h else f"{v}*" for v, h in zip(vals, hits)) or "-"
    for k in sorted(doc["per_string"], key=int):
        r = doc["per_string"][k]
        lines.append(f"| {k} | {r['target']} | {r['paper_table3']} | "
                     + " | ".join(cell(r[LABELS[m]], r[f"{LABELS[m]}_hit"]) for m in methods) + " |")
    means = [f"{doc[f'mean_{LABELS[m]}']:.2f}" if doc.get(f"mean_{LABELS[m]}") is not None else "-" for m in methods]
    lines.append(f"| mean | | {doc['paper_table3_mean']:.2f} | " + " | ".join(means) + " |")
    if doc.get("paired_campaigns"):
        paired = [f"{doc[f'paired_mean_{LABELS[m]}']:.2f}" for m in methods]
        lines.append(f"| mean over the {doc['paired_campaigns']} campaigns both methods finished | | | "
                     + " | ".join(paired) + " |")
    names, by_method = {"paper": "the paper's method", "ours": "ours"}, doc.get("git_commits", {})
    commits = "; ".join(f"{names[m]} at " + ", ".join(c[:7] if len(c) == 40 else c for c in by_method[m])
                        for m in methods if by_method.get(m))
    if commits:
        lines.append(f"\nCode that ran the campaigns: {commits}.")
    total = len(doc["types"]) * len(doc["seeds"]) * len(methods)
    partial = "" if doc["complete"] else f" Partial run: {len(doc['runs'])} of {total} campaigns so far."
    return (f"Executions until the lab's tip hits (cap {CAP}; * = no hit, counted as {CAP}).{partial}\n\n"
            + "\n".join(lines) + "\n")


def run(quick: bool = False, types: list[int] | None = None, seeds: list[int] | None = None,
        methods: list[str] | None = None, work: Path | None = None, cores: int = 2,
        finished_only: bool = False) -> dict:
    """Run the campaigns and write results/bench/loop.json (after every run), loop.png and loop.md.

    ``finished_only``: run nothing; summarize the campaigns ``work`` holds a run.json for
    (``"complete"`` only if that is all of them).

    Raises:
        ValueError: a type outside 1-7, or ``finished_only`` without ``work``."""
    from stringcast.core import load_config
    from stringcast.core.files import write_text

    config = load_config()
    types = types or ([1, 5] if quick else sorted(PAPER_TABLE3))
    seeds = seeds if seeds is not None else ([0] if quick else [0, 1, 2])
    methods = methods or list(METHODS)
    for k in types:
        if k not in PAPER_TARGET:
            raise ValueError(f"string type {k}: the paper's Table 3 covers types 1-7")
    runs: list[dict] = []
    settings = {m: METHODS[m] for m in methods}
    todo = [(k, s, m) for s in seeds for k in types for m in methods]  # seed by seed: a partial run covers every type
    n_all = len(todo)
    if finished_only:
        if not work:
            raise ValueError("finished_only: name the campaigns' folder (--work)")
        todo = [(k, s, m) for k, s, m in todo if (run_dir(Path(work), k, s, m) / "run.json").exists()]
    with tempfile.TemporaryDirectory(prefix="bench_loop_") as tmp:
        work = Path(work).resolve() if work else Path(tmp)
        for i, (k, s, m) in enumerate(todo, 1):
            r = run_one(k, s, m, config, work, cores)
            runs.append(r)
            print(f"  [{i}/{len(todo)}] string {k} seed {s} {m}: "
                  + (f"FAILED {r['error']}" if r["error"] else
                     f"{'hit' if r['hit'] else 'no hit'} after {r['executions']} execution(s), closest "
                     + ", ".join(f"{c:.1f}" for c in r["closest_approach_mm"]) + f" mm; {r['wall_s']:.0f} s"),
                  flush=True)
            doc = header("loop", quick) | summarize(runs, types, methods) | {
                "cap": CAP, "complete": i == n_all, "types": types, "seeds": seeds, "methods": settings,
                "paper_table3": {str(k): v for k, v in PAPER_TABLE3.items()}, "paper_table3_mean_all": 2.14,
                "reference": {"name": "paper_table3", "mean": float(np.mean(list(PAPER_TABLE3.values())))},
                "goals": {"all_hit_ours": True, "max_ours": CAP, "mean_ours": 2.0},
                "lab": "full-size (config/config.yaml as is, plus the method overlay)",
                "runs": runs, "seconds_per_execution_mean": _mean_s(runs),
                "git_commits": {m: sorted({r.get("git_commit") or "unrecorded" for r in runs if r["method"] == m})
                                for m in methods},
                "figure": "loop.png", "table": "loop.md",
            }
            write("loop", doc)
            _figure(doc["per_string"], methods, BENCH_DIR / "loop.png")  # all three agree at every point
            write_text(BENCH_DIR / "loop.md", _table(doc, methods))
    return doc


def _mean_s(runs: list[dict]) -> float | None:
    v = [r["s_per_execution"] for r in runs if r.get("s_per_execution")]
    return float(np.mean(v)) if v else None


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="string types 1 and 5, seed 0, both methods")
    ap.add_argument("--types", type=int, nargs="+", help="string types (default 1-7)")
    ap.add_argument("--seeds", type=int, nargs="+", help="seeds (default 0 1 2)")
    ap.add_argument("--methods", nargs="+", choices=list(METHODS), help="methods (default both)")
    ap.add_argument("--work", type=Path, help="keep (and reuse/resume) the campaigns here")
    ap.add_argument("--cores", type=int, default=2, help="Snakemake --cores per campaign")
    ap.add_argument("--finished-only", action="store_true",
                    help="run nothing: summarize the finished campaigns in --work")
    ap.add_argument("--only", nargs=3, metavar=("TYPE", "SEED", "METHOD"),
                    help="run this one campaign into --work (its run.json; loop.json is left as it is)")
    a = ap.parse_args()
    if a.only:
        if not a.work:
            ap.error("--only needs --work (where the campaign's run.json goes)")
        k, s, m = int(a.only[0]), int(a.only[1]), a.only[2]
        if k not in PAPER_TARGET or m not in METHODS:
            ap.error(f"--only {k} {s} {m}: a type 1-7 and a method of {', '.join(METHODS)}")
        from stringcast.core import load_config

        r = run_one(k, s, m, load_config(), Path(a.work).resolve(), a.cores)
        print(f"string {k} seed {s} {m}: " + (f"FAILED {r['error']}" if r["error"] else
                                               f"{'hit' if r['hit'] else 'no hit'} after {r['executions']}"))
    else:
        run(a.quick, a.types, a.seeds, a.methods, a.work, a.cores, a.finished_only)
