"""The inertial-response check tells a string that feels the grasp's acceleration from one that does not.

Each case builds its own recording: a rigid pendulum (the tracked points along it) hanging from a grasp
that casts 0.4 m sideways in 0.8 s while the hand turns, integrated by SciPy either in the world
(gravity and the grasp's pseudo-force) or in the hand's frame without that frame's inertial forces
(the field recording of issue 52 behaves so).
"""
import numpy as np
import pytest
from scipy import optimize
from scipy.integrate import solve_ivp

from stringcast.estimate.inertia import MIN_EXCITATION, inertial_response, string_response
from stringcast.estimate.verdict import INERTIA_SHARE_MAX, likely_cause
from stringcast.core import EstimationSettings

G, L, N = 9.81, 0.35, 8
CLAMP_PSI0 = 0.3   # rad: the clamp's rest direction from the hand's


def _hand(t, amplitude=0.4, duration=0.8, turn=0.6, turn_in_step=False):
    """Grasp x, y (m), hand angle (rad) at t and their second derivatives: a minimum-jerk cast from t = 0.3 s;
    the hand turns out and back (sin^2 of the cast's phase), or with the cast's own profile (``turn_in_step``)."""
    s = np.clip((t - 0.3) / duration, 0.0, 1.0)
    moving = (t > 0.3) & (t < 0.3 + duration)
    p = 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5
    pdd = np.where(moving, (60 * s - 180 * s ** 2 + 120 * s ** 3) / duration ** 2, 0.0)
    if turn_in_step:
        r, rdd = p, pdd
    else:
        r, rdd = np.sin(np.pi * s) ** 2, np.where(moving, 2 * np.pi ** 2 * np.cos(2 * np.pi * s) / duration ** 2, 0.0)
    hand = np.stack([amplitude * p, 0.5 + 0.1 * amplitude * p, -1.0 + turn * r], -1)
    acc = np.stack([amplitude * pdd, 0.1 * amplitude * pdd, turn * rdd], -1)
    return hand, acc


def _recording(inertial=True, amplitude=0.4, noise_m=0.0, dropout=False, seed=0, turn_in_step=False, clamp=0.0):
    """(frame_t, tracked (F, N, 2), valid, hand_t, hand) of the pendulum (module doc), frames at 1 kHz.

    ``clamp`` (1/s^2): a torsion spring pulling the pendulum towards the hand's direction turned by
    CLAMP_PSI0 (a string held stiffly by its grasp), in the world frame; it starts at rest in equilibrium."""
    c = 0.3
    phi0 = _hand(np.array([0.0]))[0][0, 2]
    th0 = -np.pi / 2 if not clamp else optimize.brentq(
        lambda th: -G * np.cos(th) / L - clamp * (th - phi0 - CLAMP_PSI0), -np.pi, 0.0)

    def f(t, y):
        th, om = y
        _, acc = _hand(np.array([t]), amplitude, turn_in_step=turn_in_step)
        ax, ay, phidd = acc[0]
        if inertial:    # world frame: gravity and the grasp's pseudo-force (and the clamp's spring)
            spring = clamp * (th - _hand(np.array([t]))[0][0, 2] - CLAMP_PSI0) if clamp else 0.0
            return [om, ((-G - ay) * np.cos(th) + ax * np.sin(th)) / L - spring - c * om]
        # the hand's frame, its inertial forces left out: the angle turns with the hand
        return [om, -G * np.cos(th) / L - c * (om - 0.0) + phidd]

    frame_t = np.arange(0.0, 2.5, 1e-3)
    sol = solve_ivp(f, (0, 2.5), [th0, 0.0], t_eval=frame_t, max_step=1e-3, rtol=1e-8, atol=1e-10)
    th = sol.y[0]
    hand_t = np.arange(0.0, 2.5, 2e-3)
    hand, _ = _hand(hand_t, amplitude, turn_in_step=turn_in_step)
    g, _ = _hand(frame_t, amplitude, turn_in_step=turn_in_step)
    r = (np.arange(1, N + 1) * L / N)[None, :, None]
    tracked = g[:, None, :2] + r * np.stack([np.cos(th), np.sin(th)], -1)[:, None, :]
    rng = np.random.default_rng(seed)
    tracked = tracked + rng.normal(0.0, noise_m, tracked.shape)
    valid = np.ones(tracked.shape[:2], bool)
    if dropout:   # 10 % of the frames lost in 30 ms gaps, and a tip swapped for a wrong point now and then
        for start in rng.choice(len(frame_t) - 30, 8, replace=False):
            valid[start:start + 30] = False
        bad = rng.choice(len(frame_t), 20, replace=False)
        tracked[bad, -1] += 0.05
    return frame_t, tracked, valid, hand_t, hand


