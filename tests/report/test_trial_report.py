"""The trial report (issue 25): the stages' verdicts in a banner at the top, a next motion planned on a
failed fit marked so, and a grasp point outside the image does not stop the page."""
import re
from dataclasses import replace

import cv2
import numpy as np

from stringcast.calibrate.calibration import Calibration
from stringcast.core import PARAM_NAMES, read_json, write_json
from stringcast.core.files import write_parquet
from stringcast.estimate import run_estimation
from stringcast.model import parameters as prm
from stringcast.plan import next_motion as nm
from stringcast.plan import planning as pn
from stringcast.report import write_trial_report
from stringcast.report.verdicts import stage_verdicts
from tests.estimate.test_estimation import CHI_TRUE, _stage_settings, make_trial


def _trial(tmp_path, settings, campaign, dx):
    """data/ and results/ of one trial made by the model: tracks shifted by dx (m) along x, a calibration
    that warns, sync ok, the fit and the next motion the stages make of them. The calibration maps
    1 mm to 1 px of a 160 x 120 image: the grasp (about 0.3 m, 0.6 m) is far outside it."""
    data, res = tmp_path / "data" / "trial_1", tmp_path / "results" / "trial_1"
    data.mkdir(parents=True), res.mkdir(parents=True)
    chi = CHI_TRUE[:len(PARAM_NAMES) + campaign.string.mass_groups().max() + 1]
    c, mu = prm.decode(chi, settings.model, campaign.string.mass_groups())
    df, *_ = make_trial(campaign, c, mu, data)
    (data / "tracks.parquet").unlink()
    df.loc[df["point"] > 0, "x_m"] += dx
    write_parquet(res / "tracks.parquet", df)
    (data / "video").mkdir()
    for k in range(df["frame"].nunique()):
        cv2.imwrite(str(data / "video" / f"frame_{k:04d}.png"), np.full((120, 160), 100, np.uint8))
    write_json(res / "calibration.json", {**Calibration(np.diag([0.001, 0.001, 1.0]), (160, 120)).to_dict(),
                                          "verdict": {"status": "warn", "reasons": ["the shots cover 40 % of the image"]}})
    write_json(res / "sync.json", {"offset_s": 0.0, "method": "trigger", "verdict": {"status": "ok", "reasons": []}})
    write_json(res / "prev.json", {"chi": chi})
    run_estimation(res / "tracks.parquet", data / "joints.csv", campaign, res / "prev.json", 3, res / "params.json",
                   res / "fit.parquet", **_stage_settings(settings, iterations=64, batch=32))
    s = replace(settings, motion=replace(settings.motion, max_candidates=256, extra_after_hit=16, posture_pool=8))
    coeffs, mu0 = pn.first_parameters(model=s.model, motion=s.motion, string=campaign.string)
    first = pn.search(campaign, s.model, s.motion, coeffs, mu0, np.random.default_rng(5))
    pn.write_motion(first, campaign, s.motion, coeffs, mu0, 0, data / "motion.csv", data / "motion.json", "first")
    nm.run_plan(res / "params.json", data / "motion.json", campaign, res / "motion.csv", res / "motion.json", seed=1,
                model=s.model, motion=s.motion)
    return data, res


def _text(html: str) -> str:
    return " ".join(re.sub(r"<[^>]+>", " ", html).split())


def test_report_shows_the_verdicts_and_a_plan_on_a_failed_fit(tmp_path, settings, campaign):
    data, res = _trial(tmp_path, settings, campaign, dx=0.15 * campaign.string.length)
    assert read_json(res / "params.json")["verdict"]["status"] == "fail"
    write_trial_report(data, res, campaign, res / "report.html", settings=settings)
    html = (res / "report.html").read_text()
    banner = html[html.index('<div id="verdicts"'):html.index("</div>", html.index('<div id="verdicts"'))]
    assert 'class="banner fail"' in banner and html.index('id="verdicts"') < html.index("<h2>Summary</h2>")
    text = _text(banner)
    assert "calibration warn the shots cover 40 % of the image" in text
    assert "sync ok" in text and "tracking" not in text.split("fit")[0]   # no tracking.json: no row
    assert "fit fail the estimate is not usable; likely cause: geometry" in text
    summary = _text(html[html.index("<h2>Summary</h2>"):])
    assert "next motion planned on a failed fit" in summary and "predicted hit" not in summary
    assert 'id="fig-overlay"' in html       # the grasp is outside the image: the strip is a note, the page whole


def test_report_on_a_good_fit_says_predicted_hit(tmp_path, settings, campaign):
    data, res = _trial(tmp_path, settings, campaign, dx=0.0)
    write_json(res / "tracking.json", {"verdict": {"status": "ok", "reasons": []}})
    write_trial_report(data, res, campaign, res / "report.html", settings=settings)
    html = (res / "report.html").read_text()
    assert 'class="banner warn"' in html                # the calibration warns, the rest is ok
    assert 'class="verdict-tracking"' in html and 'class="verdict-fit"' in html
    summary = _text(html[html.index("<h2>Summary</h2>"):])
    assert "next motion: predicted hit" in summary and "planned on a failed fit" not in summary


def test_stage_verdicts_banner_rows():
    banner = stage_verdicts({"calibration": {"K": None}, "sync": None,
                             "tracking": {"verdict": {"status": "warn", "reasons": ["25 % valid"]}},
                             "fit": {"verdict": {"status": "fail", "reasons": ["E = 264 mm"], "likely_cause": "clock"}}})
    assert banner["status"] == "fail"
    assert [(r["stage"], r["status"], r["cause"]) for r in banner["rows"]] == [
        ("calibration", "not judged", ""), ("tracking", "warn", ""), ("fit", "fail", "clock")]
    assert stage_verdicts({"fit": {"verdict": {"status": "perhaps"}}})["rows"][0]["status"] == "not judged"
    assert stage_verdicts({"sync": {}})["status"] == "not judged"
