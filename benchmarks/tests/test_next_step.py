"""benchmarks/next_step.py: which steps it takes from loop runs, how it judges a re-planned step (the
played verdict for the played motion, the lab for a changed one), and its summary."""
import json
import shutil
from pathlib import Path

import pytest
import yaml

import stringcast.api as api
from benchmarks.next_step import find_steps, replan_step, summarize

ROOT = Path(__file__).resolve().parents[2]


def _run(work: Path, name: str, origins: list[str], verdicts: dict[int, tuple[float, bool]]) -> Path:
    """A loop run's files: trial k's next motion (origin origins[k - 1]) and the lab's verdict on trial k."""
    run = work / name
    (run / "config").mkdir(parents=True)
    shutil.copy(ROOT / "config" / "config.yaml", run / "config" / "config.yaml")
    data = run / "data" / name
    data.mkdir(parents=True)
    (data / "campaign.yaml").write_text(yaml.safe_dump({"string": "1", "target": "1", "setup": "default", "seed": 3}))
    for k, origin in enumerate(origins, 1):
        res = run / "results" / name / f"trial_{k}"
        res.mkdir(parents=True)
        (res / "motion.json").write_text(json.dumps({"origin": origin, "target": {"radius_mm": 20.0}}))
    for k, (mm, hit) in verdicts.items():
        (data / f"trial_{k}").mkdir(parents=True)
        (data / f"trial_{k}" / "ground_truth.json").write_text(json.dumps({"closest_approach_mm": mm, "hit": hit}))
        (data / f"trial_{k}" / "motion.csv").write_text(f"t_s,q1_rad\n0,{k}\n")
    return run


def test_steps_are_the_methods_next_motions_with_a_verdict(tmp_path):
    _run(tmp_path, "loop_family_mujoco_state_s7_seed3_ours", ["wide_perturbation", "perturbation", "new"],
         {1: (80.0, False), 2: (30.0, False), 3: (4.0, True)})             # trial 3's next motion never played
    _run(tmp_path, "loop_mujoco_state_s7_seed3_paper", ["perturbation"], {2: (1.0, True)})   # another method
    (tmp_path / "loop_notes").mkdir()                                         # not a run
    steps = find_steps([tmp_path], "ours", ("perturbation", "wide_perturbation", "new"))
    assert [(s["k"], s["origin"], s["played_mm"], s["played_hit"]) for s in steps] == \
        [(1, "wide_perturbation", 30.0, False), (2, "perturbation", 4.0, True)]
    assert steps[0]["physics"] == "mujoco" and steps[0]["family"] and steps[0]["radius_mm"] == 20.0
    assert [s["k"] for s in find_steps([tmp_path], "ours", ("perturbation",))] == [2]
    assert [s["name"] for s in find_steps([tmp_path], "paper", ("perturbation",))] == ["loop_mujoco_state_s7_seed3_paper"]


def test_a_replanned_step_is_judged_by_the_played_verdict_or_the_lab(tmp_path, monkeypatch):
    """Re-planned to the played motion: the loop's verdict, nothing played; to another: the lab plays it
    with the loop's executor seed (campaign seed x 1000 + k + 1), and its verdict counts."""
    run = _run(tmp_path / "work", "loop_elastica_state_s1_seed3_ours", ["perturbation"], {2: (30.0, False)})
    played = (run / "data" / run.name / "trial_2" / "motion.csv").read_text()
    replanned, plays = {"csv": played}, []

    def fake_plan(params, played_json, campaign, out_csv, out_json, seed, tracks, joints, *, model, motion):
        assert seed == 1 and Path(tracks).name == "tracks.parquet" and Path(joints).name == "joints.csv"
        assert model.dt_s == 5e-5 and motion.planner == "robust"              # the overlay merged over the run's
        Path(out_csv).write_text(replanned["csv"])
        return type("Plan", (), {"d_min": 0.002})()

    def fake_execute(csv, backend, out, campaign, executor, cfg, seed):
        plays.append(seed)
        Path(out).mkdir(parents=True)
        (Path(out) / "ground_truth.json").write_text(json.dumps({"closest_approach_mm": 6.0, "hit": True}))

    monkeypatch.setattr(api, "run_plan", fake_plan, raising=False)
    monkeypatch.setattr(api, "execute", fake_execute, raising=False)
    step, = find_steps([tmp_path / "work"], "ours", ("perturbation",))
    overlay = {"model": {"dt_s": 5e-5}}
    same = replan_step((step, overlay, str(tmp_path / "out")))
    assert not same["changed"] and same["variant_mm"] == 30.0 and not same["variant_hit"] and plays == []
    replanned["csv"] = played.replace(",2", ",2.5")
    other = replan_step((step, overlay, str(tmp_path / "out2")))
    assert other["changed"] and other["variant_mm"] == 6.0 and other["variant_hit"] and plays == [3002]
    assert other["predicted_mm"] == pytest.approx(2.0)


def test_summary_counts_gains_and_losses_per_lab_and_origin():
    rows = [{"physics": "mujoco", "family": False, "origin": "perturbation", "played_hit": True, "variant_hit": False,
             "changed": True, "played_mm": 5.0, "variant_mm": 25.0},
            {"physics": "mujoco", "family": False, "origin": "new", "played_hit": False, "variant_hit": True,
             "changed": True, "played_mm": 40.0, "variant_mm": 3.0},
            {"physics": "elastica", "family": True, "origin": "perturbation", "played_hit": True, "variant_hit": True,
             "changed": False, "played_mm": 2.0, "variant_mm": 2.0}]
    s = summarize(rows)
    assert s["all"]["all"] == {"steps": 3, "played_hits": 2, "variant_hits": 2, "gained": 1, "lost": 1,
                                    "changed": 2, "played_mm_median": 5.0, "variant_mm_median": 3.0}
    assert s["all"]["perturbation"]["lost"] == 1 and s["all"]["new"]["gained"] == 1
    assert set(s) == {"all", "mujoco default", "elastica family"} and "new" not in s["elastica family"]
