"""benchmarks.loop_ab: two loop runs paired campaign by campaign, on run.json files made here."""
import json

import pytest
import yaml

from benchmarks.loop_ab import compare, config_difference, load_runs, split_of


def _campaign(work, physics, k, seed, method, misses, motion=None, family=False):
    """A finished campaign folder: its run.json (lab misses per execution, mm) and its config."""
    d = work / f"loop_{'family_' if family else ''}{physics}_state_s{k}_seed{seed}_{method}"
    (d / "config").mkdir(parents=True)
    hit = misses[-1] <= 20.0
    rec = {"physics": physics, "string": k, "seed": seed, "method": method, "git_commit": "abc",
           "executions": len(misses), "hit": hit, "closest_approach_mm": misses,
           "prediction": [{"median_mm": 10.0 * (i + 1)} for i in range(len(misses) - 1)]}
    (d / "run.json").write_text(json.dumps(rec))
    (d / "config" / "config.yaml").write_text(yaml.safe_dump({"motion": {"seed": seed, **(motion or {})}}))
    return d


def test_two_runs_paired_by_physics_type_and_seed(tmp_path):
    base, var = tmp_path / "a", tmp_path / "b"
    #                      type 1: base 1 / variant 2 executions; type 2: base 3 / variant 1
    _campaign(base, "mujoco", 1, 0, "ours", [5.0])
    _campaign(var, "mujoco", 1, 0, "ours", [30.0, 4.0], {"replan_miss_mm": 30.0})
    _campaign(base, "mujoco", 2, 3, "ours", [50.0, 25.0, 3.0])
    _campaign(var, "mujoco", 2, 3, "ours", [9.0], {"replan_miss_mm": 30.0})
    _campaign(base, "mujoco", 2, 3, "ours_other", [9.0])          # another method: not read
    _campaign(base, "elastica", 1, 0, "ours", [40.0] * 8)          # no hit in 8: counts CAP
    _campaign(var, "elastica", 1, 0, "ours", [40.0, 10.0])
    a, b = load_runs(base, "ours"), load_runs(var, "ours")
    assert set(a) == set(b) == {("mujoco", 1, 0), ("mujoco", 2, 3), ("elastica", 1, 0)}
    assert config_difference(base / "loop_mujoco_state_s1_seed0_ours", var / "loop_mujoco_state_s1_seed0_ours") == \
        {"motion.replan_miss_mm": [None, 30.0]}
    assert [split_of("mujoco", 2), split_of("mujoco", 3), split_of("elastica", 0)] == ["choosing", "judging", "judging"]

    m = compare(a, b, [("mujoco", 1, 0), ("mujoco", 2, 3)])
    assert m["base"]["mean"] == 2.0 and m["variant"]["mean"] == 1.5 and m["paired_diff_mean"] == -0.5
    assert m["first_shot_changed"] == {"miss_to_hit": 1, "hit_to_miss": 1}
    assert m["base"]["first_shot_hits"] == m["variant"]["first_shot_hits"] == 1
    assert m["base"]["hit_at_second_after_a_miss"] == [0, 1] and m["variant"]["hit_at_second_after_a_miss"] == [1, 1]
    assert m["base"]["second_step_prediction_error_mm_median"] == 10.0
    # one campaign per type: the type-stratified interval is the mean itself
    assert m["paired_diff_ci95"] == pytest.approx([-0.5, -0.5])
    e = compare(a, b, [("elastica", 1, 0)])
    assert e["variant"]["second_step_prediction_error_mm_median"] == 10.0
    b[("elastica", 1, 0)]["prediction"][0]["median_mm"] = None      # a prediction not judged: left out
    assert compare(a, b, [("elastica", 1, 0)])["variant"]["second_step_prediction_error_mm_median"] is None
    assert e["base"]["mean"] == 8 and e["base"]["max"] == 8 and e["paired_diff_mean"] == -6
    with pytest.raises(FileNotFoundError, match="no state-mode default-string campaigns of method 'paper'"):
        load_runs(base, "paper")


def test_drawn_material_campaigns_pair_apart_from_the_default_strings(tmp_path):
    """``--family``'s campaigns (``loop_family_*``) are read only when asked for, and the default
    strings' only when not: the same (physics, type, seed) names two different strings."""
    _campaign(tmp_path, "mujoco", 7, 7, "ours", [5.0])
    _campaign(tmp_path, "mujoco", 7, 7, "ours", [40.0, 30.0, 3.0], family=True)
    _campaign(tmp_path, "mujoco", 2, 6, "ours", [30.0, 2.0], family=True)
    default, drawn = load_runs(tmp_path, "ours"), load_runs(tmp_path, "ours", family=True)
    assert set(default) == {("mujoco", 7, 7)} and set(drawn) == {("mujoco", 7, 7), ("mujoco", 2, 6)}
    assert default[("mujoco", 7, 7)]["executions"] == 1 and drawn[("mujoco", 7, 7)]["executions"] == 3
    with pytest.raises(FileNotFoundError, match="drawn-material campaigns of method 'paper'"):
        load_runs(tmp_path, "paper", family=True)
