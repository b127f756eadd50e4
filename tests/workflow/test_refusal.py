"""A bad raw file stops the workflow before any decode: Snakemake's own run of a campaign with one broken
file builds none of its jobs, names the file and the problem, ends non-zero, and changes nothing.

The cases are the check's (tests/check/test_check_cases.py), one of each kind of raw file; the check
itself is tested case by case there."""
import hashlib
import subprocess
import sys
from pathlib import Path

import pytest

from check.test_check_cases import CASES
from raw_campaign import good_campaign

ROOT = Path(__file__).resolve().parents[2]
KINDS = ("campaign-bad-yaml", "campaign-5000mm-string-10-points", "video-yaml-fps-100000", "video-yaml-frames-wrong",
         "no-video", "joints-in-degrees", "joints-nan-row", "joints-t-not-increasing", "motion-json-missing",
         "calib-unreadable-image")


def _checksums(folder: Path) -> dict:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("name,breakage,status,expected", [c for c in CASES if c[0] in KINDS],
                         ids=[c[0] for c in CASES if c[0] in KINDS])
def test_snakemake_refuses_a_bad_raw_file_before_any_job(tmp_path, name, breakage, status, expected):
    (tmp_path / "Snakefile").symlink_to(ROOT / "Snakefile")
    (tmp_path / "workflow").symlink_to(ROOT / "workflow")
    (tmp_path / "config").mkdir()
    (tmp_path / "config" / "config.yaml").write_text((ROOT / "config" / "config.yaml").read_text())
    breakage(good_campaign(tmp_path))
    raw = _checksums(tmp_path / "data")
    proc = subprocess.run([sys.executable, "-m", "snakemake", "--cores", "1"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    out = proc.stdout + proc.stderr
    assert proc.returncode != 0, out
    assert "stringcast: data/c was not built" in out and "Traceback" not in out, out
    for text in expected:
        assert text in out, out
    assert _checksums(tmp_path / "data") == raw                              # the raw files untouched
    made = [p for p in (tmp_path / "results").rglob("*") if p.is_file()] if (tmp_path / "results").exists() else []
    made = [p for p in made if p.parent.name != ".stringcast"]    # the run's config for its jobs, not a product
    assert [p.name for p in made] == ["refused_campaigns.log"], made        # no job ran: no frames.npy, nothing
