"""The fit's verdict (issue 25): a fit that cannot be right says so in params.json and on the command
line, and names the likely cause (geometry, clock, tracking, model)."""
import dataclasses

import pytest
import yaml

from stringcast import cli
from stringcast.core import ConfigError, DataError, EstimationSettings, PARAM_NAMES, Verdict, read_json, write_json
from stringcast.core.files import read_parquet, write_parquet
from stringcast.estimate import estimation as es
from stringcast.estimate.verdict import fit_verdict, sweep_bounds
from stringcast.model import parameters as prm
from tests.conftest import ROOT
from tests.estimate.test_estimation import CHI_TRUE, _stage_settings, make_trial


@pytest.fixture(scope="module")
def trial(tmp_path_factory, settings, campaign):
    """A trial the model itself made (tracks exact), and the truth as the previous estimate: with a
    tiny budget the fit stays at the truth, so whatever it misses is what was done to the tracks."""
    d = tmp_path_factory.mktemp("trial")
    chi = CHI_TRUE[:len(PARAM_NAMES) + campaign.string.mass_groups().max() + 1]
    c, mu = prm.decode(chi, settings.model, campaign.string.mass_groups())
    make_trial(campaign, c, mu, d)
    write_json(d / "prev.json", {"chi": chi})
    return d


def _fit(trial, settings, campaign, tmp_path, dx=0.0, dt=0.0, upstream=None):
    """run_estimation on the trial's tracks with the string's points shifted by dx (m, in x) and the
    frames' times by dt (s); the params.json written."""
    df = read_parquet(trial / "tracks.parquet")
    string = df["point"] > 0
    df.loc[string, "x_m"] += dx
    df["t_s"] += dt
    write_parquet(tmp_path / "tracks.parquet", df)
    for stage, doc in (upstream or {}).items():
        write_json(tmp_path / f"{stage}.json", doc)
    es.run_estimation(tmp_path / "tracks.parquet", trial / "joints.csv", campaign, trial / "prev.json", 3,
                      tmp_path / "params.json", tmp_path / "fit.parquet",
                      **_stage_settings(settings, iterations=64, batch=32))
    return read_json(tmp_path / "params.json")


def test_clean_fit_is_ok(trial, settings, campaign, tmp_path):
    doc = _fit(trial, settings, campaign, tmp_path, upstream={"calibration": {"K": None}})  # no verdict key: ok
    assert doc["verdict"] == {"status": "ok", "reasons": [], "likely_cause": ""}
    fig = doc["fit_check"]
    assert fig["error_share"] < 0.001 and fig["skill"] > 0.99 and fig["valid_share"] == 1.0
    assert fig["length_mm"] == pytest.approx(campaign.string.length * 1000)


def test_constant_offset_fails_as_geometry(trial, settings, campaign, tmp_path):
    """The tracked string 15 % of L to the side of where the arm holds it (a wrong board pose): the
    model cannot follow, most of the error is one offset, the string at rest does not hang from the grasp."""
    L = campaign.string.length
    doc = _fit(trial, settings, campaign, tmp_path, dx=0.15 * L)
    v, fig = doc["verdict"], doc["fit_check"]
    assert v["status"] == "fail" and v["likely_cause"] == "geometry", v
    assert any(r.startswith("likely cause: geometry") for r in v["reasons"])
    assert fig["offset_gain"] < 0.7 and fig["bias_mm"][0] > 0.1 * L * 1000 and fig["rest_gap_share"] > 0.05
    assert fig["shift_gain"] > 0.8   # no time shift explains it


def test_time_shift_fails_as_clock(trial, settings, campaign, tmp_path):
    """The frames' times 30 ms late (15 frame periods; a wrong sync): re-timing them explains the error."""
    doc = _fit(trial, settings, campaign, tmp_path, dt=0.030)
    v, fig = doc["verdict"], doc["fit_check"]
    assert v["status"] == "fail" and v["likely_cause"] == "clock", v
    assert fig["best_shift_ms"] == pytest.approx(-30.0, abs=2.1) and fig["shift_gain"] < 0.5
    assert any("check sync.json" in r for r in v["reasons"])


