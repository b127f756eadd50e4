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
    assert [(c.name, p, t, s) for c, p, t, s in found] == [
        ("loop_elastica_video_s2_seed0_paper", "elastica", 2, 0), ("loop_mujoco_state_s3_seed1_paper", "mujoco", 3, 1)]
    assert [c.name for c, *_ in campaigns(tmp_path, ["mujoco"], [4])] == ["loop_mujoco_state_s5_seed4_paper"]


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
    rows = [{"physics": "mujoco", "paper": {"median_mm": p}, "ours": {"median_mm": o}}
            for p, o in [(30.0, 20.0), (40.0, 25.0), (10.0, 9.0), (12.0, None)]]
    s = summarize(rows, ["paper", "ours"])["mujoco"]
    assert s["campaigns"] == 3                                       # the row without ours' figure left out
    assert s["paper"]["median_mm"] == 30.0 and s["ours"]["median_mm"] == 20.0
    assert s["ours"]["paired_diff_mm"] == pytest.approx((-10 - 15 - 1) / 3)
    lo, hi = s["ours"]["paired_diff_ci95"]
    assert -15 <= lo <= s["ours"]["paired_diff_mm"] <= hi <= -1 and "paired_diff_mm" not in s["paper"]
