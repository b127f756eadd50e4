"""The sync's confidence: the video's evidence against a trigger time, in units of the clip's own noise."""
import numpy as np
import pytest

from stringcast.core import SyncSettings
from stringcast.sync.confidence import block_counts, block_length, choose_offset, compare_residuals, video_quality
from stringcast.sync.video_offset import VideoEvidence

TAU = 0.0431  # s, the true offset of the synthetic clips


def _evidence(F=200, S=2, jitter_ms=0.3, drift_ms=0.0, peaks=(0.0,), heights=(1.0,), seed=0):
    """Synthetic evidence: frames' own best offsets TAU + jitter (+ a slow drift shared by neighbouring frames)
    at 0.5 m/s, and per-frame score curves with bumps at ``peaks`` (ms from TAU) of ``heights``."""
    rng = np.random.default_rng(seed)
    slow = drift_ms * np.sin(np.linspace(0, 3 * np.pi, F))[:, None]
    tau_ks = TAU + (rng.normal(0, jitter_ms, (F, S)) + slow) / 1000
    taus = TAU + np.arange(-10, 10.01, 0.25) / 1000
    curve = sum(h * np.exp(-0.5 * ((taus - TAU - p / 1000) / 0.0015) ** 2) for p, h in zip(peaks, heights))
    per_frame = curve[None, :, None] + rng.normal(0, 0.02, (F, len(taus), S))
    return VideoEvidence(taus, per_frame, np.ones(S, bool), tau_ks, np.full((F, S), 0.5), 500.0, 2.0, 60.0)


def _est(ev, offset=TAU):
    return {"offset_s": offset, "time_residual_ms": 0.3, "frames_used": ev.tau_ks.shape[0],
            "segments_used": [0, 1], "segment_offsets_s": [offset] * ev.tau_ks.shape[1], "residual_mm": 0.2,
            "evidence": ev}


def test_block_length_follows_the_frames_correlation():
    rng = np.random.default_rng(0)
    assert block_length(rng.normal(size=400)) <= 3
    assert block_length(np.sin(np.linspace(0, 4 * np.pi, 400)) + 0.1 * rng.normal(size=400)) > 30
    counts = block_counts(100, 10, samples=50)
    assert counts.shape == (50, 100) and np.all(counts.sum(axis=1) == 100)


def test_residual_excess_and_how_often_the_resamples_reach_it():
    ev = _evidence()
    near = compare_residuals(ev, TAU + 0.0001, TAU)  # the trigger right, the video 0.1 ms off
    far = compare_residuals(ev, TAU, TAU + 0.002)  # the trigger 2 ms off
    assert near["p"] > 0.05 and far["p"] == 0.0 and far["resamples"] == 4000
    assert far["excess_mm"] == pytest.approx(far["trigger_mm"] - far["video_mm"])
    assert far["trigger_mm"] == pytest.approx(1.4826 * 1.0, rel=0.1)  # 2 ms at 0.5 m/s: 1 mm, x the MAD's 1.4826
    # frames that drift together are fewer independent pieces of evidence: a larger standard error
    drifting = compare_residuals(_evidence(drift_ms=1.0), TAU, TAU + 0.002)
    assert drifting["block_frames"] > 5 * far["block_frames"]
    assert drifting["standard_error_mm"] > 2 * far["standard_error_mm"]


def test_two_peaks_of_similar_height_are_ambiguous_and_keep_the_trigger():
    st = SyncSettings()
    ev = _evidence(peaks=(0.0, 6.0), heights=(1.0, 1.0))
    fig, reasons = video_quality(ev, _est(ev), st)
    assert fig["ambiguous"] and min(abs(fig["second_peak_s"] - TAU - d) for d in (0.0, 0.006)) < 3e-4
    assert any("two peaks" in r for r in reasons)
    choice = choose_offset(_est(ev), None, TAU + 0.006, st)
    assert choice["chosen"] == "trigger" and choice["verdict"].status == "warn"
    one = _evidence(peaks=(0.0, 6.0), heights=(1.0, 0.5))
    fig, reasons = video_quality(one, _est(one), st)
    assert not fig["ambiguous"] and reasons == []


