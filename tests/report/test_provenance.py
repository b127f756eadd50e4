"""Every report page says what produced it: the method, the code's commit, the library versions."""
import copy
import re
import subprocess

import pytest

from stringcast.report import provenance as prov
from stringcast.core import DEFAULT_CONFIG, PAPER_CONFIG, load_config
from stringcast.core.settings import EstimationSettings, settings_from_config
from stringcast.report import write_campaign_report


def test_provenance_names_the_method_commit_and_versions():
    ours = settings_from_config(load_config(DEFAULT_CONFIG))
    p = prov.provenance(ours)
    assert set(p) == {"method", "settings_digest", "commit", "versions"}
    assert p["method"] == "ours"
    assert re.fullmatch(r"[0-9a-f]{40}(-dirty)?|unknown", p["commit"]), p["commit"]
    assert list(p["versions"]) == ["stringcast", "numpy", "numba", "scipy", "opencv", "pandas", "snakemake",
                                   "mujoco", "cma"]
    assert all(v for v in p["versions"].values()) and p["versions"]["numpy"] != "not installed"

    paper = prov.provenance(settings_from_config(load_config([DEFAULT_CONFIG, PAPER_CONFIG])))
    assert paper["method"] == "the paper's method"

    # a file that sets a setting to its default, or changes only the virtual lab, is still ours
    # (the settings are compared, not the files)
    config = load_config(DEFAULT_CONFIG)
    explicit = dict(copy.deepcopy(config), estimation={"iterations": EstimationSettings().iterations},
                    lab={**config["lab"], "scene_seed": 12})
    assert prov.provenance(settings_from_config(explicit)) == p

    custom = dict(copy.deepcopy(config), estimation={"iterations": EstimationSettings().iterations + 1})
    c = prov.provenance(settings_from_config(custom))
    assert re.fullmatch(r"[0-9a-f]{12}", c["settings_digest"])
    assert c["method"] == f"custom settings {c['settings_digest']}" and c["settings_digest"] != p["settings_digest"]


def _git(cwd, *args):
    return subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=cwd, check=True,
                          capture_output=True, text=True).stdout.strip()


def test_git_commit_dirty_only_for_tracked_changes(tmp_path):
    assert prov.git_commit.__wrapped__(tmp_path) == "unknown"   # not a checkout
    _git(tmp_path, "init", "-q")
    (tmp_path / "a.txt").write_text("a\n")
    _git(tmp_path, "add", "a.txt")
    _git(tmp_path, "commit", "-q", "-m", "a")
    head = _git(tmp_path, "rev-parse", "HEAD")
    (tmp_path / "untracked.txt").write_text("u\n")
    assert prov.git_commit.__wrapped__(tmp_path) == head
    (tmp_path / "a.txt").write_text("b\n")
    assert prov.git_commit.__wrapped__(tmp_path) == head + "-dirty"
    sub = tmp_path / "sub"
    sub.mkdir()   # a folder inside someone else's checkout is not a checkout of the code
    assert prov.git_commit.__wrapped__(sub) == "unknown"


@pytest.mark.parametrize("files,method", [((DEFAULT_CONFIG,), "ours"),
                                          ((DEFAULT_CONFIG, PAPER_CONFIG), "the paper&#39;s method")])
def test_campaign_page_footer_shows_provenance(tmp_path, files, method):
    from stringcast.core import resolve_campaign

    config = load_config(list(files))
    campaign = resolve_campaign({"string": 1, "target": 1}, config, "c")
    (tmp_path / "data").mkdir()
    write_campaign_report(tmp_path / "data", tmp_path / "results", campaign, tmp_path / "report.html",
                          settings=settings_from_config(config))
    html = (tmp_path / "report.html").read_text()
    footer = html[html.index('<footer id="provenance">'):]
    assert f'<td class="l">{method}</td>' in footer
    assert prov.git_commit() in footer and f"numpy {prov.library_versions()['numpy']}" in footer


def test_the_campaign_table_s_fit_cell_names_the_verdict_and_its_cause():
    """Issue 52: a failed fit shows on the campaign page, with its likely cause; an ok fit names none."""
    from stringcast.report.campaign_page import _fit_cell

    assert _fit_cell({"verdict": {"status": "fail", "reasons": ["x"], "likely_cause": "model"}}) == \
        {"fit_status": "fail", "fit_cause": "model"}
    assert _fit_cell({"verdict": {"status": "ok", "reasons": [], "likely_cause": ""}}) == \
        {"fit_status": "ok", "fit_cause": ""}
    assert _fit_cell({}) == {"fit_status": "not judged", "fit_cause": ""}
    assert _fit_cell({"verdict": "garbled"}) == {"fit_status": "not judged", "fit_cause": ""}
