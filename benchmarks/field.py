"""Benchmark ``field``: the pipeline, method ours, on recordings from a lab nobody here built (issue 52).

Every campaign under ``--field`` (default ``../shared/field``: a folder per campaign, laid out as the
data contract asks, and ``lab.yaml`` beside them describing that lab's arm, camera and board) is run
by the project's own workflow, with ``config/config.yaml`` and that ``lab.yaml`` (ours: the settings' defaults),
up to every trial's fit and next motion. No ground truth is read: a field recording has none.

Per trial, from the pipeline's own files: the fit's skill (the share of the tracked motion it
explains over a string carried rigidly by the hand, ``params.json``'s ``fit_check``), its median
point error in mm and as a share of the string's length, E (eq. 6, ours' weighting), the fitted
coefficients and masses, the fit's likely cause and reasons, the tracked string's inertial response
(:mod:`stringcast.estimate.inertia`: its share of a pendulum's tilt under the grasp's acceleration), and
each stage's verdict (status and first reason).
``results/bench/field.json`` holds them with the library versions.

The work folder (``--work``, default a temporary one) is a Snakemake project whose ``data/<c>`` link
to the campaigns (read-only: the workflow never writes into data/) and whose ``results/`` keeps every
product, so a second run with the same ``--work`` reuses what is up to date.

Run: ``python -m benchmarks.field [--field DIR] [--work DIR] [--cores 2]``.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.common import ROOT, header, write

STAGE_FILES = (("calibration", "calibration.json"), ("sync", "sync.json"), ("clock", "clock.json"),
               ("geometry", "geometry.json"), ("tracking", "tracking.json"), ("fit", "params.json"),
               ("plan", "motion.json"))


def field_campaigns(field: Path) -> list[Path]:
    """The campaign folders under ``field`` (those with a ``campaign.yaml``), sorted by name."""
    return sorted(p for p in field.iterdir() if (p / "campaign.yaml").is_file())


def make_project(work: Path, field: Path) -> list[str]:
    """Lay out a Snakemake project in ``work`` (the repository's Snakefile, workflow and config linked,
    ``data/<c>`` linked to each field campaign); returns the campaign names."""
    work.mkdir(parents=True, exist_ok=True)
    for name in ("Snakefile", "workflow", "config"):
        link = work / name
        if not link.exists():
            link.symlink_to(ROOT / name)
    (work / "data").mkdir(exist_ok=True)
    names = []
    for c in field_campaigns(field):
        link = work / "data" / c.name
        if not link.exists():
            link.symlink_to(c.resolve())
        names.append(c.name)
    return names


def trial_figures(res: Path) -> dict:
    """One trial's figures from its results folder (module doc)."""
    out: dict = {"verdicts": {}}
    for stage, name in STAGE_FILES:
        path = res / name
        if not path.is_file():
            out["verdicts"][stage] = None
            continue
        v = json.loads(path.read_text()).get("verdict") or {}
        reasons = v.get("reasons") or []
        out["verdicts"][stage] = {"status": v.get("status"), "first_reason": reasons[0] if reasons else None}
    params = res / "params.json"
    if params.is_file():
        p = json.loads(params.read_text())
        fig = p.get("fit_check") or {}
        out.update(skill=fig.get("skill"), error_median_mm=fig.get("error_median_mm"),
                   error_share=fig.get("error_share"), tip_error_median_mm=fig.get("tip_error_median_mm"),
                   null_error_median_mm=fig.get("null_error_median_mm"), E_mm=p.get("E_mm"),
                   likely_cause=(p.get("verdict") or {}).get("likely_cause"),
                   fit_reasons=(p.get("verdict") or {}).get("reasons"),
                   inertia={k: fig.get(k) for k in ("inertia_share", "rotation_coupling", "swing_period_s",
                                                    "inertia_points")},
                   coefficients=p.get("coefficients"), mu_groups=p.get("mu_groups"))
    return out


def run(field: Path, work: Path, cores: int) -> dict:
    """Run the workflow on every field campaign's trials and collect :func:`trial_figures`."""
    names = make_project(work, field)
    lab_yaml = field / "lab.yaml"
    configs = [str(lab_yaml)] if lab_yaml.is_file() else []
    targets = []
    for name in names:
        for trial in sorted((field / name).glob("trial_*")):
            targets.append(f"results/{name}/{trial.name}/motion.csv")
    t0 = time.perf_counter()
    cmd = [sys.executable, "-m", "snakemake", "--cores", str(cores), "--directory", str(work),
           *(("--configfile", *configs) if configs else ()), "--keep-going", *targets]
    proc = subprocess.run(cmd, cwd=work, text=True, capture_output=True)
    trials = {}
    for tgt in targets:
        res = work / Path(tgt).parent
        trials[str(Path(tgt).parent.relative_to("results"))] = trial_figures(res)
    return {"campaigns": names, "trials": trials, "workflow_exit_status": proc.returncode,
            "workflow_tail": proc.stdout[-2000:] + proc.stderr[-2000:] if proc.returncode else "",
            "seconds": time.perf_counter() - t0, "method": "ours (the settings' defaults)",
            "configs": ["config/config.yaml", *configs]}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--field", type=Path, default=ROOT.parent / "shared" / "field", help="the field recordings")
    p.add_argument("--work", type=Path, default=None, help="keep (and reuse) the project and its results here")
    p.add_argument("--cores", type=int, default=2)
    a = p.parse_args(argv)
    if not a.field.is_dir() or not field_campaigns(a.field):
        print(f"field: no campaign (a folder with campaign.yaml) under {a.field}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="stringcast-field-") as tmp:
        doc = {**header("field", False), **run(a.field, a.work or Path(tmp), a.cores)}
    path = write("field", doc)
    for name, t in doc["trials"].items():
        skill = t.get("skill")
        fit = (t["verdicts"].get("fit") or {}).get("status")
        print(f"{name}: skill {skill if skill is None else round(skill, 2)}, median error "
              f"{t.get('error_median_mm') or float('nan'):.1f} mm, fit {fit} (likely cause: {t.get('likely_cause')})")
    if doc["workflow_exit_status"]:
        print(f"the workflow ended with exit status {doc['workflow_exit_status']}:\n{doc['workflow_tail']}",
              file=sys.stderr)
    print(f"-> {path}")
    return 0 if doc["workflow_exit_status"] == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
