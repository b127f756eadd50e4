"""benchmarks.field: the project laid out over the field campaigns, and a trial's figures read from its files."""
import json

from benchmarks.field import field_campaigns, make_project, trial_figures


def test_the_project_links_every_campaign_and_only_campaigns(tmp_path):
    field = tmp_path / "field"
    for name in ("a", "b"):
        (field / name).mkdir(parents=True)
        (field / name / "campaign.yaml").write_text("string: 1\ntarget: 1\n")
    (field / "notes").mkdir()
    (field / "lab.yaml").write_text("arms: {}\n")
    assert [p.name for p in field_campaigns(field)] == ["a", "b"]
    work = tmp_path / "work"
    assert make_project(work, field) == ["a", "b"]
    assert (work / "data" / "a").resolve() == (field / "a").resolve()
    assert (work / "Snakefile").is_symlink() and (work / "workflow" / "rules").is_dir()
    assert make_project(work, field) == ["a", "b"]            # a second run reuses the layout


def test_a_trial_s_figures_and_verdicts_come_from_its_files(tmp_path):
    (tmp_path / "tracking.json").write_text(json.dumps({"verdict": {"status": "ok", "reasons": []}}))
    (tmp_path / "params.json").write_text(json.dumps({
        "E_mm": 1500.0, "coefficients": {"k_s": 1e6}, "mu_groups": [0.1, 0.1],
        "verdict": {"status": "fail", "reasons": ["fit: the fit explains only 0 %"], "likely_cause": "model"},
        "fit_check": {"skill": -0.5, "error_median_mm": 68.0, "error_share": 0.13, "tip_error_median_mm": 169.0,
                      "null_error_median_mm": 45.0}}))
    fig = trial_figures(tmp_path)
    assert fig["skill"] == -0.5 and fig["error_share"] == 0.13 and fig["likely_cause"] == "model"
    assert fig["verdicts"]["fit"] == {"status": "fail", "first_reason": "fit: the fit explains only 0 %"}
    assert fig["verdicts"]["tracking"] == {"status": "ok", "first_reason": None}
    assert fig["verdicts"]["sync"] is None                   # no file: no verdict, not an ok
