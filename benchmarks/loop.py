"""Benchmark ``loop``: executions until the lab's tip hits, per physics and string type, ours and the paper's method.

For every lab physics (``lab.physics``: ``mujoco``, the MuJoCo chain, and ``elastica``, the
Cosserat rod of issue 27), every string type (1-7) with its paper target (docs/results.md,
"String types": types 1, 2 -> target 1; 3 -> 2; 4, 5, 6 -> 3; 7 -> 4), every seed and every
method, the whole loop runs as a person would run it: :func:`stringcast_lab.campaign.run_campaign`
in a project root of its own (the repo's Snakefile and workflow/ linked, its own
config/config.yaml carrying the method, ``lab.physics`` and the mode), at most ``CAP`` = 8
executions. Whether the tip hit is the *lab's* verdict (``ground_truth.json`` of the last
trial, as the campaign loop reads it to stop); the workflow's stages never read it. The
campaigns run with ``reports=False``: no HTML reports, and the hitting trial is processed only
as far as the prediction error needs (below).

Methods are config overlays (:mod:`benchmarks.loop_methods`): ``paper`` (``config/paper.yaml``, the
paper's method as the paper wrote it) and ``ours`` (the settings' defaults, one set for both physics;
docs/method.md). Variants (``VARIANTS``) are ours with one setting changed, run only by name
(``--only 1 0 ours_no_residual``, or loop.smk's ``methods="ours_no_residual"``) and left out of
loop.json; ``benchmarks.loop_ab`` compares such a run with ours.

A seed ``s`` sets the lab's noise (the campaign's seed: camera noise, joint noise, trigger
error), the pipeline's own searches (``estimation.seed`` and ``motion.seed`` = ``s``) and, in
the state mode, the drawn tracking error, so the seeds differ in both the lab and the method.

Modes (``--mode``; issue 27):

* ``state`` (default): the lab plays each motion without filming it (``lab.render: false``),
  and the benchmark, not the workflow, writes each trial's ``tracks.parquet`` and the
  calibration, sync and tracking verdicts from the lab's true points with the tracking's own
  measured error, dropout and sync error (``tracking.json`` and ``generalization.json`` in
  ``--state-source``, default results/bench/; :mod:`benchmarks.loop_state` says exactly what is
  drawn, and what that leaves out). The workflow then runs only its estimate, plan and predict
  rules, unchanged. Each run's ``state_mode`` and loop.json's say so.
* ``video``: everything filmed, calibrated, synced and tracked, as a campaign on a real camera.
  With ``--mode state``, a video-mode check also runs (``--video-seeds``, default seed 0, every
  type, ``--video-methods``, default ours): loop.json's ``video_check``.

Per run (``run.json``): executions, hit, the lab's closest approach per execution (mm), E per
trial (mm), the next-motion prediction error of every loop step (trial k's estimate predicting
trial k + 1: the workflow's ``prediction.json``, :mod:`stringcast.estimate.prediction`; the
hitting trial is tracked, or synthesized, for it), seconds, the physics and the mode.

loop.json (docs/results.md, "Benchmark records"): one entry per physics, ``"mujoco": {...}``,
``"elastica": {...}`` (:func:`benchmarks.loop_summary.summarize`: ``campaigns_per_method``,
``mean_ours`` with ``mean_ours_ci95``, ``mean_paper_method``, ``paired_diff_ci95`` (ours minus
the paper's method), ``all_hit_ours``, ``max_ours``, ``first_shot_hit_rate_*``,
``prediction_error_mm_*``, ``mode``, ``per_string``), ``video_check`` (the video-mode runs'
entries per physics and their relative difference to the state mode's mean), ``state_mode``
(the error model per type, or null), ``runs``, the goals of issue 27, library versions and
commits. A run without a hit counts as ``cap`` executions in the means (a lower bound).
Figure: results/bench/loop.png (one panel per physics); table: results/bench/loop.md.

The family (issue 52, ``--family``): each seed s also draws the lab's string material
(``lab.material``: seed s, class ``KINDS[s % 5]``, so seeds 0-4 cover thread, cord, rope, elastic cord
and bead chain), the runs are named ``loop_family_...``, and their summary (the same keys, ``draws``)
goes into loop.json's ``family`` entry beside today's (:func:`benchmarks.loop_summary.family_into`)
and loop_family.md. Every run records ``fit_skill`` (each fit's skill, the fit check's share of the
tracked motion explained) and the summary its median and 10th percentile per method. The family's
filmed check (``--video-seeds 0 1 2 3 4 --video-seed-per-type --video-methods paper ours``: type k
filmed with seed (k - 1) mod 5, every class at least once, both methods) is the entry's ``video_check``.

Run: ``python -m benchmarks.loop [--quick] [--physics mujoco elastica] [--mode state|video]
[--types 1 5] [--seeds 0 1 2 3 4] [--methods paper ours] [--video-seeds 0] [--family] [--work DIR]``, one
campaign after another in this process. Default per physics: 7 types x 5 seeds x both methods
(state mode) and 7 types x seed 0 x ours (video check); ``--quick``: types 1 and 5, seed 0.

The campaigns are independent, so they may also run as separate jobs, side by side or on a
cluster, through ``benchmarks/loop.smk`` (Snakemake): one job per campaign (``python -m
benchmarks.loop --only TYPE SEED METHOD --physics P --mode M --work DIR``: its ``run.json``
only), then one that gathers them into loop.json (``--finished-only``)::

    snakemake -s benchmarks/loop.smk --cores 8 --config work=/data/loop seeds="0 1 2 3 4"
    snakemake -s benchmarks/loop.smk --profile config/profiles/slurm --config work=/shared/loop

``--work`` keeps every campaign (``loop_<physics>_<mode>_s<type>_seed<seed>_<method>/``) and its
``run.json``; the same DIR later reuses finished runs and resumes the others; ``--finished-only``
summarizes the finished ones. loop.json, loop.png and loop.md are rewritten after every run
(``"complete": false`` until the last), so a stopped run leaves a consistent partial result.
"""
from __future__ import annotations

