"""The ur-rtde backend against a recording stand-in for ur_rtde's RTDE interfaces.

The stand-in is a fake UR arm: its actual joints follow the servoJ command with a
first-order lag, its controller clock advances one period per waitPeriod, and it can
publish stale packages (a repeated timestamp) like a receive thread that fell behind.
"""
import json
import sys

import numpy as np
import pandas as pd
import pytest

from stringcast.core.arm import JointLimitError, motion_window
from stringcast.core import ConfigError
from stringcast.execute.executor import execute
from stringcast.core import ExecutorSettings
from stringcast.execute.ur_rtde import StartPostureError, URMapping, URSettings
from stringcast.core.files import write_json
from stringcast.core.joint_log import read_joint_table, write_joint_table

UPRIGHT = np.radians([0.0, -90.0, 0.0, -90.0, 0.0, 0.0])  # UR's straight-up pose


class FakeArm:
    """A UR arm's joints and controller clock; the control/receive stand-ins share it."""

    def __init__(self, q6, rate=500.0, tau=0.008, t0=4321.0, stall_every=0, fail=None):
        self.q = np.array(q6, float)          # the true joints
        self.t = t0                           # the controller clock
        self.pub_q, self.pub_t = self.q.copy(), self.t   # the last published package
        self.cmd = self.q.copy()
        self.dt, self.alpha = 1.0 / rate, 1.0 - np.exp(-1.0 / (rate * tau))
        self.stall_every, self.cycles = stall_every, 0
        self.fail = fail or {}                # {"servoJ": (call_no, exception)}, ...
        self.calls = []                       # every method called, in order
        self.constructed = 0

    def record(self, name, *args):
        self.calls.append((name, args))
        n = sum(1 for c in self.calls if c[0] == name)
        if name in self.fail and self.fail[name][0] == n:
            raise self.fail[name][1]

    def names(self):
        return [c[0] for c in self.calls]


class FakeControl:
    def __init__(self, arm):
        self.arm = arm

    def initPeriod(self):
        self.arm.record("initPeriod")
        return self.arm.cycles

    def servoJ(self, q, speed, acceleration, time, lookahead_time, gain):
        self.arm.record("servoJ", list(q), speed, acceleration, time, lookahead_time, gain)
        assert len(q) == 6 and all(isinstance(v, float) for v in q)
        self.arm.cmd = np.array(q, float)
        return True

    def waitPeriod(self, t_start):
        self.arm.record("waitPeriod", t_start)
        a = self.arm
        a.q += a.alpha * (a.cmd - a.q)
        a.t += a.dt
        a.cycles += 1
        if not (a.stall_every and a.cycles % a.stall_every == 0):
            a.pub_q, a.pub_t = a.q.copy(), a.t

    def moveJ(self, q, speed, acceleration):
        self.arm.record("moveJ", list(q), speed, acceleration)
        a = self.arm
        a.q = np.array(q, float)
        a.cmd, a.pub_q = a.q.copy(), a.q.copy()
        a.t += 2.0
        a.pub_t = a.t
        return True

    def servoStop(self):
        self.arm.record("servoStop")

    def stopScript(self):
        self.arm.record("stopScript")

    def disconnect(self):
        self.arm.record("disconnect_control")


class FakeReceive:
    def __init__(self, arm):
        self.arm = arm

    def getActualQ(self):
        self.arm.record("getActualQ")
        return self.arm.pub_q.tolist()

    def getTimestamp(self):
        self.arm.record("getTimestamp")
        return float(self.arm.pub_t)

    def disconnect(self):
        self.arm.record("disconnect_receive")


def factory(arm):
    def interfaces(robot_ip, rate_hz):
        arm.constructed += 1
        arm.calls.append(("construct", (robot_ip, rate_hz)))
        return FakeControl(arm), FakeReceive(arm)
    return interfaces


def _motion(campaign, tmp_path, T=0.4, amp=0.3, q0=(0.6, -0.4, -0.2)):
    arm = campaign.arm
    t = np.arange(int(round(T * arm.controller_rate)) + 1) / arm.controller_rate
    s = t / T
    q = np.asarray(q0) + (amp * (10 * s**3 - 15 * s**4 + 6 * s**5))[:, None] * np.array([1.0, -0.5, 0.3])
    path = tmp_path / "motion.csv"
    write_joint_table(path, t, q)
    write_json(path.with_suffix(".json"), {"T_s": T})
    return path, t, q


