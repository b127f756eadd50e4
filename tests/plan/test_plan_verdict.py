"""The plan stage's verdict (stringcast.plan.verdict): what a planned hit rests on decides how sure it is."""
import pytest

from stringcast.plan.verdict import RESIDUAL_WARN_RADII, plan_verdict

R = 0.02     # the target's radius, m


def _residual(mm):
    return {"median_mm": mm, "max_mm": 3 * mm, "delay_s": 0.3, "valid_share": 0.9, "sets": 21}


def test_a_small_correction_is_ok_and_says_how_sure():
    v = plan_verdict("perturbation", True, 0.004, R, _residual(8.0))
    assert v.status == "ok" and "8 mm off" in v.reasons[0] and "nine times in ten" in v.reasons[0]


@pytest.mark.parametrize("origin", ["perturbation", "wide_perturbation"])
def test_a_correction_beyond_the_radius_warns(origin):
    size = RESIDUAL_WARN_RADII * R * 1000 + 5
    v = plan_verdict(origin, True, 0.004, R, _residual(size))
    assert v.status == "warn" and f"{size:.0f} mm off" in v.reasons[0] and "radius 20 mm" in v.reasons[0]
    assert plan_verdict(origin, True, 0.004, R, _residual(size - 10)).status == "ok"


def test_the_radius_sets_the_threshold_not_millimetres():
    """The same 30 mm correction: doubtful for a 20 mm target, not for a 50 mm one."""
    assert plan_verdict("perturbation", True, 0.01, 0.02, _residual(30.0)).status == "warn"
    assert plan_verdict("perturbation", True, 0.01, 0.05, _residual(30.0)).status == "ok"


def test_first_and_new_motions_warn_with_their_hit_rate():
    first = plan_verdict("first", True, 0.003, R)
    new = plan_verdict("new", True, 0.003, R, observed_miss_m=0.180)
    assert first.status == new.status == "warn"
    assert "before any fit" in first.reasons[0] and "one time in three" in first.reasons[0]
    assert "after a tracked miss of 180 mm" in new.reasons[0] and "no measured correction" in new.reasons[0]


def test_a_failed_fit_fails_the_plan_whatever_it_predicts():
    v = plan_verdict("perturbation", True, 0.001, R, _residual(3.0), failed_fit={"status": "fail",
                                                                                "likely_cause": "recording"})
    assert v.status == "fail" and v.reasons[0].startswith("planned on a failed fit (likely cause: recording)")


def test_a_predicted_miss_and_a_slack_hit_warn():
    miss = plan_verdict("perturbation", False, 0.035, R, _residual(3.0))
    assert miss.status == "warn" and "passes 35 mm from the target's centre" in miss.reasons[0]
    slack = plan_verdict("new", True, 0.002, R, slack=True)
    assert slack.status == "warn" and "slack string" in slack.reasons[0]


def test_without_a_correction_nothing_is_claimed():
    v = plan_verdict("perturbation", True, 0.002, R, None)
    assert v.status == "ok" and v.reasons == ()
