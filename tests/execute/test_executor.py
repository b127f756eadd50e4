"""Executor: limits checked before the backend is called, dry run, timing, overwrite refusal."""

import numpy as np
import pytest

from stringcast.core.arm import JointLimitError
from stringcast.core import ConfigError
from stringcast.execute.executor import build_command, execute
from stringcast.core.files import DataError, write_json
from stringcast.core.joint_log import read_joint_table, write_joint_table


@pytest.fixture
def fake_lab(monkeypatch):
    """A recording stand-in for stringcast_lab.run_trial (writes a joints.csv like the lab)."""
    calls = []

    def run_trial(t_cmd, q_cmd, campaign, config, out_dir, seed, motion_start_s):
        calls.append({"t": t_cmd, "q": q_cmd, "out": out_dir, "seed": seed, "start": motion_start_s})
        write_joint_table(out_dir / "joints.csv", t_cmd, q_cmd)
        return {"hit": False}

    monkeypatch.setattr("stringcast.execute.executor.virtual_lab_trial", lambda: run_trial)
    return calls


def _smooth_motion(campaign, T=0.4, amp=0.3):
    arm = campaign.arm
    t = np.arange(int(round(T * arm.controller_rate)) + 1) / arm.controller_rate
    s = t / T
    bump = amp * (10 * s**3 - 15 * s**4 + 6 * s**5)  # rest-to-rest, smooth
    q0 = np.array([0.6, -0.4, -0.2])
    return t, q0 + bump[:, None] * np.array([1.0, -0.5, 0.3])


def _write_motion(path, t, q):
    write_joint_table(path, t, q)
    write_json(path.with_suffix(".json"), {"T_s": float(t[-1])})
    return path


def test_a_motion_without_its_motion_json_is_refused_before_anything_moves(tmp_path, campaign, config, fake_lab,
                                                                           settings):
    t, q = _smooth_motion(campaign)
    motion = _write_motion(tmp_path / "motion.csv", t, q)
    motion.with_suffix(".json").unlink()
    with pytest.raises(DataError, match=r"motion.json: missing: .*planning the next motion reads it"):
        execute(motion, "virtual", tmp_path / "trial_1", campaign, settings.executor, config)
    assert fake_lab == [] and not (tmp_path / "trial_1").exists()


def test_the_command_line_says_what_it_played_and_where(tmp_path, campaign, config, fake_lab, capsys):
    from stringcast.cli import main

    t, q = _smooth_motion(campaign)
    motion = _write_motion(tmp_path / "motion.csv", t, q)
    (tmp_path / "campaign.yaml").write_text("string: 1\ntarget: 1\n")
    code = main(["execute", str(motion), "--out", str(tmp_path / "trial_1"), "--campaign", str(tmp_path / "campaign.yaml")])
    out = capsys.readouterr().out
    assert code == 0 and len(fake_lab) == 1
    assert f"executed {motion} on virtual: {len(fake_lab[0]['t'])} samples" in out and str(tmp_path / "trial_1") in out


def test_plays_motion_with_pre_and_post_roll(tmp_path, campaign, config, fake_lab, settings):
    t, q = _smooth_motion(campaign)
    motion = _write_motion(tmp_path / "motion.csv", t, q)
    out = tmp_path / "trial_1"
    info = execute(motion, "virtual", out, campaign, settings.executor, config, seed=7)
    assert len(fake_lab) == 1
    call = fake_lab[0]
    rate = campaign.arm.controller_rate
    pre, post = settings.executor.pre_roll_s, settings.executor.post_roll_s
    assert call["start"] == pytest.approx(pre, abs=0.5 / rate)
    assert len(call["t"]) == len(t) + round(pre * rate) + round(post * rate)
    np.testing.assert_allclose(np.diff(call["t"]), 1 / rate)
    k0 = round(pre * rate)
    np.testing.assert_allclose(call["q"][:k0], np.repeat(q[:1], k0, axis=0))
    np.testing.assert_allclose(call["q"][k0:k0 + len(q)], q)
    np.testing.assert_allclose(call["q"][-1], q[-1])
    assert call["seed"] == 7 and info["hit"] is False
    t2, q2 = read_joint_table(out / "motion.csv")
    np.testing.assert_allclose(q2, q, atol=1e-8)
    assert (out / "motion.json").exists()