def test_earlier_stages_verdicts_are_carried(trial, settings, campaign, tmp_path):
    """A clean fit on a failed calibration is not usable either; sync's warning comes along."""
    up = {"calibration": {"verdict": {"status": "fail", "reasons": ["principal point undetermined"]}},
          "sync": {"offset_s": 0.0, "verdict": {"status": "warn", "reasons": ["video and trigger disagree"]}}}
    doc = _fit(trial, settings, campaign, tmp_path, upstream=up)
    v = doc["verdict"]
    assert v["status"] == "fail" and v["likely_cause"] == "geometry"
    assert v["reasons"] == ["calibration: principal point undetermined", "sync: video and trigger disagree"]
    write_json(tmp_path / "sync.json", {"verdict": {"status": "maybe", "reasons": []}})
    with pytest.raises(DataError, match="sync.json"):
        _fit(trial, settings, campaign, tmp_path)


def test_a_carried_reason_names_its_stage_once():
    """Tracking's reasons already begin "tracking: "; the fit carries them without a second prefix."""
    fig = {**FIG}
    up = {"tracking": Verdict("warn", ("tracking: the points jitter by 1.7 mm",)), "clock": Verdict("warn", ("off",))}
    v, _ = fit_verdict(fig, 30.0, EstimationSettings(), up)
    assert "tracking: the points jitter by 1.7 mm" in v.reasons and "clock: off" in v.reasons
    assert not any(r.startswith("tracking: tracking:") for r in v.reasons)


def test_cli_prints_the_verdict_after_E(trial, settings, campaign, tmp_path, capsys):
    df = read_parquet(trial / "tracks.parquet")
    df["t_s"] += 0.030
    write_parquet(tmp_path / "tracks.parquet", df)
    (tmp_path / "campaign.yaml").write_text(yaml.safe_dump({"string": 1, "target": 1}))
    (tmp_path / "tiny.yaml").write_text(yaml.safe_dump({"estimation": {"iterations": 64, "batch": 32}}))
    rc = cli.main(["--config", str(ROOT / "config" / "config.yaml"), "--config", str(tmp_path / "tiny.yaml"),
                   "estimate", "--tracks", str(tmp_path / "tracks.parquet"), "--joints", str(trial / "joints.csv"),
                   "--campaign", str(tmp_path / "campaign.yaml"), "--prev", str(trial / "prev.json"), "--trial", "3",
                   *(a for stage in ("geometry", "clock", "tracking")     # none written: their verdicts ok
                     for a in (f"--{stage}", str(tmp_path / f"{stage}.json"))),
                   "--out-params", str(tmp_path / "params.json"), "--out-fit", str(tmp_path / "fit.parquet")])
    lines = capsys.readouterr().out.splitlines()
    assert rc == 0 and lines[0].startswith("estimation: E = ")
    head = "fit: fail, the estimate is not usable, likely cause clock: shifting the frames' times by "
    assert lines[1].startswith(head)
    # the planted +30 ms, found back within three frame periods (2 ms each) by a 64-evaluation fit
    assert abs(float(lines[1][len(head):].split(" ms")[0]) + 30.0) <= 6.0
    assert lines[1].endswith(f"-> {tmp_path / 'params.json'}")


FIG = {"length_mm": 300.0, "valid_share": 0.9, "error_median_mm": 30.0, "error_share": 0.1, "skill": 0.7,
       "null_error_median_mm": 100.0, "rest_error_mm": None, "rest_gap_share": 0.0, "best_shift_ms": 2.0,
       "best_shift_frames": 1, "shift_gain": 0.95, "bias_mm": [3.0, 1.0], "offset_gain": 0.95,
       "early_error_mm": 30.0, "late_error_mm": 30.0}


