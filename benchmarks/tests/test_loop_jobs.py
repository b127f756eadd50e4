"""The loop benchmark's campaigns as separate Snakemake jobs (benchmarks/loop.smk): one job per
campaign, then a gather into loop.json with the same summary as the in-process run; and loop.json's
figures (benchmarks/loop_summary.py): per physics, intervals, the paired difference, the video check."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks.loop import Spec, run_dir
from benchmarks.loop_methods import VARIANTS, method_config
from benchmarks.loop_summary import family_into, markdown
from benchmarks.loop_summary import bootstrap_ci, summarize, video_check

ROOT = Path(__file__).resolve().parents[2]


def _record(k: int, seed: int, method: str, executions: int, hit: bool, physics: str = "mujoco",
            mode: str = "state", prediction_mm=(12.0,)) -> dict:
    """A finished campaign's run.json, as benchmarks.loop.run_one writes it."""
    steps = [{"trial": j + 2, "params_trial": j + 1, "median_mm": e, "blew_up": False}
             for j, e in enumerate(prediction_mm[:executions - 1])]
    return {"string": k, "target": 1, "seed": seed, "method": method, "physics": physics, "mode": mode,
            "campaign": f"c{k}{seed}{method}", "git_commit": "test", "libraries": {}, "error": None,
            "executions": executions, "hit": hit, "closest_approach_mm": [50.0] * (executions - 1) + [5.0],
            "E_mm": [20.0] * executions, "wall_s": 1.0, "s_per_execution": 1.0, "timings_s": {},
            "prediction": steps, "prediction_s": 0.1, "state_mode": None}


def _snakemake(tmp_path, *args):
    env = dict(os.environ, STRINGCAST_BENCH_DIR=str(tmp_path / "bench"))
    return subprocess.run([sys.executable, "-m", "snakemake", "-s", str(ROOT / "benchmarks" / "loop.smk"),
                           "--directory", str(tmp_path), "--cores", "2", *args],
                          capture_output=True, text=True, env=env)


def test_one_job_per_campaign_then_one_gather(tmp_path):
    """Per physics: types x seeds x methods in the state mode, and the video check's types x seed 0 x ours."""
    proc = _snakemake(tmp_path, "-n", "--config", f"work={tmp_path / 'w'}", "types=1 5", "seeds=0 1")
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    n = 2 * (2 * 2 * 2 + 2 * 1 * 1)                      # physics x (main + video check)
    assert out.count("rule campaign:") == n and out.count("rule gather:") == 1, out
    assert "loop_elastica_state_s5_seed1_paper/run.json" in out and "loop_mujoco_video_s1_seed0_ours/run.json" in out
    assert "loop_mujoco_video_s1_seed0_paper" not in out                              # the check: ours only
    proc = _snakemake(tmp_path, "-n", "--config", f"work={tmp_path / 'w'}", "types=1", "seeds=0", "physics=mujoco",
                      "mode=video")
    assert proc.returncode == 0 and (proc.stdout + proc.stderr).count("rule campaign:") == 2   # no video check


def test_a_variant_run_ends_with_its_campaigns_and_gathers_nothing(tmp_path):
    """A variant of ours is an A/B left out of loop.json (loop.py refuses its name): the run plans its
    campaigns and no gather, with ours beside it or alone."""
    variant = sorted(VARIANTS)[0]
    for methods in (variant, f"ours {variant}"):
        proc = _snakemake(tmp_path, "-n", "--config", f"work={tmp_path / 'w'}", "types=1", "seeds=0 1",
                          "physics=mujoco", f"methods={methods}", "video_seeds=")
        out = proc.stdout + proc.stderr
        assert proc.returncode == 0, out
        assert out.count("rule campaign:") == 2 * len(methods.split()) and "rule gather" not in out, out
        assert f"loop_mujoco_state_s1_seed1_{variant}/run.json" in out