def _arm_at(campaign, config, q_planar, base=0.3, wrist2=1.2, wrist3=-0.4, **kw):
    held = np.array([base, 0.0, 0.0, 0.0, wrist2, wrist3])
    m = URSettings.from_settings(ExecutorSettings(), campaign.arm).mapping
    return FakeArm(m.to_ur(np.asarray(q_planar, float), held), rate=campaign.arm.controller_rate, **kw)


def _n_cmd(config, campaign, n_motion):
    rate = campaign.arm.controller_rate
    e = ExecutorSettings()
    return n_motion + round(e.pre_roll_s * rate) + round(e.post_roll_s * rate)


def test_default_mapping_matches_ur_joint_frames(campaign, config, settings):
    """UR's upright pose is planar (90, 0, 0) deg; all-zero is the arm flat with the wrist link down."""
    m = URSettings.from_settings(settings.executor, campaign.arm).mapping
    np.testing.assert_allclose(m.to_planar(UPRIGHT), np.radians([90.0, 0.0, 0.0]), atol=1e-12)
    np.testing.assert_allclose(m.to_planar(np.zeros(6)), np.radians([0.0, 0.0, -90.0]), atol=1e-12)
    # lifting the shoulder (negative UR angle) raises the elbow: planar +y
    from stringcast.core.arm import forward_kinematics
    up = forward_kinematics(campaign.arm, m.to_planar(np.radians([0, -30, 0, 0, 0, 0])))
    assert up[1, 1] > 0
    held = np.arange(6.0)
    q6 = m.to_ur(np.array([0.1, 0.2, 0.3]), held)
    np.testing.assert_allclose(q6[[0, 4, 5]], held[[0, 4, 5]])
    np.testing.assert_allclose(m.to_planar(q6), [0.1, 0.2, 0.3])
    with pytest.raises(ConfigError, match="joint_map"):
        URMapping(np.array([1, 1, 3]), -np.ones(3), np.zeros(3))
    with pytest.raises(ConfigError, match="gain"):
        URSettings.from_settings(ExecutorSettings.from_mapping({"ur": {"gain": 5}}), campaign.arm)


def test_out_of_limit_motion_never_touches_the_arm(tmp_path, campaign, config, settings):
    motion, t, q = _motion(campaign, tmp_path, T=0.2, amp=1.5)  # far beyond the speed limit
    arm = _arm_at(campaign, config, q[0])
    with pytest.raises(JointLimitError, match="speed"):
        execute(motion, "ur-rtde", tmp_path / "trial_1", campaign, settings.executor, config, robot_ip="10.0.0.2",
                interfaces=factory(arm))
    assert arm.constructed == 0 and arm.calls == []
    assert not (tmp_path / "trial_1").exists()


def test_start_posture_too_far_refused_before_servoj(tmp_path, campaign, config, settings):
    motion, t, q = _motion(campaign, tmp_path)
    arm = _arm_at(campaign, config, q[0] + np.array([0.0, 0.05, 0.0]))   # 0.05 rad > 0.02 tolerance
    with pytest.raises(StartPostureError, match="--move-to-start"):
        execute(motion, "ur-rtde", tmp_path / "trial_1", campaign, settings.executor, config, robot_ip="10.0.0.2",
                interfaces=factory(arm))
    names = arm.names()
    assert "servoJ" not in names and "moveJ" not in names and "servoStop" not in names
    assert "stopScript" in names                              # the control script is released
    assert not (tmp_path / "trial_1").exists()                # nothing moved, nothing recorded