import argparse
import dataclasses
import re
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import BENCH_DIR, ROOT, git_commit, library_versions, write
from benchmarks.loop_methods import METHODS, VARIANTS, material_of, method_config
from benchmarks.loop_summary import (CAP, PAPER_TABLE3, PAPER_TARGET, document, family_into, figure, markdown,
                                    prediction_steps)

PHYSICS = ("mujoco", "elastica")
MODES = ("state", "video")
STATE_SOURCE = ROOT / "results" / "bench"
"""Where the state mode's error figures are read (tracking.json, generalization.json) by default."""


@dataclasses.dataclass(frozen=True)
class Spec:
    """What a benchmark run covers: the main runs (physics x types x seeds x methods in ``mode``) and,
    in the state mode, the video check (physics x video_types x video_seeds x video_methods)."""

    types: tuple[int, ...] = tuple(sorted(PAPER_TABLE3))
    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    methods: tuple[str, ...] = tuple(METHODS)
    physics: tuple[str, ...] = PHYSICS
    mode: str = "state"
    video_types: tuple[int, ...] | None = None       # None: the main runs' types
    video_seeds: tuple[int, ...] = (0,)
    video_methods: tuple[str, ...] = ("ours",)
    video_seed_per_type: bool = False
    """The video check films each of its types with one seed, the i-th type's ``video_seeds[i % n]`` (types 1-7
    with seeds 0-4 in a family run: every material class at least once), not every seed."""
    state_source: Path = STATE_SOURCE
    family: bool = False
    """Each seed s also draws the lab's string material (``lab.material``: seed s, class ``KINDS[s % 5]``,
    :func:`material_of`); the runs are named ``loop_family_...`` and summarized under loop.json's ``family``."""

    def __post_init__(self):
        bad = ([f"type {k}" for k in (*self.types, *(self.video_types or ())) if k not in PAPER_TARGET]
               + [f"method {m}" for m in (*self.methods, *self.video_methods) if m not in METHODS]
               + [f"physics {p}" for p in self.physics if p not in PHYSICS]
               + ([f"mode {self.mode}"] if self.mode not in MODES else []))
        if bad:
            raise ValueError(f"loop benchmark: unknown {', '.join(bad)} (types 1-7, methods {list(METHODS)}, "
                             f"physics {list(PHYSICS)}, modes {list(MODES)})")

    def campaigns(self) -> list[tuple[str, str, int, int, str]]:
        """(physics, mode, type, seed, method) of every run, seed by seed within each physics (a
        partial run covers every type), each physics' video check after its main runs."""
        vtypes, vseeds = self.video_types or self.types, self.video_seeds
        filmed = ([(k, vseeds[i % len(vseeds)]) for i, k in enumerate(vtypes)] if self.video_seed_per_type and vseeds
                  else [(k, s) for s in vseeds for k in vtypes])
        out = []
        for p in self.physics:
            out += [(p, self.mode, k, s, m) for s in self.seeds for k in self.types for m in self.methods]
            if self.mode == "state":
                out += [(p, "video", k, s, m) for k, s in filmed for m in self.video_methods]
        return out