def test_gather_summarises_the_campaign_jobs_run_json(tmp_path):
    """Campaigns already finished (their run.json) are not run again; the gather writes loop.json
    with the summary benchmarks.loop_summary.summarize gives for the same runs, per physics."""
    work = tmp_path / "w"
    runs = [_record(1, 0, "paper", 3, True), _record(1, 0, "ours", 2, True),
            _record(5, 0, "paper", 8, False), _record(5, 0, "ours", 1, True)]
    video = [_record(1, 0, "ours", 3, True, mode="video"), _record(5, 0, "ours", 1, True, mode="video")]
    for r in runs + video:
        d = run_dir(work, r["string"], r["seed"], r["method"], r["physics"], r["mode"])
        d.mkdir(parents=True)
        (d / "run.json").write_text(json.dumps(r))
    proc = _snakemake(tmp_path, "--config", f"work={work}", "types=1 5", "seeds=0", "physics=mujoco")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "rule campaign" not in proc.stdout + proc.stderr    # nothing re-run
    doc = json.loads((tmp_path / "bench" / "loop.json").read_text())
    expect = summarize(runs, [1, 5], ["paper", "ours"])
    for key in ("mean_ours", "mean_paper_method", "max_ours", "all_hit_ours", "per_string", "mean_ours_ci95",
                "paired_diff_ci95", "prediction_error_mm_ours", "first_shot_hit_rate_ours", "campaigns_per_method"):
        assert doc["mujoco"][key] == expect[key], key
    m = doc["mujoco"]
    assert m["mean_ours"] == pytest.approx(1.5) and m["all_hit_ours"] and doc["complete"] and m["mode"] == "state"
    assert doc["video_check"]["mujoco"]["mean_ours"] == pytest.approx(2.0)
    assert doc["video_check"]["mujoco"]["relative_difference_ours"] == pytest.approx(2.0 / 1.5 - 1)
    assert "elastica" not in doc and doc["physics"] == ["mujoco"] and doc["state_mode"] is not None
    assert "## mujoco (state mode)" in (tmp_path / "bench" / "loop.md").read_text()
    assert (tmp_path / "bench" / "loop.png").stat().st_size > 0


def test_summary_intervals_first_shots_and_predictions():
    """The mean's interval holds the mean; the paired difference's interval is below 0 where ours
    always needs fewer executions; a blown-up prediction sorts last in the median."""
    runs = []
    for k in (1, 2, 3):
        for s in range(5):
            runs += [_record(k, s, "ours", 1 + (s == 0), True, prediction_mm=(5.0,)),
                     _record(k, s, "paper", 3 + s % 2, True, prediction_mm=(20.0, 30.0, 40.0))]
    runs[1]["prediction"][0] = {"trial": 2, "params_trial": 1, "median_mm": None, "blew_up": True}
    out = summarize(runs, [1, 2, 3], ["paper", "ours"])
    assert out["mean_ours"] == pytest.approx(1.2) and out["campaigns_per_method"] == {"paper_method": 15, "ours": 15}
    lo, hi = out["mean_ours_ci95"]
    assert 1.0 <= lo <= 1.2 <= hi <= 1.4 + 1e-9
    assert out["paired_campaigns"] == 15 and out["paired_diff_ci95"][1] < 0
    assert out["first_shot_hit_rate_ours"] == pytest.approx(12 / 15) and out["first_shot_hit_rate_paper_method"] == 0
    assert out["prediction_error_mm_ours"] == 5.0 and out["prediction_steps_ours"] == 3   # 3 campaigns took 2
    paper_steps = [20.0, 30.0] * 9 + [20.0, 30.0, 40.0] * 6
    paper_steps[0] = np.inf
    assert out["prediction_error_mm_paper_method"] == pytest.approx(np.median(paper_steps))
    assert out["failed_ours"] == [] and out["failed_paper_method"] == []
    crashed = dict(runs[0], error="RuntimeError: snakemake failed", executions=None, hit=False)
    out = summarize([crashed] + runs[1:], [1, 2, 3], ["paper", "ours"])
    assert out["failed_ours"] == [[1, 0]] and out["max_ours"] == 8 and not out["all_hit_ours"]
    assert bootstrap_ci({1: [2, 2, 2]}) == [2.0, 2.0] and bootstrap_ci({1: []}) is None
    assert bootstrap_ci({1: [1, 3]}, seed=4) == bootstrap_ci({1: [1, 3]}, seed=4)     # seeded