def test_full_play_logs_every_cycle(tmp_path, campaign, config, settings):
    motion, t, q = _motion(campaign, tmp_path)
    arm = _arm_at(campaign, config, q[0] + 0.01, stall_every=97)   # within tolerance; stale packages
    held0 = arm.q[[0, 4, 5]].copy()
    out = tmp_path / "trial_1"
    info = execute(motion, "ur-rtde", out, campaign, settings.executor, config, robot_ip="10.0.0.2", interfaces=factory(arm))
    K = _n_cmd(config, campaign, len(t))
    rate = campaign.arm.controller_rate
    n_settle = round(0.2 * rate)   # the default unlogged settle ramp
    names = arm.names()
    assert names[0] == "construct" and arm.calls[0][1] == ("10.0.0.2", rate)
    assert info["settle_samples"] == n_settle
    assert names.count("servoJ") == names.count("initPeriod") == names.count("waitPeriod") == n_settle + K
    # each cycle is initPeriod, servoJ, ..., waitPeriod in that order
    cyc = [n for n in names if n in ("initPeriod", "servoJ", "waitPeriod")]
    assert cyc == ["initPeriod", "servoJ", "waitPeriod"] * (n_settle + K)
    assert names.index("servoStop") > max(i for i, n in enumerate(names) if n == "servoJ")
    assert names.index("stopScript") > names.index("servoStop")
    # servoJ arguments: held joints fixed, mapped joints = the command, period and gains from config
    m = URSettings.from_settings(settings.executor, campaign.arm).mapping
    sent = np.array([c[1][0] for c in arm.calls if c[0] == "servoJ"])
    np.testing.assert_allclose(sent[:, [0, 4, 5]], np.repeat(held0[None], n_settle + K, axis=0))
    settle = m.to_planar(sent[:n_settle])   # a smooth ramp from where the arm was onto the start
    np.testing.assert_allclose(settle[-1], q[0], atol=1e-12)
    assert np.max(np.abs(np.diff(settle, axis=0))) < 0.01 * 2 / n_settle
    k0 = round(ExecutorSettings().pre_roll_s * rate)
    np.testing.assert_allclose(m.to_planar(sent[n_settle + k0:n_settle + k0 + len(q)]), q, atol=1e-12)
    _, _, _, dt, look, gain = next(c[1] for c in arm.calls if c[0] == "servoJ")
    assert dt == pytest.approx(1 / rate) and look == 0.1 and gain == 300
    # the log: the workflow's reader, strictly increasing t from 0, stale packages dropped
    tj, qj = read_joint_table(out / "joints.csv")
    df = pd.read_csv(out / "joints.csv")
    assert list(df.columns) == ["t_s", "q1_rad", "q2_rad", "q3_rad", "q1_cmd_rad", "q2_cmd_rad", "q3_cmd_rad"]
    assert tj[0] == 0 and np.all(np.diff(tj) > 0)
    doc = json.loads((out / "executor.json").read_text())
    assert doc["partial"] is False and doc["joints"] == "joints.csv"
    assert doc["duplicate_stamps_dropped"] > 0 and len(tj) == K - doc["duplicate_stamps_dropped"] == doc["rows"]
    assert doc["max_period_s"] == pytest.approx(2 / rate)
    assert info["rows"] == len(tj)
    # the measured joints follow the command with the arm's lag, and the motion is found where it was sent
    qc = df[["q1_cmd_rad", "q2_cmd_rad", "q3_cmd_rad"]].to_numpy()
    assert np.max(np.abs(qj - qc)) < 0.05 and np.max(np.abs(qj[-1] - q[-1])) < 1e-3
    start, stop = motion_window(tj, qj)
    assert start == pytest.approx(k0 / rate, abs=0.03) and stop == pytest.approx(k0 / rate + t[-1], abs=0.06)
    assert (out / "motion.csv").exists() and (out / "motion.json").exists()
    assert not (out / "joints.partial.csv").exists()


def test_move_to_start(tmp_path, campaign, config, settings):
    motion, t, q = _motion(campaign, tmp_path)
    arm = _arm_at(campaign, config, q[0] + np.array([0.2, -0.1, 0.1]))
    execute(motion, "ur-rtde", tmp_path / "trial_1", campaign, settings.executor, config, robot_ip="ip", move_to_start=True,
            interfaces=factory(arm))
    names = arm.names()
    assert names.count("moveJ") == 1 and names.index("moveJ") < names.index("servoJ")
    target, speed, _ = next(c[1] for c in arm.calls if c[0] == "moveJ")
    m = URSettings.from_settings(settings.executor, campaign.arm).mapping
    np.testing.assert_allclose(m.to_planar(np.array(target)), q[0], atol=1e-12)
    assert speed <= 0.3
    assert json.loads((tmp_path / "trial_1" / "executor.json").read_text())["moved_to_start"] is True
    # a start posture whose straight joint path to the start leaves the limits: no moveJ
    arm = _arm_at(campaign, config, np.array([campaign.arm.q_min[0] - 0.2, q[0, 1], q[0, 2]]))
    with pytest.raises(StartPostureError, match="pendant"):
        execute(motion, "ur-rtde", tmp_path / "trial_2", campaign, settings.executor, config, robot_ip="ip", move_to_start=True,
                interfaces=factory(arm))
    assert "moveJ" not in arm.names() and "servoJ" not in arm.names() and "stopScript" in arm.names()