def project_root(path: Path, cfg: dict) -> Path:
    """A project root at ``path``: the repo's Snakefile and workflow/ linked, ``cfg`` as
    config/config.yaml (written atomically). Returns the config file's path."""
    from stringcast.core import write_yaml

    (path / "config").mkdir(parents=True, exist_ok=True)
    for name in ("Snakefile", "workflow"):
        link = path / name
        if not link.exists():
            link.symlink_to(ROOT / name)
    cfg_path = path / "config" / "config.yaml"
    write_yaml(cfg_path, cfg)
    return cfg_path


def run_dir(work: Path, string_type: int, seed: int, method: str, physics: str = "mujoco",
            mode: str = "state", family: bool = False) -> Path:
    """The campaign's project folder (and campaign name) under ``work``."""
    return work / f"loop_{'family_' if family else ''}{physics}_{mode}_s{string_type}_seed{seed}_{method}"


RUN_NAME = re.compile(r"^loop_(?P<family>family_)?(?P<physics>[a-z]+)_(?P<mode>state|video)_s(?P<type>\d+)"
                      r"_seed(?P<seed>\d+)_(?P<method>[a-z_]+)$")
"""A campaign folder's name as :func:`run_dir` makes it (groups family, physics, mode, type, seed, method)."""


def check_physics(truth_json: Path, physics: str) -> None:
    """Refuse a trial the lab played with another physics than ``physics`` (``ground_truth.json``'s
    ``physics``; a lab that does not record it ran the MuJoCo chain).

    Raises:
        DataError: naming the file and both physics.
    """
    from stringcast.core import DataError, read_json

    ran = read_json(truth_json).get("physics", "mujoco")
    if ran != physics:
        raise DataError(f"{truth_json}: the lab ran {ran!r} physics, not lab.physics {physics!r}: does this "
                        f"checkout's lab implement {physics!r} (and record it in ground_truth.json's \"physics\")?")


def _trial_hook(physics: str, mode: str, cfg: dict, model, seed: int, records: list):
    """run_campaign's ``before_processing``: check the lab's physics; in the state mode write the
    trial's tracked files (:func:`benchmarks.loop_state.synthesize_trial`), its record into ``records``."""
    from benchmarks.loop_state import synthesize_trial
    from stringcast.core import load_campaign, settings_from_config

    tracking = settings_from_config(cfg).tracking

    def hook(k: int, trial_dir: Path, results_dir: Path) -> None:
        check_physics(Path(trial_dir) / "ground_truth.json", physics)
        if mode == "state":
            campaign = load_campaign(Path(trial_dir).parent / "campaign.yaml", cfg)
            records.append(synthesize_trial(k, trial_dir, results_dir, campaign, model, seed, tracking))
    return hook