@pytest.mark.parametrize("change, status, cause", [
    ({}, "ok", ""),
    ({"valid_share": 0.3}, "warn", "tracking"),
    ({"error_share": 0.2, "error_median_mm": 60.0, "skill": 0.5}, "warn", "model"),
    ({"error_share": 0.3, "error_median_mm": 90.0, "skill": 0.1, "early_error_mm": 20.0, "late_error_mm": 120.0},
     "fail", "model"),
    ({"error_share": 0.3, "error_median_mm": 90.0, "skill": 0.1, "valid_share": 0.3}, "fail", "tracking"),
    ({"rest_gap_share": 0.2}, "warn", "geometry"),
    ({"error_share": 0.2, "error_median_mm": 60.0, "rest_error_mm": 40.0}, "warn", "geometry"),
    ({"error_share": 0.2, "error_median_mm": 60.0, "rest_error_mm": 40.0, "rest_folded_points": [1]}, "warn", "model"),
    ({"error_share": 0.04, "best_shift_frames": 5, "best_shift_ms": 10.0, "shift_gain": 0.2}, "warn", "clock"),
    ({"error_share": 0.016, "best_shift_frames": 4, "best_shift_ms": 8.0, "shift_gain": 0.64}, "ok", ""),
    ({"error_share": 0.1, "best_shift_frames": 4, "best_shift_ms": 8.0, "shift_gain": 0.64}, "warn", "clock"),
    ({"error_share": 0.1, "best_shift_frames": 2, "best_shift_ms": 4.0, "shift_gain": 0.2}, "ok", ""),
])
def test_verdict_rules(change, status, cause):
    """The rules of estimate.verdict on figures made up for each: a fit within 10 % of L that explains
    70 % of the motion is ok; each figure past its threshold warns or fails and names its cause; a time
    shift under 3 frame periods is no evidence; an error already at rest is the camera's, unless the
    string folds within a segment there (the model's then); a small error that re-timing removes only warns, and one
    it only partly removes (string 7's first fit on the lab: 1.6 % of L, +8 ms gains 0.64, sync right) is ok."""
    v, c = fit_verdict({**FIG, **change}, 40.0, EstimationSettings())
    assert (v.status, c) == (status, cause), v.reasons
    assert v.ok or v.reasons[-1].startswith("likely cause: ")


def test_blown_up_fit_fails():
    fig = {k: None for k in FIG} | {"length_mm": 300.0}
    v, cause = fit_verdict(fig, float("inf"), EstimationSettings())
    assert v.status == "fail" and cause == "model" and "E = inf" in v.reasons[0]


def test_verdict_thresholds_are_checked():
    with pytest.raises(ConfigError, match="verdict_error_share"):
        EstimationSettings(verdict_error_share=(0.3, 0.2))
    with pytest.raises(ConfigError, match="verdict_skill"):
        EstimationSettings(verdict_skill=(0.2, 0.4))
    assert dataclasses.replace(EstimationSettings(), verdict_shift_gain=(0.8, 0.4)).verdict_shift_gain == (0.8, 0.4)


OK = Verdict()
PINNED = {"mapping_uncertainty_mm": 0.4, "clock_uncertainty_ms": 0.1}
"""The sweep's bounds on a well pinned trial (the issue's field footage: within 0.4 mm at the string)."""
GEOMETRY_LOOK = {"error_share": 0.3, "error_median_mm": 90.0, "skill": -0.2, "null_error_median_mm": 75.0,
                 "rest_error_mm": 60.0, "bias_mm": [50.0, 10.0], "offset_gain": 0.6, "speed_median_mm_s": 800.0}
"""A fit worse than the rigidly carried string, already off at rest and in one direction: the figures that
name geometry when nothing else is known."""


