"""A next motion planned on a failed fit (issue 25): still planned (the person decides), and marked so in
motion.json, in the plan's message and on the command line."""
from dataclasses import replace

import numpy as np
import pytest
import yaml

from stringcast import cli
from stringcast.core import PARAM_NAMES, read_json, write_json
from stringcast.plan import next_motion as nm
from stringcast.plan import planning as pn
from tests.conftest import ROOT

FAILED = {"status": "fail", "likely_cause": "geometry",
          "reasons": ["the fitted string is 84 mm from the tracked one at the median moving frame",
                      "likely cause: geometry (the camera calibration or board pose): one constant offset"]}


@pytest.fixture
def played(tmp_path, settings, campaign):
    """A played first motion (m1.json) and a small planner's settings."""
    s = replace(settings, motion=replace(settings.motion, max_candidates=256, extra_after_hit=16, batch=64,
                                         posture_pool=8))
    coeffs, mu = pn.first_parameters(model=s.model, motion=s.motion, string=campaign.string)
    first = pn.search(campaign, s.model, s.motion, coeffs, mu, np.random.default_rng(5))
    pn.write_motion(first, campaign, s.motion, coeffs, mu, 0, tmp_path / "m1.csv", tmp_path / "m1.json", "first")
    doc = {"coefficients": dict(zip(PARAM_NAMES, coeffs)), "mu": mu}
    return s, doc


@pytest.mark.parametrize("verdict", [FAILED, {"status": "ok", "reasons": [], "likely_cause": ""}, None])
def test_plan_on_a_failed_fit_is_marked(tmp_path, campaign, played, verdict):
    s, doc = played
    write_json(tmp_path / "params.json", doc if verdict is None else {**doc, "verdict": verdict})
    res = nm.run_plan(tmp_path / "params.json", tmp_path / "m1.json", campaign, tmp_path / "m2.csv",
                      tmp_path / "m2.json", seed=1, model=s.model, motion=s.motion)
    out = read_json(tmp_path / "m2.json")
    failed = verdict is FAILED
    assert out["planned_on_failed_fit"] is failed
    assert out["failed_fit"] == (FAILED if failed else None)
    assert res.message.startswith("planned on a failed fit (likely cause: geometry)") is failed
    assert (tmp_path / "m2.csv").exists()          # planned all the same


def test_cli_plan_warns_on_a_failed_fit(tmp_path, campaign, played, capsys):
    s, doc = played
    write_json(tmp_path / "params.json", {**doc, "verdict": FAILED})
    (tmp_path / "campaign.yaml").write_text(yaml.safe_dump({"string": 1, "target": 1}))
    small = {"motion": {"max_candidates": 256, "extra_after_hit": 16, "batch": 64, "posture_pool": 8}}
    (tmp_path / "small.yaml").write_text(yaml.safe_dump(small))
    rc = cli.main(["--config", str(ROOT / "config" / "config.yaml"), "--config", str(ROOT / "config" / "paper.yaml"),
                   "--config", str(tmp_path / "small.yaml"),
                   "plan", "--params", str(tmp_path / "params.json"), "--played-motion", str(tmp_path / "m1.json"),
                   "--campaign", str(tmp_path / "campaign.yaml"), "--out-dir", str(tmp_path / "next"), "--seed", "1"])
    lines = capsys.readouterr().out.splitlines()
    assert rc == 0 and lines[0].startswith("plan: fail, next motion predicted ")
    assert "): planned on a failed fit (likely cause: geometry)" in lines[0]
    assert lines[0].endswith(f"-> {tmp_path / 'next' / 'motion.csv'}")
    assert lines[-2:] == [f"  - the fit ({tmp_path / 'params.json'}): {r}" for r in FAILED["reasons"]]
    assert read_json(tmp_path / "next" / "motion.json")["verdict"]["status"] == "fail"