def predictions(root: Path, name: str, n: int, cores: int, workflow_args, hook) -> tuple[list[dict], float]:
    """Every loop step's next-motion prediction error of a finished campaign of ``n`` executions: the
    workflow's ``prediction.json`` of trials 2..n (the hitting trial tracked first, or in the state
    mode synthesized by ``hook``). Returns (one dict per step, seconds); a step whose job failed
    has ``error``."""
    from stringcast_lab.campaign import run_workflow
    from stringcast.core import read_json

    if n < 2:
        return [], 0.0
    t0 = time.perf_counter()
    res = root / "results" / name
    if not (res / f"trial_{n}" / "tracks.parquet").exists():
        hook(n, root / "data" / name / f"trial_{n}", res / f"trial_{n}")
    failure = None
    try:
        run_workflow(root, [f"results/{name}/trial_{k}/prediction.json" for k in range(2, n + 1)], cores, [],
                     f"campaign {name}, predictions", [*workflow_args, "--keep-going"])
    except RuntimeError as exc:   # the steps that did finish still count
        failure = str(exc).splitlines()[0]
    for cache in ("frames.npy", "frames.json"):
        (res / f"trial_{n}" / cache).unlink(missing_ok=True)
    keys = ("median_mm", "p95_mm", "max_mm", "frames", "valid_frames", "valid_share", "blew_up",
            "tracked_closest_approach_mm")
    steps = []
    for k in range(2, n + 1):
        p = res / f"trial_{k}" / "prediction.json"
        doc = read_json(p) if p.exists() else None
        steps.append({"trial": k, "params_trial": k - 1} | (
            {key: doc.get(key) for key in keys} | {"verdict": doc["verdict"]["status"]} if doc
            else {"error": failure or f"{p}: not made"}))
    return steps, time.perf_counter() - t0


def run_one(string_type: int, seed: int, method: str, config: dict, work: Path, cores: int = 2,
            physics: str = "mujoco", mode: str = "state", state_source: Path = STATE_SOURCE,
            family: bool = False) -> dict:
    """One campaign: string ``string_type`` at its paper target, ``method``, ``seed``, ``physics`` and
    ``mode``, at most ``CAP`` executions. Reuses ``run_dir(...)/run.json`` when a previous run finished.

    Returns a dict: the run's identity; executions, hit, closest_approach_mm (per execution, lab
    truth), E_mm (per trial, params.json), prediction (per loop step) and prediction_error_mm
    (their median), wall_s (the campaign), prediction_s, s_per_execution, timings_s, state_mode
    (the error model and each trial's draw; None in the video mode), git_commit and libraries,
    error (None, or the failure).

    Raises:
        DataError: (state mode) the error model's files are missing (before anything runs).
    """
    from benchmarks.loop_state import WORKFLOW_ARGS, error_model
    from stringcast_lab.campaign import run_campaign
    from stringcast.core import DataError, read_json, write_json

    root = run_dir(work, string_type, seed, method, physics, mode, family)
    name, done = root.name, root / "run.json"
    if done.exists():
        return read_json(done)
    model = error_model(string_type, state_source) if mode == "state" else None
    cfg = method_config(config, method, seed, physics, mode, family)
    cfg_path = project_root(root, cfg)
    records: list[dict] = []
    hook = _trial_hook(physics, mode, cfg, model, seed, records)
    args = WORKFLOW_ARGS if mode == "state" else ()
    rec = {"string": string_type, "target": PAPER_TARGET[string_type], "seed": seed, "method": method,
           "physics": physics, "mode": mode, "campaign": name, "git_commit": git_commit(),
           "material": cfg["lab"].get("material"), "fit_skill": [],
           "libraries": library_versions(), "error": None,
           "state_mode": None if model is None else {"error_model": model.as_dict(), "trials": records}}
    t0 = time.perf_counter()
    try:
        summary = run_campaign(name, str(string_type), str(PAPER_TARGET[string_type]), config_path=str(cfg_path),
                               max_executions=CAP, cores=cores, seed=seed, root=root, reports=False,
                               keep_frames=False, before_processing=hook, workflow_args=args)
        rec["wall_s"] = time.perf_counter() - t0
        for t in summary["trials"]:
            check_physics(root / "data" / name / f"trial_{t['trial']}" / "ground_truth.json", physics)
        rec["prediction"], rec["prediction_s"] = predictions(root, name, len(summary["trials"]), cores, args, hook)
    except (RuntimeError, DataError) as exc:  # a failed workflow step or trial is a result, not the end
        rec.update(executions=None, hit=False, closest_approach_mm=[], E_mm=[], timings_s={}, prediction=[],
                   prediction_error_mm=None, wall_s=time.perf_counter() - t0, s_per_execution=None,
                   error=f"{type(exc).__name__}: {exc}")
        write_json(done, rec)
        return rec
    trials = summary["trials"]
    rec["executions"], rec["hit"] = len(trials), bool(trials[-1]["hit"])   # the lab's verdict on the last
    rec["closest_approach_mm"] = [float(t["closest_approach_mm"]) for t in trials]
    rec["E_mm"] = []
    for t in trials:
        p = root / "results" / name / f"trial_{t['trial']}" / "params.json"
        doc = read_json(p) if p.exists() else {}
        e, skill = doc.get("E_mm"), (doc.get("fit_check") or {}).get("skill")
        rec["E_mm"].append(None if e is None else float(e))
        rec["fit_skill"].append(None if skill is None else float(skill))
    steps = prediction_steps(rec)
    rec["prediction_error_mm"] = float(np.median(steps)) if steps else None
    rec["timings_s"] = summary["timings_s"]
    per_exec = [v for k, v in summary["timings_s"].items() if k.startswith(("execute_", "process_"))]
    rec["s_per_execution"] = float(sum(per_exec) / len(trials)) if per_exec else None
    write_json(done, rec)
    return rec


