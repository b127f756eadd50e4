"""``stringcast next`` on a recorded trial from another lab (../shared/field): the pipeline from the raw
files to the next motion in one process, without the virtual lab (``make test-core`` runs it in a
venv without the lab extra; the product's suite runs it too)."""
import contextlib
import io
import json
import os
import shutil
from pathlib import Path

import pytest
import yaml

from stringcast.cli import main
from stringcast.core import METHOD_CONFIGS

ROOT = Path(__file__).resolve().parents[1]
FIELD = Path(os.environ.get("STRINGCAST_FIELD_DATA", ROOT.parent / "shared" / "field"))
SMALL = {"estimation": {"iterations": 128, "batch": 64}, "motion": {"max_candidates": 1024, "extra_after_hit": 32}}
"""Small search budgets: the chain, not the search, is under test."""


def project(root: Path, trials=("trial_1",)) -> Path:
    """A project at ``root``: the repo's config, small budgets (small.yaml) and data/field_1 with its
    calib/ and each of ``trials`` linked to the field's trial_1 files (read-only, not copied)."""
    if not (FIELD / "field_1" / "trial_1" / "joints.csv").is_file():
        pytest.skip(f"the field recording is not at {FIELD} (set STRINGCAST_FIELD_DATA)")
    (root / "config").mkdir(parents=True)
    shutil.copyfile(ROOT / "config" / "config.yaml", root / "config" / "config.yaml")
    (root / "small.yaml").write_text(yaml.safe_dump(SMALL))
    dst = root / "data" / "field_1"
    dst.mkdir(parents=True)
    shutil.copyfile(FIELD / "field_1" / "campaign.yaml", dst / "campaign.yaml")
    (dst / "calib").symlink_to(FIELD / "field_1" / "calib")
    for name in trials:
        (dst / name).mkdir()
        for f in (FIELD / "field_1" / "trial_1").iterdir():
            (dst / name / f.name).symlink_to(f)
    return root


@pytest.fixture(scope="module")
def field_next(tmp_path_factory):
    """``stringcast next`` (ours) run once on the field recording: (project root, its printed output, the
    raw files' mtimes before). Its 1.6 GB of decoded frames go with the module's last test."""
    root = project(tmp_path_factory.mktemp("field") / "project")
    before = {p: p.stat().st_mtime_ns for p in (root / "data").rglob("*") if p.is_file()}
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["--config", str(FIELD / "lab.yaml"), "--config", str(root / "small.yaml"), "next",
                     str(root / "data" / "field_1" / "trial_1")])
    assert code == 0, out.getvalue()
    yield root, out.getvalue(), before
    shutil.rmtree(root, ignore_errors=True)


@pytest.mark.slow
def test_next_runs_a_recorded_trial_to_its_next_motion(field_next):
    root, out, before = field_next
    res = root / "results" / "field_1"
    for i, stage in enumerate(("decode", "calib-views", "calibrate", "sync", "sweep", "track", "estimate", "plan",
                               "report-trial"), 1):
        assert f"[next {i}/9] {stage} done" in out
    motion = (res / "trial_1" / "motion.csv").read_text().splitlines()
    assert motion[0].startswith("t_s,q1_rad") and len(motion) > 100
    params = json.loads((res / "trial_1" / "params.json").read_text())
    assert params["verdict"]["status"] in ("ok", "warn", "fail") and params["fit_check"]
    assert params["optimizer"] == "cmaes"                          # ours, the default
    plan = json.loads((res / "trial_1" / "motion.json").read_text())
    assert plan["planner"] == "robust"
    assert plan["planned_on_failed_fit"] == (params["verdict"]["status"] == "fail")
    assert (res / "report.html").is_file() and (res / "logs" / "track_1.log").is_file()
    assert f"next motion -> {res / 'trial_1' / 'motion.csv'}" in out
    assert (plan["verdict"]["status"] == "fail") == plan["planned_on_failed_fit"] and plan["verdict"]["reasons"]
    # the raw files are only read
    assert {p: p.stat().st_mtime_ns for p in (root / "data").rglob("*") if p.is_file()} == before


def test_next_method_paper_puts_the_papers_file_last(tmp_path, monkeypatch):
    """``next --method paper`` merges config/paper.yaml over the project's config and every ``--config``."""
    import stringcast.chain

    root = project(tmp_path / "project")
    seen = {}
    monkeypatch.setattr(stringcast.chain, "run_next", lambda trial, paths, main, say: seen.setdefault("paths", paths))
    main(["--config", str(root / "small.yaml"), "next", str(root / "data" / "field_1" / "trial_1"), "--method", "paper"])
    assert seen["paths"] == [str(root / "config" / "config.yaml"), str(root / "small.yaml"),
                             *map(str, METHOD_CONFIGS["paper"])]


@pytest.mark.slow
def test_the_papers_estimate_and_plan_run_on_a_recorded_trial(field_next, tmp_path):
    """The steps ``--method paper`` changes, as ``next`` runs them (:func:`stringcast.chain.trial_steps`),
    on the field trial's tracked results: the random search of eqs. (2)-(3) and the Section V planner
    (the budgets here are small)."""
    from stringcast.chain import trial_steps

    src = field_next[0]
    root = project(tmp_path / "project")
    shutil.copytree(src / "results", root / "results", ignore=shutil.ignore_patterns("frames*"))
    paths = [str(root / "config" / "config.yaml"), str(FIELD / "lab.yaml"), str(root / "small.yaml"),
             *map(str, METHOD_CONFIGS["paper"])]                  # as `next --method paper` merges them
    with contextlib.chdir(root):
        steps = {s.rule: s for s in trial_steps("field_1", 1, True, 2)}
        for rule in ("estimate", "plan"):
            assert main([*(a for p in paths for a in ("--config", p)), "--log", steps[rule].log,
                         *steps[rule].argv]) == 0, rule
    res = root / "results" / "field_1" / "trial_1"
    params = json.loads((res / "params.json").read_text())
    assert params["optimizer"] == "random_search" and params["evaluations"] == SMALL["estimation"]["iterations"]
    assert json.loads((res / "motion.json").read_text())["planner"] == "paper"


def test_next_names_a_missing_earlier_estimate(tmp_path, capsys):
    root = project(tmp_path / "project", trials=("trial_1", "trial_2"))
    assert main(["--config", str(FIELD / "lab.yaml"), "next", str(root / "data" / "field_1" / "trial_2")]) == 2
    out = "".join(capsys.readouterr())
    assert "results/field_1/trial_1/params.json: missing" in out and "stringcast next data/field_1/trial_1" in out
    assert not (root / "results").exists()


def test_next_refuses_a_folder_that_is_not_a_trial(tmp_path, capsys):
    assert main(["next", str(tmp_path)]) == 2
    assert "not a trial folder" in "".join(capsys.readouterr())


def test_a_trial_folder_is_placed_by_its_path_links_kept(tmp_path):
    """``stringcast next`` finds the project and campaign from the path as given: a campaign folder linked
    into data/ (a recording kept elsewhere) belongs to this project; a folder outside data/ is refused."""
    from stringcast.chain import trial_location
    from stringcast.core import DataError

    (tmp_path / "store" / "c" / "trial_2").mkdir(parents=True)
    (tmp_path / "project" / "data").mkdir(parents=True)
    (tmp_path / "project" / "data" / "c").symlink_to(tmp_path / "store" / "c")
    assert trial_location(tmp_path / "project" / "data" / "c" / "trial_2") == (tmp_path / "project", "c", 2)
    with pytest.raises(DataError, match="not a trial folder"):
        trial_location(tmp_path / "store" / "c" / "trial_2")