def test_out_of_limit_motion_refused_before_backend(tmp_path, campaign, config, fake_lab, settings):
    t, q = _smooth_motion(campaign, T=0.2, amp=1.5)  # far beyond the speed limit
    motion = _write_motion(tmp_path / "motion.csv", t, q)
    with pytest.raises(JointLimitError, match="motion.csv"):
        execute(motion, "virtual", tmp_path / "trial_1", campaign, settings.executor, config)
    assert fake_lab == []
    assert not (tmp_path / "trial_1").exists()


def test_position_limit_refused(tmp_path, campaign, config, fake_lab, settings):
    t, q = _smooth_motion(campaign)
    q = q.copy()
    q[:, 0] += campaign.arm.q_max[0]  # start beyond the maximum
    motion = _write_motion(tmp_path / "motion.csv", t, q)
    with pytest.raises(JointLimitError, match="above its maximum"):
        execute(motion, "virtual", tmp_path / "trial_1", campaign, settings.executor, config)
    assert fake_lab == []


def test_dry_run_moves_nothing(tmp_path, campaign, config, fake_lab, capsys, settings):
    t, q = _smooth_motion(campaign)
    motion = _write_motion(tmp_path / "motion.csv", t, q)
    info = execute(motion, "virtual", tmp_path / "trial_1", campaign, settings.executor, config, dry_run=True)
    assert fake_lab == [] and info["dry_run"]
    assert not (tmp_path / "trial_1").exists()
    assert "dry run" in capsys.readouterr().out


def test_bad_timing_refused(tmp_path, campaign, config, fake_lab, settings):
    t, q = _smooth_motion(campaign)
    motion = _write_motion(tmp_path / "motion.csv", t + 0.01, q)
    with pytest.raises(DataError, match="starts at t_s = 0"):
        execute(motion, "virtual", tmp_path / "a", campaign, settings.executor, config)
    motion = _write_motion(tmp_path / "motion.csv", t * 2, q)  # 250 Hz
    with pytest.raises(DataError, match="controller period"):
        execute(motion, "virtual", tmp_path / "a", campaign, settings.executor, config)
    assert fake_lab == []


def test_refuses_to_overwrite_recorded_trial(tmp_path, campaign, config, fake_lab, settings):
    t, q = _smooth_motion(campaign)
    motion = _write_motion(tmp_path / "motion.csv", t, q)
    out = tmp_path / "trial_1"
    execute(motion, "virtual", out, campaign, settings.executor, config)
    with pytest.raises(DataError, match="joints.csv"):
        execute(motion, "virtual", out, campaign, settings.executor, config)
    assert len(fake_lab) == 1


def test_ur_rtde_and_unknown_backend(tmp_path, campaign, config, fake_lab, settings):
    t, q = _smooth_motion(campaign)
    motion = _write_motion(tmp_path / "motion.csv", t, q)
    with pytest.raises(ConfigError, match="--robot-ip"):
        execute(motion, "ur-rtde", tmp_path / "x", campaign, settings.executor, config)
    with pytest.raises(ConfigError, match="unknown backend"):
        execute(motion, "robot9000", tmp_path / "x", campaign, settings.executor, config)
    assert fake_lab == []


def test_build_command_shapes():
    q = np.linspace(0, 1, 11)[:, None] * np.ones((1, 3))
    t, qc, start = build_command(q, 500.0, 0.01, 0.02)
    assert qc.shape == (5 + 11 + 10, 3) and start == pytest.approx(0.01)
    assert t[0] == 0 and np.allclose(np.diff(t), 0.002)