def run(quick: bool = False, spec: Spec | None = None, work: Path | None = None, cores: int = 2,
        finished_only: bool = False) -> dict:
    """Run ``spec``'s campaigns and write results/bench/loop.json (after every run), loop.png and loop.md.

    ``spec`` None: the default (``quick``: types 1 and 5, seed 0), as ``benchmarks.run`` calls it.

    ``finished_only``: run nothing; summarize the campaigns ``work`` holds a run.json for
    (``"complete"`` only if that is all of them).

    Raises:
        ValueError: ``finished_only`` without ``work``.
        DataError: (state mode) the error model's files are missing.
    """
    from stringcast.core import load_config
    from stringcast.core import write_text

    config = load_config()
    spec = spec or (Spec(types=(1, 5), seeds=(0,)) if quick else Spec())
    todo = spec.campaigns()
    n_all = len(todo)
    if finished_only:
        if not work:
            raise ValueError("finished_only: name the campaigns' folder (--work)")
        todo = [c for c in todo
                if (run_dir(Path(work), c[2], c[3], c[4], c[0], c[1], spec.family) / "run.json").exists()]
    runs: list[dict] = []
    doc = document(runs, spec, False, quick, METHODS)
    with tempfile.TemporaryDirectory(prefix="bench_loop_") as tmp:
        work = Path(work).resolve() if work else Path(tmp)
        for i, (p, mode, k, s, m) in enumerate(todo, 1):
            r = run_one(k, s, m, config, work, cores, p, mode, spec.state_source, spec.family)
            runs.append(r)
            print(f"  [{i}/{len(todo)}] {p} {mode} string {k} seed {s} {m}: "
                  + (f"FAILED {r['error']}" if r["error"] else
                     f"{'hit' if r['hit'] else 'no hit'} after {r['executions']} execution(s), closest "
                     + ", ".join(f"{c:.1f}" for c in r["closest_approach_mm"]) + f" mm; {r['wall_s']:.0f} s"),
                  flush=True)
            doc = document(runs, spec, i == n_all, quick, METHODS)
            if spec.family:    # beside today's entries in loop.json, and its own table
                materials = {str(s): material_of(s) for s in spec.seeds}
                write("loop", family_into(BENCH_DIR / "loop.json", doc, spec, materials))
                write_text(BENCH_DIR / "loop_family.md", markdown(doc, spec))
                continue
            write("loop", doc)
            figure({q: doc[q] for q in spec.physics}, list(spec.methods), BENCH_DIR / "loop.png")
            write_text(BENCH_DIR / "loop.md", markdown(doc, spec))   # all three agree at every point
    return doc


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="string types 1 and 5, seed 0")
    ap.add_argument("--types", type=int, nargs="+", help="string types (default 1-7)")
    ap.add_argument("--seeds", type=int, nargs="+", help="seeds (default 0 1 2 3 4)")
    ap.add_argument("--methods", nargs="+", choices=list(METHODS), help="methods (default both)")
    ap.add_argument("--physics", nargs="+", choices=PHYSICS, default=list(PHYSICS), help="lab physics")
    ap.add_argument("--mode", choices=MODES, default="state", help="state: no video, the tracking's measured "
                    "error drawn on the lab's truth; video: filmed and tracked")
    ap.add_argument("--video-seeds", type=int, nargs="*", default=[0],
                    help="state mode: the video check's seeds (none: no check)")
    ap.add_argument("--video-types", type=int, nargs="+", help="the video check's types (default: --types)")
    ap.add_argument("--video-methods", nargs="+", choices=list(METHODS), default=["ours"],
                    help="the video check's methods")
    ap.add_argument("--video-seed-per-type", action="store_true",
                    help="the video check films its i-th type with the (i mod n)-th of --video-seeds only")
    ap.add_argument("--state-source", type=Path, default=STATE_SOURCE,
                    help="folder holding tracking.json and generalization.json (the state mode's error)")
    ap.add_argument("--family", action="store_true", help="each seed also draws the lab's string material "
                    "(lab.material); summarized as loop.json's family entry")
    ap.add_argument("--work", type=Path, help="keep (and reuse/resume) the campaigns here")
    ap.add_argument("--cores", type=int, default=2, help="Snakemake --cores per campaign")
    ap.add_argument("--finished-only", action="store_true",
                    help="run nothing: summarize the finished campaigns in --work")
    ap.add_argument("--only", nargs=3, metavar=("TYPE", "SEED", "METHOD"),
                    help="run this one campaign (of each --physics, in --mode) into --work (its run.json; "
                         "loop.json is left as it is)")
    return ap