def test_verdicts_of_the_choice():
    st = SyncSettings()
    ev = _evidence()
    none = choose_offset(_est(ev), None, None, st)
    assert none["chosen"] == "video" and none["verdict"].ok and set(none["candidates"]) == {"video"}
    wrong = choose_offset(_est(ev), None, TAU + 0.030, st)
    assert wrong["chosen"] == "video" and wrong["verdict"].status == "ok"   # recorded, with a sound video
    assert f"{TAU + 0.030:.5f} s" in wrong["verdict"].reasons[0] and f"{TAU:.5f} s" in wrong["verdict"].reasons[0]
    right = choose_offset(_est(ev, TAU + 0.0002), None, TAU, st)
    assert right["chosen"] == "trigger" and right["offset_s"] == TAU and right["verdict"].ok
    failed = choose_offset(None, "no segment in view", TAU, st)
    assert failed["chosen"] == "trigger" and "unchecked" in failed["verdict"].reasons[0]
    few = _evidence(F=12)
    kept = choose_offset(_est(few), None, TAU, st)  # too few frames to confirm the trigger: kept, but a warn
    assert kept["chosen"] == "trigger" and kept["verdict"].status == "warn"
    assert "cannot confirm" in kept["verdict"].reasons[0] and "min_frames" in kept["verdict"].reasons[0]


@pytest.mark.parametrize("board_mm, chosen", [(10.0, "trigger"), (0.5, "video")])
def test_a_mapping_error_at_the_arm_bounds_what_the_video_can_overrule(board_mm, chosen):
    """Frames that agree to 0.05 ms make the resampling test sure of any gap (issue 51: "as well in 0 of 4000
    block resamples"), but an error of the mapping where the arm is, common to every frame, is not in them: a
    still arm seen 10 mm off (the board check) moves a segment crossing itself at 0.5 m/s by up to 20 ms. A
    trigger 4 ms from the video's offset is kept then, with a note saying why, and overruled where the arm is
    seen 0.5 mm off (1 ms); the chosen offset's uncertainty holds the systematic bound."""
    st = SyncSettings()
    ev = _evidence(jitter_ms=0.05)
    est = {**_est(ev), "board_check": {"residual_mm": board_mm}}
    choice = choose_offset(est, None, TAU + 0.004, st)
    video, trig = choice["candidates"]["video"], choice["candidates"]["trigger"]
    assert trig["excess_p"] < trig["excess_p_needed"]          # the frames alone are sure
    assert video["speed_eff_m_s"] == pytest.approx(0.5)
    assert video["systematic_ms"] == pytest.approx(board_mm / 0.5)
    assert video["uncertainty_ms"] == pytest.approx(board_mm / 0.5 + 3 * video["standard_error_ms"])
    assert choice["chosen"] == chosen and choice["verdict"].ok
    note = choice["verdict"].reasons[0]
    assert "of 4000 block resamples" not in note and "no resampling of the frames sees" in note
    if chosen == "trigger":
        assert "is kept" in note and trig["beyond_video_uncertainty"] is False
        assert choice["uncertainty_ms"] == pytest.approx(4.0 + video["uncertainty_ms"], rel=1e-3)
    else:
        assert "overruled" in note and choice["uncertainty_ms"] == video["uncertainty_ms"]


def test_a_board_pose_shift_the_strips_follow_is_no_systematic_error():
    """The board check found the still arm 20 mm off as one rigid shift, beyond what the intrinsics explain (its
    cause: the board pose): the strips follow that shift, so only the features' scatter about it (0.4 mm) bounds
    the mapping's error at the arm, not the 20 mm; a trigger 4 ms off is overruled then."""
    st = SyncSettings()
    ev = _evidence(jitter_ms=0.05)
    bc = {"residual_mm": 20.0, "fit_rms_mm": 0.4, "likely_cause": "board_pose"}
    choice = choose_offset({**_est(ev), "board_check": bc}, None, TAU + 0.004, st)
    assert choice["candidates"]["video"]["mapping_error_mm"] == pytest.approx(0.4)
    assert choice["chosen"] == "video"
    weak = choose_offset({**_est(ev), "board_check": {**bc, "likely_cause": "intrinsics"}}, None, TAU + 0.004, st)
    assert weak["candidates"]["video"]["mapping_error_mm"] == pytest.approx(20.0) and weak["chosen"] == "trigger"