def test_spec_and_run_config(config):
    spec = Spec(types=(1, 5), seeds=(0, 1), physics=("mujoco",))
    runs = spec.campaigns()
    assert len(runs) == 2 * 2 * 2 + 2 and runs[-1] == ("mujoco", "video", 5, 0, "ours")
    assert len(Spec(mode="video", physics=("mujoco",)).campaigns()) == 7 * 5 * 2
    filmed = [c for c in Spec(video_seeds=(0, 1, 2, 3, 4), video_methods=("paper", "ours"), video_seed_per_type=True,
                              physics=("elastica",)).campaigns() if c[1] == "video"]
    assert [(k, s) for _, _, k, s, m in filmed if m == "ours"] == [(1, 0), (2, 1), (3, 2), (4, 3), (5, 4), (6, 0), (7, 1)]
    assert len(filmed) == 14
    with pytest.raises(ValueError, match="physics bullet"):
        Spec(physics=("bullet",))
    cfg = method_config(config, "ours", 3, "elastica", "state")
    assert cfg["lab"]["physics"] == "elastica" and cfg["lab"]["render"] is False and cfg["estimation"]["seed"] == 3
    assert "render" not in method_config(config, "paper", 0, "mujoco", "video")["lab"]
    assert run_dir(Path("/w"), 5, 1, "ours", "elastica", "state").name == "loop_elastica_state_s5_seed1_ours"


def test_a_family_run_draws_every_material_class_and_joins_loop_json(config, tmp_path):
    """Seeds 0-4 of a family run draw one material of each class; the lab reads it; loop.json keeps its
    other entries and gains ``family`` with the draws and the fits' skill."""
    from stringcast_lab.materials import KINDS, lab_material

    classes = [method_config(config, "ours", s, "mujoco", "state", family=True)["lab"]["material"]["class"]
               for s in range(5)]
    assert sorted(classes) == sorted(KINDS)
    cfg = method_config(config, "paper", 3, "elastica", "state", family=True)
    assert lab_material(cfg["lab"]).kind == classes[3] and "material" not in method_config(config, "paper", 3)["lab"]
    assert run_dir(Path("/w"), 5, 1, "ours", "mujoco", "state", True).name == "loop_family_mujoco_state_s5_seed1_ours"
    runs = [_record(k, s, m, 1 + (m == "paper"), True) | {"material": {"seed": s, "class": KINDS[s]},
                                                           "fit_skill": [0.8, 0.6]}
            for k in (1, 2) for s in (0, 1) for m in ("ours", "paper")]
    spec = Spec(types=(1, 2), seeds=(0, 1), physics=("mujoco",), family=True)
    doc = {"mujoco": summarize(runs, [1, 2], ["paper", "ours"]), "complete": False, "runs": runs,
           "git_commits": {}, "libraries": {}}
    old = tmp_path / "loop.json"
    old.write_text(json.dumps({"mujoco": {"mean_ours": 1.5}, "complete": True}))
    out = family_into(old, doc, spec, {"0": runs[0]["material"]})
    assert out["mujoco"] == {"mean_ours": 1.5} and out["complete"] is True
    fam = out["family"]["mujoco"]
    assert fam["mean_ours"] == 1.0 and fam["mean_paper_method"] == 2.0 and len(fam["draws"]) == 4
    assert fam["fit_skill_ours"] == {"median": pytest.approx(0.7), "p10": pytest.approx(0.6), "fits": 8}
    old.write_text(json.dumps(out))                     # a second engine's family run keeps the first's
    el = [r | {"physics": "elastica"} for r in runs]
    spec_el = Spec(types=(1, 2), seeds=(0, 1), physics=("elastica",), family=True)
    both = family_into(old, {"elastica": summarize(el, [1, 2], ["paper", "ours"]), "complete": True, "runs": el,
                             "git_commits": {}, "libraries": {}}, spec_el, {})
    assert both["family"]["mujoco"] == fam and both["family"]["elastica"]["mean_ours"] == 1.0
    assert len(both["family"]["runs"]) == 16 and "video_check" not in both["family"]
    filmed = {"types": [1, 2], "seeds": [0], "methods": ["paper", "ours"],      # the filmed check, per engine
              "elastica": video_check(el, None, el, [1, 2], ["paper", "ours"])}
    old.write_text(json.dumps(both))
    film = family_into(old, {"elastica": both["family"]["elastica"], "complete": True, "runs": el,
                             "git_commits": {}, "libraries": {}, "video_check": filmed}, spec_el, {})
    assert film["family"]["video_check"]["elastica"]["mean_ours"] == 1.0
    assert film["family"]["video_check"]["elastica"]["relative_difference_ours_same_campaigns"] == 0.0
    assert film["family"]["video_check"]["elastica"]["paired_diffs"] == [[1, 0, -1], [1, 1, -1], [2, 0, -1], [2, 1, -1]]
    assert film["family"]["video_check"]["elastica"]["paired_diff_ci95_pooled"] == [-1.0, -1.0]
    md = markdown({"elastica": both["family"]["elastica"] | {"mode": "state"}, "complete": True, "runs": el, "git_commits": {},
                   "video_check": filmed}, spec_el)
    assert ("pooled over the campaigns, ours minus the paper's: [-1.00, -1.00] (each campaign's: type 1 -1, "
            "type 1 -1, type 2 -1, type 2 -1)") in md