@pytest.mark.parametrize("upstream, sweep, change, cause", [
    ({"geometry": OK, "clock": OK, "tracking": OK}, None, {}, "geometry"),            # no sweep: as before
    ({"geometry": OK, "clock": OK, "tracking": OK}, PINNED, {}, "model"),
    ({"geometry": OK, "clock": OK}, PINNED, {}, "model"),                             # no tracking.json: ok
    # the mapping known only to 30 mm (a third of the error): it may be the cause
    ({"geometry": OK, "clock": OK, "tracking": OK}, {**PINNED, "mapping_uncertainty_mm": 30.0}, {}, "geometry"),
    # the clock known to 30 ms (24 mm at the string's speed, more than a quarter of the error), with no sign
    # of a clock fault: the geometry is ruled out all the same, and nothing else stands out
    ({"geometry": OK, "clock": OK, "tracking": OK}, {**PINNED, "clock_uncertainty_ms": 30.0}, {}, "model"),
    # a failed stage's bound pins nothing: its evidence decides as before
    ({"geometry": Verdict("fail", ("the calibration failed",)), "clock": OK, "tracking": OK}, PINNED, {}, "geometry"),
    # a warned stage (over its own 1 mm tolerance) still states its bound, here 2.65 mm of a 90 mm error
    # (the field recording of issue 52: every upstream stage warned at the mm level, and the fit blamed the
    # geometry for a 68 mm error the sweep had pinned to 2.65 mm)
    ({"geometry": Verdict("warn", ("known only to 2.65 mm",)), "clock": Verdict("warn", ("known to 0.66 ms",)),
      "tracking": Verdict("warn", ("jitter 1.6 mm",))},
     {**PINNED, "mapping_uncertainty_mm": 2.65, "clock_uncertainty_ms": 0.66, "tracking_scale_mm": 5.1}, {}, "model"),
    # tracking warned and stated no scale (or one over a quarter of the error): it may be the cause
    ({"geometry": OK, "clock": OK, "tracking": Verdict("warn", ("p95 49 mm",))}, PINNED, {}, "tracking"),
    ({"geometry": OK, "clock": OK, "tracking": Verdict("warn", ("p95 49 mm",))}, {**PINNED, "tracking_scale_mm": 49.0},
     {}, "tracking"),
    ({"geometry": OK, "clock": OK, "tracking": Verdict("fail", ("lost",))}, {**PINNED, "tracking_scale_mm": 1.0},
     {}, "tracking"),
    ({"geometry": OK, "clock": OK, "tracking": OK}, PINNED, {"valid_share": 0.3}, "tracking"),
])
def test_a_fit_the_sweep_pinned_is_the_models(upstream, sweep, change, cause):
    """Where the arm's sweep pinned the mapping and the clock (their verdicts not fail, their stated
    uncertainties at most a quarter of the fit's error) and tracking is ok or pinned by its stated error
    scale, a fit worse than a rigidly carried string is the model's, whatever its offset and its error at rest look like (issue 51: the
    field footage said geometry in 20 of 33 such trials); it says recalibrating will not help. Without
    the sweep's bounds, with a loose one, or with an earlier stage failing, the old evidence decides, less
    the evidence of a cause the sweep alone ruled out."""
    v, c = fit_verdict({**FIG, **GEOMETRY_LOOK, **change}, 90.0, EstimationSettings(), upstream, sweep)
    assert v.status == "fail" and c == cause, v.reasons
    why = next(r for r in v.reasons if r.startswith("likely cause: "))
    if c == "model" and sweep["clock_uncertainty_ms"] > 1:
        assert "pinned the mapping to 0.40 mm)" in why and "offset" not in why
    elif c == "model":
        assert (f"pinned the mapping to {sweep['mapping_uncertainty_mm']:.2f} mm and the clock to "
                f"{sweep['clock_uncertainty_ms']:.2f} ms") in why
        assert "recalibrating will not help" in why and "carried rigidly" in why
        if sweep.get("tracking_scale_mm") is not None:
            assert "tracking's own figures state its errors to 5.1 mm" in why


def test_sweep_bounds_are_read_from_geometry_and_clock(tmp_path):
    """params.json's verdict reads the bounds from the sweep's files: only where the sweep ran."""
    write_json(tmp_path / "geometry.json", {"sweep": {"applied": True, "uncertainty_p95_mm": 0.3}})
    write_json(tmp_path / "clock.json", {"sweep": {"applied": False, "reason": "switched off"}})
    got = es.read_sweep_bounds({"geometry": tmp_path / "geometry.json", "clock": tmp_path / "clock.json",
                                "tracking": tmp_path / "missing.json"})
    assert got == {"mapping_uncertainty_mm": 0.3, "clock_uncertainty_ms": None, "tracking_scale_mm": None}
    assert sweep_bounds(None, None) == {"mapping_uncertainty_mm": None, "clock_uncertainty_ms": None,
                                        "tracking_scale_mm": None}
    write_json(tmp_path / "tracking.json", {"error_scale_mm": 5.1, "verdict": {"status": "warn", "reasons": ["x"]}})
    assert es.read_sweep_bounds({"tracking": tmp_path / "tracking.json"})["tracking_scale_mm"] == 5.1


@pytest.mark.parametrize("skill, status", [(-0.2, "fail"), (0.0, "fail"), (0.1, "ok"), (0.6, "ok")])
def test_a_close_fit_no_better_than_the_rigid_string_fails(skill, status):
    """Issue 52: a fit worse than a string carried rigidly by the hand is never a usable estimate, even where
    its error is under verdict_floor_share of L (there the skill's warn thresholds do not judge it)."""
    err = 9.0                                                    # 3 % of the 300 mm string: under the floor
    fig = {**FIG, "error_median_mm": err, "error_share": err / 300.0, "skill": skill,
           "null_error_median_mm": err / (1 - skill) if skill < 1 else 1.0}
    v, cause = fit_verdict(fig, 20.0, EstimationSettings())
    assert v.status == status, v.reasons
    assert (status == "fail") == any("no closer to the tracked string than the string carried rigidly" in r
                                     for r in v.reasons)
    assert (cause != "") == (status == "fail")
