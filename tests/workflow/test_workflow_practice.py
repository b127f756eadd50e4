"""Workflow practice: lint, formatting, wildcard constraints, profiles (fast: dry runs only).

The kill-and-restart and raw-data-untouched checks need real outputs and live in the slow
end-to-end test (tests/test_workflow.py).
"""
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent


def _run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(args, cwd=cwd, capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def project(tmp_path_factory) -> Path:
    """A project root with one campaign of one tiny trial whose raw files pass the check: enough for the DAG."""
    from raw_campaign import good_campaign

    root = tmp_path_factory.mktemp("wf")
    (root / "Snakefile").symlink_to(ROOT / "Snakefile")
    (root / "workflow").symlink_to(ROOT / "workflow")
    (root / "config").mkdir()
    (root / "config" / "config.yaml").write_text((ROOT / "config" / "config.yaml").read_text())
    good_campaign(root).rename(root / "data" / "c1")
    return root


def test_snakemake_lint_is_clean(project):
    proc = _run([str(BIN / "snakemake"), "--lint"], project)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0 and "good condition" in out, out


def test_rules_are_snakefmt_formatted():
    proc = _run([str(BIN / "snakefmt"), "--check", "Snakefile", "workflow/"], ROOT)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_no_lambdas_and_every_rule_logs():
    for path in [ROOT / "Snakefile", *(ROOT / "workflow" / "rules").glob("*.smk")]:
        text = path.read_text()
        code = [line.split("#", 1)[0] for line in text.splitlines()]
        assert not any(re.search(r"\blambda\b", line) for line in code), path
        for rule in re.split(r"\nrule ", text)[1:]:
            name = rule.split(":", 1)[0]
            if name != "all":
                assert "\n    log:" in rule, f"{path}: rule {name}"
            if name not in ("all", "refused_campaigns"):   # the refusal only prints and fails: nothing to time
                assert "\n    benchmark:" in rule, f"{path}: rule {name}"


@pytest.mark.parametrize("profile", ["local", "slurm"])
def test_profiles_plan_every_stage(project, profile):
    proc = _run([str(BIN / "snakemake"), "--profile", str(ROOT / "config" / "profiles" / profile), "-n",
                 "--cores", "8"], project)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    for rule in ("plan_first", "calibrate", "sync", "sweep", "track", "estimate", "plan", "report_trial",
                 "report_campaign"):
        assert re.search(rf"^rule {rule}:", out, re.M), (rule, out[-2000:])
    if profile == "slurm":  # per-rule resources from the profile reach the jobs
        est = out[out.index("rule estimate:"):]
        assert "mem_mb=4000" in est.split("rule ")[1] and "NUMBA_NUM_THREADS=8" in est


def test_wildcard_constraints_refuse_odd_names(project):
    proc = _run([str(BIN / "snakemake"), "-n", "--cores", "1", "results/c 1/trial_x/tracks.parquet"], project)
    assert proc.returncode != 0
    assert "MissingRuleException" in proc.stderr + proc.stdout or "No rule to produce" in proc.stderr + proc.stdout


@pytest.mark.parametrize("doc, message", [({"trackng": {"rest_frames": 30}}, "'trackng' was unexpected"),
                                          ({"tracking": {"rest_frame": 30}}, "'rest_frame' was unexpected")])
def test_config_typo_is_a_schema_error_naming_the_key(project, tmp_path, doc, message):
    bad = tmp_path / "typo.yaml"
    bad.write_text(yaml.safe_dump(doc))
    proc = _run([str(BIN / "snakemake"), "-n", "--cores", "1", "--configfile", str(bad)], project)
    out = proc.stdout + proc.stderr
    assert proc.returncode != 0 and message in out, out[-2000:]