def test_a_variant_is_ours_with_one_setting_changed(config):
    """``ours_no_residual`` is ours without the residual correction, and loop.json's spec refuses it."""
    from dataclasses import replace

    from stringcast.core import settings_from_config

    ours = settings_from_config(method_config(config, "ours", 0, "mujoco", "state"))
    variant = settings_from_config(method_config(config, "ours_no_residual", 0, "mujoco", "state"))
    assert ours.motion.residual_correction is True and variant.motion.residual_correction is False
    assert replace(variant, motion=replace(variant.motion, residual_correction=True)) == ours
    with pytest.raises(ValueError, match="method ours_no_residual"):
        Spec(methods=("ours_no_residual",))


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_every_variant_changes_only_what_it_names(config, name):
    """Each variant resolves to valid settings that differ from ours in exactly the settings it names
    (``ours_isotropic_drag``: the model's drag law; none a no-op)."""
    from dataclasses import fields

    from stringcast.core import settings_from_config

    ours = settings_from_config(method_config(config, "ours", 0, "elastica", "state"))
    variant = settings_from_config(method_config(config, name, 0, "elastica", "state"))
    changed = {(sec.name, key.name) for sec in fields(ours) for key in fields(getattr(ours, sec.name))
               if getattr(getattr(ours, sec.name), key.name) != getattr(getattr(variant, sec.name), key.name)}
    named = {(sec, key) for sec, entries in VARIANTS[name].items() for key in entries}
    assert changed == named


def test_a_lab_that_ran_other_physics_is_refused(tmp_path):
    """A trial whose ground_truth.json does not say it ran the physics asked for (a lab without it
    records none: the MuJoCo chain) stops the campaign, naming the file."""
    from benchmarks.loop import check_physics
    from stringcast.core import DataError

    truth = tmp_path / "ground_truth.json"
    truth.write_text(json.dumps({"hit": False}))
    check_physics(truth, "mujoco")
    with pytest.raises(DataError, match=r"ground_truth\.json: the lab ran 'mujoco' physics, not lab.physics 'elastica'"):
        check_physics(truth, "elastica")
    truth.write_text(json.dumps({"physics": "elastica"}))
    check_physics(truth, "elastica")
