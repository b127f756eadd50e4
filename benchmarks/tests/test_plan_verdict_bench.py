"""benchmarks/plan_verdict.py: which plans it takes from loop runs, the rule and verdict of each, a motion
played alike in two runs counted once, and the hit rates with their intervals."""
import json
from pathlib import Path

from benchmarks.plan_verdict import find_plans, summarize, wilson


def _plan(origin, residual_mm=None, hit_predicted=True, failed=False):
    return {"origin": origin, "hit_predicted": hit_predicted, "closest_approach_mm": 4.0,
            "target": {"radius_mm": 20.0}, "planned_on_failed_fit": failed,
            "failed_fit": {"status": "fail", "likely_cause": "model"} if failed else None,
            "residual_correction": None if residual_mm is None else {"median_mm": residual_mm}}


def _run(work: Path, name: str, plans: list[dict], played_mm: list[float]) -> None:
    """A loop run: the first motion and trial k's next motions (plans[0] first), trial k's lab verdict."""
    res, data = work / name / "results" / name, work / name / "data" / name
    for k, doc in enumerate(plans):
        d = res / ("first_motion" if k == 0 else f"trial_{k}")
        d.mkdir(parents=True)
        (d / "motion.json").write_text(json.dumps(doc))
    for k, mm in enumerate(played_mm, 1):
        (data / f"trial_{k}").mkdir(parents=True)
        (data / f"trial_{k}" / "ground_truth.json").write_text(json.dumps({"closest_approach_mm": mm, "hit": mm <= 20}))


def test_plans_are_judged_by_what_they_rest_on(tmp_path):
    plans = [_plan("first"), _plan("wide_perturbation", 35.0), _plan("perturbation", 6.0), _plan("new"),
             _plan("perturbation", 4.0, failed=True)]
    _run(tmp_path, "loop_family_mujoco_state_s2_seed0_ours", plans, [90.0, 40.0, 3.0, 25.0])  # the last never played
    _run(tmp_path, "loop_family_mujoco_state_s2_seed0_ours_mass_floor", plans[:2], [90.0, 41.0])  # trial 1 alike
    _run(tmp_path, "loop_mujoco_state_s1_seed0_paper", [_plan("first")], [5.0])                  # another method
    rows = find_plans([tmp_path], ("ours", "ours_mass_floor"))
    got = [(r["name"].split("seed0_")[1], r["k"], r["rule"], r["status"], r["hit"]) for r in rows]
    assert got == [("ours", 1, "first", "warn", False),
                   ("ours", 2, "large_residual", "warn", False),
                   ("ours", 3, "small_residual", "ok", True),
                   ("ours", 4, "new", "warn", False),
                   ("ours_mass_floor", 2, "large_residual", "warn", False)]   # played otherwise (41 mm): counted
    labs = summarize(rows)
    assert set(labs) == {"all", "mujoco family"}
    assert labs["all"]["status"]["ok"] == {"steps": 1, "hits": 1, "rate": 1.0, "ci95": wilson(1, 1)}
    assert labs["all"]["rule"]["large_residual"]["steps"] == 2 and labs["all"]["status"]["warn"]["hits"] == 0


def test_the_wilson_interval_holds_the_rate_and_narrows_with_steps():
    lo, hi = wilson(9, 10)
    assert lo < 0.9 < hi <= 1.0 and wilson(0, 0) is None
    lo2, hi2 = wilson(90, 100)
    assert lo < lo2 < 0.9 < hi2 < hi
