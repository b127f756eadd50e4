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


def _tip_path(truth_json: Path, end_mm, target=(1200.0, 300.0)) -> None:
    """A lab truth with a tip path (ground_truth.parquet) whose closest approach is ``end_mm`` from the target."""
    import numpy as np
    import pandas as pd
    t = np.linspace(0.0, 2.0, 201)
    ex, ey = end_mm
    across = np.array([-ey, ex]) / np.hypot(ex, ey)             # a straight pass across the way to the target
    x = (target[0] + ex + 400 * (t - 1.0) * across[0]) / 1000   # closest to it at t = 1, at (ex, ey)
    y = (target[1] + ey + 400 * (t - 1.0) * across[1]) / 1000
    tip = pd.DataFrame({"frame": np.arange(len(t)), "t_s": t, "point": 10, "x_m": x, "y_m": y})
    grasp = tip.assign(point=0, x_m=0.0, y_m=0.0)
    truth_json.write_text(json.dumps({"closest_approach_mm": float(np.hypot(ex, ey)), "hit": bool(np.hypot(ex, ey) <= 20),
                                      "target_mm": [target[0], target[1], 20.0], "hit_window_s": [0.5, 1.5]}))
    pd.concat([grasp, tip]).to_parquet(truth_json.with_suffix(".parquet"))


def test_the_realised_step_is_the_share_of_the_way_to_the_target_the_tip_moved(tmp_path):
    from benchmarks.plan_verdict import realised_gain, realised_steps
    plans = [_plan("first"), _plan("perturbation", 25.0), _plan("perturbation", 25.0), _plan("perturbation", 8.0)]
    name = "loop_family_mujoco_state_s2_seed0_ours"
    _run(tmp_path, name, plans, [0, 0, 0, 0])
    data = tmp_path / name / "data" / name
    for k, end in enumerate([(-80.0, 0.0), (-40.0, 0.0), (-30.0, 10.0), (-6.0, 0.0)], 1):
        _tip_path(data / f"trial_{k}" / "ground_truth.json", end)
    rows = find_plans([tmp_path], ("ours",))
    gains = [r["realised_gain"] for r in rows]
    # -80 -> -40 of a planned 80 mm: half the way; -40 -> -30 (10 mm off the way): a quarter;
    # (-30, 10) -> (-6, 0): (24, -10) . (30, -10) / 1000 = 0.82
    assert gains[0] is None and abs(gains[1] - 0.5) < 1e-6 and abs(gains[2] - 0.25) < 1e-6
    assert abs(gains[3] - 0.82) < 1e-6
    steps = realised_steps(rows)
    assert steps["all"]["steps"] == 3 and steps["after_a_missed_perturbation"]["steps"] == 2
    replay = steps["aim_replay"]
    assert replay["as played"] == {"all": 1, "after_a_miss": 1}       # only the last step hit
    # 1 / gain, at most 2: (-40, 0) + 2 (10, 10) = (-20, 20) misses by 28 mm, and (-30, 10) + 2 (24, -10)
    # = (18, -10) by 21 mm: the longer aim loses the hit; 1.25 times: (0, -2.5) hits, (-27.5, 12.5) misses
    assert replay["1 / gain, gain in [0.5, 1]"] == {"all": 0, "after_a_miss": 0}
    assert replay["1.25"] == {"all": 1, "after_a_miss": 1} and replay["steps"] == 3 and replay["after_a_miss"] == 2
    assert realised_gain(None, [1.0, 2.0]) is None and realised_gain([0.0, 0.0], [1.0, 2.0]) is None


def test_the_lab_closest_point_keeps_to_the_hit_window(tmp_path):
    import numpy as np
    from benchmarks.plan_verdict import lab_closest_point
    truth = tmp_path / "ground_truth.json"
    _tip_path(truth, (-30.0, 5.0))
    doc = json.loads(truth.read_text())
    assert lab_closest_point(truth, doc) == __import__("pytest").approx([-30.0, 5.0], abs=1e-6)
    far = lab_closest_point(truth, doc | {"hit_window_s": [1.6, 2.0]})   # the pass at t = 1 is outside it
    assert np.hypot(*far) > 200                                          # 0.6 s further along the pass
    assert lab_closest_point(tmp_path / "none.json", doc) is None
