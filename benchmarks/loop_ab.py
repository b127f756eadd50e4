"""Benchmark ``loop_ab``: two loop runs of ours compared campaign by campaign (a candidate change to ours).

Issue 27 asks that a setting of ours be chosen on MuJoCo seeds 0-2 and judged on MuJoCo seeds 3-4
and on every Elastica campaign. This reads the ``run.json`` of two sets of state-mode campaigns
(``benchmarks.loop``'s folders: a base run and a variant run, each ``WORK:METHOD``; the variant may
be a ``VARIANTS`` name or ours run at another commit) and pairs them by physics, string type and
seed. Per physics and split (``choosing``: MuJoCo seeds 0-2; ``judging``: the rest; ``all``):

* mean executions of each side (a campaign without a hit, or failed, counts ``CAP``), the paired
  difference (variant minus base) and its 95 % bootstrap interval, resampled within each string
  type as ``loop.json``'s ``paired_diff_ci95`` is (:func:`benchmarks.loop_summary.bootstrap_ci`);
* first-shot hits of each side, and the campaigns whose first shot changed (miss -> hit, hit -> miss);
* after a first miss: the share that hit at the second execution, and the median next-motion
  prediction error of that step (mm);
* the most executions any campaign took.

The sides' commits, and the settings in which their campaigns' configs differ, are recorded.
``results/bench/loop_ab_<NAME>.json``.

Run: ``python -m benchmarks.loop_ab --base /data/loop:ours --variant /data/loop2:ours --name NAME``
(``--family``: the campaigns on drawn materials instead of the default strings).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import yaml

from benchmarks.common import header, write
from benchmarks.loop import run_dir
from benchmarks.loop_summary import CAP, bootstrap_ci, executions

SPLITS = ("choosing", "judging", "all")


def split_of(physics: str, seed: int) -> str:
    """Issue 27's protocol: MuJoCo seeds 0-2 choose, everything else judges."""
    return "choosing" if physics == "mujoco" and seed <= 2 else "judging"


def load_runs(work: Path, method: str, family: bool = False) -> dict[tuple[str, int, int], dict]:
    """{(physics, type, seed): run.json} of ``work``'s state-mode campaigns of ``method``: on the default
    strings, or with ``family`` on drawn materials (``benchmarks.loop --family``'s ``loop_family_*``).

    Raises:
        FileNotFoundError: no such campaign in ``work``.
    """
    out = {}
    for path in sorted(Path(work).glob(f"loop_*_state_s*_seed*_{method}/run.json")):
        rec = json.loads(path.read_text())
        if path.parent != run_dir(Path(work), rec["string"], rec["seed"], method, rec["physics"], "state", family):
            continue                     # another method whose name ends in this one's, or the other strings
        out[(rec["physics"], int(rec["string"]), int(rec["seed"]))] = rec
    if not out:
        strings = "drawn-material" if family else "default-string"
        raise FileNotFoundError(f"loop_ab: no state-mode {strings} campaigns of method {method!r} under {work}")
    return out


def _flat(doc: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in doc.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def config_difference(base_dir: Path, variant_dir: Path) -> dict:
    """{setting: [base, variant]} where two paired campaigns' ``config/config.yaml`` differ."""
    a, b = (_flat(yaml.safe_load((d / "config" / "config.yaml").read_text()) or {}) for d in (base_dir, variant_dir))
    return {k: [a.get(k), b.get(k)] for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k) and k != "_path"}


