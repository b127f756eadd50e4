"""benchmarks/loop_prediction.py: which campaigns it takes, what each variant sets, and its summary."""
from pathlib import Path

import pytest
import yaml

from benchmarks.loop_prediction import campaigns, summarize, variants

ROOT = Path(__file__).resolve().parents[2]


def _campaign(work: Path, name: str, trials: int) -> None:
    for k in range(1, trials + 1):
        d = work / name / "results" / name / f"trial_{k}"
        d.mkdir(parents=True)
        (d / "tracks.parquet").write_bytes(b"")


def test_only_paper_campaigns_with_a_second_trial_of_the_asked_physics_and_seeds(tmp_path):
    _campaign(tmp_path, "loop_mujoco_state_s3_seed1_paper", 2)
    _campaign(tmp_path, "loop_mujoco_state_s4_seed1_paper", 1)      # hit first: nothing to predict
    _campaign(tmp_path, "loop_mujoco_state_s3_seed1_ours", 2)       # ours' motions: not the common test
    _campaign(tmp_path, "loop_elastica_video_s2_seed0_paper", 3)
    _campaign(tmp_path, "loop_mujoco_state_s5_seed4_paper", 2)
    found = campaigns(tmp_path, ["mujoco", "elastica"], [0, 1])
    assert [(c.name, p, t, s, k) for c, p, t, s, k in found] == [
        ("loop_elastica_video_s2_seed0_paper", "elastica", 2, 0, 1), ("loop_mujoco_state_s3_seed1_paper", "mujoco", 3, 1, 1)]
    assert [c.name for c, *_ in campaigns(tmp_path, ["mujoco"], [4])] == ["loop_mujoco_state_s5_seed4_paper"]


def test_all_pairs_of_the_asked_methods_campaigns_variant_names_included(tmp_path):
    _campaign(tmp_path, "loop_family_mujoco_state_s7_seed0_ours", 4)
    _campaign(tmp_path, "loop_family_mujoco_state_s7_seed0_ours_paper_drag_range", 2)
    _campaign(tmp_path, "loop_mujoco_state_s3_seed1_paper", 3)
    _campaign(tmp_path, "loop_mujoco_state_s1_seed1_ours", 1)       # hit first: no pair
    (tmp_path / "loop_mujoco_state_s2_seed1_ours.partial").mkdir()   # not a campaign's name
    found = [(c.name, k) for c, _p, _t, _s, k in campaigns(tmp_path, ["mujoco"], [0, 1], ("ours", "ours_paper_drag_range"),
                                                            all_pairs=True)]
    assert found == [("loop_family_mujoco_state_s7_seed0_ours", 1), ("loop_family_mujoco_state_s7_seed0_ours", 2),
                     ("loop_family_mujoco_state_s7_seed0_ours", 3), ("loop_family_mujoco_state_s7_seed0_ours_paper_drag_range", 1)]
    assert [k for *_, k in campaigns(tmp_path, ["mujoco"], [1], ("paper",))] == [1]   # 1 -> 2 only by default


def test_variants_take_the_papers_estimator_from_paper_yaml_and_not_its_planner(tmp_path):
    paper = yaml.safe_load((ROOT / "config" / "paper.yaml").read_text())
    extra = tmp_path / "w.yaml"
    extra.write_text("evaluation: {w: 0.5}\n")
    var = variants({"w05": extra})
    assert list(var) == ["paper", "ours", "w05"]
    assert var["paper"]["estimation"] == paper["estimation"] and var["paper"]["evaluation"]["w"] == 0.1
    assert "motion" not in var["paper"] and var["ours"] == {}   # ours: the defaults
    assert var["w05"] == {"evaluation": {"w": 0.5}}
    with pytest.raises(FileNotFoundError):
        variants({"x": tmp_path / "missing.yaml"})


def test_summary_pairs_each_variant_with_the_paper_on_the_same_campaigns():
    rows = [{"physics": "mujoco", "campaign": c, "paper": {"median_mm": p, "p95_mm": 3 * p, "E_mm": 100.0},
             "ours": {"median_mm": o, "p95_mm": None if o is None else 2 * o, "E_mm": e}}
            for c, p, o, e in [("a", 30.0, 20.0, 90.0), ("b", 40.0, 25.0, 120.0), ("b", 10.0, 9.0, 80.0),
                               ("c", 12.0, None, 1.0)]]
    s = summarize(rows, ["paper", "ours"])["mujoco"]
    assert s["pairs"] == 3 and s["campaigns"] == 2                   # the row without ours' figure left out
    assert s["ours"]["E_lower_share"] == pytest.approx(2 / 3)
    assert s["ours"]["paired_p95_diff_mm"] == pytest.approx((40 - 90 + 50 - 120 + 18 - 30) / 3)
    assert s["ours"]["p95_median_mm"] == 40.0 and s["paper"]["p95_median_mm"] == 90.0
    assert s["paper"]["median_mm"] == 30.0 and s["ours"]["median_mm"] == 20.0
    assert s["ours"]["paired_diff_mm"] == pytest.approx((-10 - 15 - 1) / 3)
    lo, hi = s["ours"]["paired_diff_ci95"]
    assert -15 <= lo <= s["ours"]["paired_diff_mm"] <= hi <= -1 and "paired_diff_mm" not in s["paper"]


def test_every_variant_starts_from_ours_not_from_the_campaigns_method(tmp_path):
    from benchmarks.loop_prediction import ours_config

    cfg = tmp_path / "config.yaml"      # a paper-method campaign's config: the paper's estimator merged in
    cfg.write_text(yaml.safe_dump({"lab": {"physics": "elastica"}, "motion": {"planner": "paper", "seed": 3},
                                   "estimation": {"optimizer": "random_search", "seed": 3},
                                   "evaluation": {"w": 0.1}, "model": {"drag": "isotropic"}}))
    assert ours_config(cfg) == {"lab": {"physics": "elastica"}, "motion": {"planner": "paper", "seed": 3},
                                "estimation": {"seed": 3}}