# call numbers 100 settle cycles + 300 and 1 start check + 300: mid-motion (pre-roll is 150 cycles)
@pytest.mark.parametrize("where, call, exc", [("servoJ", 400, KeyboardInterrupt()),
                                              ("getActualQ", 301, RuntimeError("RTDE lost"))])
def test_interrupt_or_error_stops_arm_and_leaves_partial_log(tmp_path, campaign, config, where, call, exc, capsys, settings):
    motion, t, q = _motion(campaign, tmp_path)
    arm = _arm_at(campaign, config, q[0], fail={where: (call, exc)})
    out = tmp_path / "trial_1"
    with pytest.raises(type(exc)):
        execute(motion, "ur-rtde", out, campaign, settings.executor, config, robot_ip="ip", interfaces=factory(arm))
    names = arm.names()
    i_stop = names.index("servoStop")
    assert names.index("stopScript") > i_stop
    assert "servoJ" not in names[i_stop:]                       # nothing sent after the stop
    assert not (out / "joints.csv").exists()                    # never taken for a recorded trial
    tj, qj = read_joint_table(out / "joints.partial.csv")
    assert np.all(np.diff(tj) > 0) and tj[0] == 0
    assert len(tj) == 299 and "q1_cmd_rad" in pd.read_csv(out / "joints.partial.csv").columns
    doc = json.loads((out / "executor.json").read_text())
    assert doc["partial"] is True and doc["joints"] == "joints.partial.csv"
    assert type(exc).__name__ in doc["reason"]
    assert "joints.partial.csv" in capsys.readouterr().err
    # the trial can be played again into the same folder
    arm2 = _arm_at(campaign, config, q[0])
    execute(motion, "ur-rtde", out, campaign, settings.executor, config, robot_ip="ip", interfaces=factory(arm2))
    assert (out / "joints.csv").exists()


def test_stop_goes_on_when_servostop_fails(tmp_path, campaign, config, settings):
    motion, t, q = _motion(campaign, tmp_path)
    arm = _arm_at(campaign, config, q[0], fail={"servoJ": (10, KeyboardInterrupt()),
                                                 "servoStop": (1, RuntimeError("no connection"))})
    with pytest.raises(KeyboardInterrupt):
        execute(motion, "ur-rtde", tmp_path / "t", campaign, settings.executor, config, robot_ip="ip", interfaces=factory(arm))
    assert "stopScript" in arm.names()
    doc = json.loads((tmp_path / "t" / "executor.json").read_text())
    assert any("servoStop" in f for f in doc["stop_failures"])


def test_missing_ur_rtde_and_dry_run(tmp_path, campaign, config, monkeypatch, capsys, settings):
    motion, t, q = _motion(campaign, tmp_path)
    monkeypatch.setitem(sys.modules, "rtde_control", None)     # import fails as if not installed
    with pytest.raises(ConfigError, match=r"stringcast\[ur\]"):
        execute(motion, "ur-rtde", tmp_path / "trial_1", campaign, settings.executor, config, robot_ip="10.0.0.2")
    info = execute(motion, "ur-rtde", tmp_path / "trial_2", campaign, settings.executor, config, dry_run=True)
    out = capsys.readouterr().out
    assert info["dry_run"] and "shoulder" in out and "wrist1" in out
    assert not (tmp_path / "trial_2").exists()


def test_cli_execute_ur_rtde(tmp_path, campaign, config, monkeypatch, capsys):
    from stringcast.cli import main

    motion, t, q = _motion(campaign, tmp_path)
    camp = tmp_path / "campaign.yaml"
    camp.write_text("string: 1\ntarget: 1\n")
    args = ["execute", str(motion), "--backend", "ur-rtde", "--campaign", str(camp), "--out", str(tmp_path / "trial_1")]
    assert main(args + ["--dry-run"]) == 0
    assert "dry run" in capsys.readouterr().out
    monkeypatch.setitem(sys.modules, "rtde_control", None)
    assert main(args + ["--robot-ip", "10.0.0.2", "--move-to-start"]) == 2
    assert "pip install" in capsys.readouterr().err