def compare(base: dict, variant: dict, keys: list) -> dict:
    """The figures of the module doc over the paired campaigns ``keys``."""
    ex = {s: np.array([executions(runs[k]) for k in keys], float) for s, runs in (("base", base), ("variant", variant))}
    by_type: dict[int, list[float]] = {}
    for k, d in zip(keys, ex["variant"] - ex["base"]):
        by_type.setdefault(k[1], []).append(float(d))
    first = {s: np.array([runs[k]["hit"] and runs[k]["executions"] == 1 for k in keys])
             for s, runs in (("base", base), ("variant", variant))}
    out = {"campaigns": len(keys), "paired_diff_mean": float(np.mean(ex["variant"] - ex["base"])),
           "paired_diff_ci95": bootstrap_ci(by_type),
           "first_shot_changed": {"miss_to_hit": int(np.sum(~first["base"] & first["variant"])),
                                  "hit_to_miss": int(np.sum(first["base"] & ~first["variant"]))}}
    for side, runs in (("base", base), ("variant", variant)):
        missed = [k for k in keys if not (runs[k]["hit"] and runs[k]["executions"] == 1)]
        second = [runs[k] for k in missed if runs[k]["executions"] and runs[k]["executions"] >= 2]
        pred = [r["prediction"][0]["median_mm"] for r in second
                if r.get("prediction") and r["prediction"][0].get("median_mm") is not None]   # None: not judged
        out[side] = {"mean": float(ex[side].mean()), "max": int(ex[side].max()),
                     "first_shot_hits": int(first[side].sum()),
                     "hit_at_second_after_a_miss": [sum(executions(r) == 2 for r in second), len(missed)],
                     "second_step_prediction_error_mm_median": float(np.median(pred)) if pred else None,
                     "executions": {f"{k[0]} s{k[1]} seed{k[2]}": int(e) for k, e in zip(keys, ex[side])}}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", required=True, help="WORK:METHOD of the base run (ours as it is)")
    ap.add_argument("--variant", required=True, help="WORK:METHOD of the candidate run")
    ap.add_argument("--name", required=True, help="results/bench/loop_ab_<NAME>.json")
    ap.add_argument("--family", action="store_true", help="pair the campaigns on drawn materials (loop --family)")
    a = ap.parse_args()
    (bw, bm), (vw, vm) = (s.rsplit(":", 1) for s in (a.base, a.variant))
    base, variant = load_runs(Path(bw), bm, a.family), load_runs(Path(vw), vm, a.family)
    keys = sorted(set(base) & set(variant))
    doc = header("loop_ab", False)
    k0 = keys[0]
    dirs = [run_dir(Path(w), k0[1], k0[2], m, k0[0], "state", a.family) for w, m in ((bw, bm), (vw, vm))]
    doc.update(family=a.family, base={"work": bw, "method": bm, "git_commits": sorted({base[k]["git_commit"] for k in keys})},
               variant={"work": vw, "method": vm, "git_commits": sorted({variant[k]["git_commit"] for k in keys})},
               settings_differ=config_difference(*dirs),
               unpaired={"base": len(set(base) - set(variant)), "variant": len(set(variant) - set(base))},
               cap=CAP, protocol="choosing: MuJoCo seeds 0-2; judging: MuJoCo seeds 3-4 and every Elastica campaign")
    for physics in sorted({k[0] for k in keys}):
        doc[physics] = {}
        for split in SPLITS:
            ks = [k for k in keys if k[0] == physics and split in ("all", split_of(*k[::2]))]
            if ks:
                doc[physics][split] = compare(base, variant, ks)
    ks = [k for k in keys if split_of(k[0], k[2]) == "judging"]
    doc["judging_pooled"] = compare(base, variant, ks) if ks else None
    path = write(f"loop_ab_{a.name}", doc)
    for physics in sorted({k[0] for k in keys}):
        for split, e in doc[physics].items():
            print(f"{physics:9s} {split:9s} n={e['campaigns']:2d}  base {e['base']['mean']:.2f}  variant "
                  f"{e['variant']['mean']:.2f}  diff {e['paired_diff_mean']:+.2f} {e['paired_diff_ci95']}  first hits "
                  f"{e['base']['first_shot_hits']} -> {e['variant']['first_shot_hits']}")
    print(f"-> {path}")


if __name__ == "__main__":
    main()