def test_a_pendulum_in_air_answers_the_grasp_acceleration_as_a_pendulum():
    fig = string_response(*_recording(noise_m=0.001, dropout=True))
    assert fig["inertia_share"] == pytest.approx(1.0, abs=0.2)
    assert fig["swing_period_s"] == pytest.approx(2 * np.pi * np.sqrt(L / G), rel=0.05)
    assert len(fig["points"]) >= 2


def test_a_string_carried_in_the_hand_frame_has_no_inertial_share_and_turns_with_the_hand():
    fig = string_response(*_recording(inertial=False, noise_m=0.001, dropout=True))
    assert fig["inertia_share"] is not None and abs(fig["inertia_share"]) < INERTIA_SHARE_MAX / 2
    assert fig["rotation_coupling"] == pytest.approx(1.0, abs=0.2)


@pytest.mark.parametrize("clamp", [10.0, 28.0, 100.0, 1000.0])
def test_a_string_held_stiffly_by_its_grasp_is_never_called_a_recording_fault(clamp):
    """A clamp's spring towards the hand's direction, at 0.36-36 times gravity's g / L, is physics the
    check leaves out: its share is then gravity's part of the restoring, g / L over g / L + clamp (0.74 at
    the weakest), or, where the spring rivals gravity and the balance no longer holds, unstated. Never
    under INERTIA_SHARE_MAX, so a stiffly held real string is not blamed on its recording."""
    fig = string_response(*_recording(noise_m=0.001, clamp=clamp))
    expected = (G / L) / (G / L + clamp)
    assert fig["inertia_share"] is None or fig["inertia_share"] == pytest.approx(expected, abs=0.15)
    assert fig["inertia_share"] is None or fig["inertia_share"] >= INERTIA_SHARE_MAX


def test_a_gentle_motion_states_no_share():
    frame_t, tracked, valid, hand_t, hand = _recording(amplitude=0.02)
    out = inertial_response(frame_t, tracked, valid, hand_t, hand, N - 1)
    assert out["excitation"] < MIN_EXCITATION and out["inertia_share"] is None


def test_a_hand_turning_in_step_with_the_cast_states_no_share():
    """Turning and sideways acceleration with one time profile cannot be told apart: the share's standard
    error says so instead of a number that noise decides."""
    for inertial in (True, False):
        fig = string_response(*_recording(inertial=inertial, noise_m=0.001, turn_in_step=True))
        assert fig["inertia_share"] is None


def test_too_few_tracked_frames_state_nothing_and_bad_shapes_raise():
    frame_t, tracked, valid, hand_t, hand = _recording()
    valid[:] = False
    assert string_response(frame_t, tracked, valid, hand_t, hand)["inertia_share"] is None
    with pytest.raises(ValueError, match="tracked"):
        inertial_response(frame_t, tracked[:, :, :1], valid, hand_t, hand, 0)
    with pytest.raises(ValueError, match="point"):
        inertial_response(frame_t, tracked, valid, hand_t, hand, N)


def _fig(share, points=(4, 8)):
    return {"error_share": 0.13, "error_median_mm": 68.0, "null_error_median_mm": 45.0, "skill": -0.5,
            "length_mm": 520.0, "valid_share": 0.9, "inertia_share": share, "inertia_points": list(points),
            "rotation_coupling": 1.0, "swing_period_s": 1.08}


def test_the_verdict_names_the_recording_only_where_the_model_would_be_blamed():
    est = EstimationSettings()
    cause, why = likely_cause(_fig(0.03), est, {})
    assert cause == "recording" and "3%" in why and "gripper's frame" in why
    assert likely_cause(_fig(0.9), est, {})[0] == "model"
    assert likely_cause(_fig(0.03, points=(8,)), est, {})[0] == "model"      # one chord is not enough
    offset = _fig(0.03) | {"offset_gain": 0.3, "bias_mm": [60.0, 0.0], "shift_gain": 1.0, "best_shift_frames": 0}
    assert likely_cause(offset, est, {})[0] == "geometry"                  # a mapping fault comes first