def main(argv: list[str] | None = None) -> None:
    ap = _parser()
    a = ap.parse_args(argv)
    quick_types, quick_seeds = ([1, 5], [0]) if a.quick else (None, None)
    try:
        spec = Spec(types=tuple(a.types or quick_types or sorted(PAPER_TABLE3)),
                    seeds=tuple(a.seeds if a.seeds is not None else quick_seeds or (0, 1, 2, 3, 4)),
                    methods=tuple(a.methods or METHODS), physics=tuple(a.physics), mode=a.mode,
                    video_types=tuple(a.video_types) if a.video_types else None, video_seeds=tuple(a.video_seeds),
                    video_methods=tuple(a.video_methods), video_seed_per_type=a.video_seed_per_type,
                    state_source=a.state_source.resolve(), family=a.family)
    except ValueError as exc:
        ap.error(str(exc))
    if not a.only:
        run(a.quick, spec, a.work, a.cores, a.finished_only)
        return
    if not a.work:
        ap.error("--only needs --work (where the campaign's run.json goes)")
    k, s, m = int(a.only[0]), int(a.only[1]), a.only[2]
    if k not in PAPER_TARGET or (m not in METHODS and m not in VARIANTS):
        ap.error(f"--only {k} {s} {m}: a type 1-7 and a method of {', '.join([*METHODS, *VARIANTS])}")
    from stringcast.core import load_config

    for p in spec.physics:
        r = run_one(k, s, m, load_config(), Path(a.work).resolve(), a.cores, p, a.mode, spec.state_source, a.family)
        print(f"{p} {a.mode} string {k} seed {s} {m}: " + (f"FAILED {r['error']}" if r["error"] else
                                                            f"{'hit' if r['hit'] else 'no hit'} after {r['executions']}"))


if __name__ == "__main__":
    main()
