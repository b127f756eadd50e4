"""The executor's ``ur-rtde`` backend: play a command stream on a Universal Robots arm.

The planar arm of the config is three joints of a UR e-Series arm (shoulder-lift,
elbow, wrist-1 by default, ``executor.ur.joint_map``); the other three (base,
wrist-2, wrist-3) are held at the posture the arm has when the trial starts. A
planar angle and a UR joint angle are related per planar joint by

    q_planar = sign * q_ur + offset,        q_ur = sign * (q_planar - offset)

(``executor.ur.sign``, ``executor.ur.offset_deg``). The defaults, sign -1 and
offsets (0, 0, -90) deg, follow from UR's joint frames (the standard UR DH
parameters): with the base turned so that the upper arm at shoulder = 0 points
at the target (the planar +x), the shoulder, elbow and wrist-1 axes point along
-z of the planar frame, so a positive UR rotation is clockwise in the plane; at
wrist-1 = 0 the wrist-1 -> wrist-2 link (d5 = 99.7 mm on a UR5e, the planar arm's
third link) is at -90 deg to the forearm. UR's upright pose (0, -90, 0, -90, 0, 0)
deg is planar (90, 0, 0) deg: everything straight up. The gripper must be mounted
so the grasp point lies on the wrist-1 -> wrist-2 line, 150 mm beyond the wrist-2
axis (``arms.ur5e_planar.gripper_mm``).

Control follows ur_rtde's servoJ example (``RTDEControlInterface``,
``RTDEReceiveInterface``): each controller cycle ``t0 = initPeriod()``,
``servoJ(q6, speed, acceleration, 1/rate, lookahead_time, gain)``, read
``getTimestamp()`` and ``getActualQ()``, ``waitPeriod(t0)``; then ``servoStop()``
and ``stopScript()``. Before the command stream, an unlogged ``executor.ur.settle_s``
quintic ramp (servoJ, same loop) takes the arm from its actual posture (within
``executor.start_tolerance_rad`` of the start, or there after ``--move-to-start``'s
slow moveJ) onto the start exactly, so the filmed pre-roll is at rest. Ctrl-C or any error in the loop calls ``servoStop()`` and
``stopScript()`` first, then writes what was measured to ``joints.partial.csv``
with ``executor.json`` saying ``partial: true``, then re-raises. A partial log is
never named ``joints.csv``: the workflow finds trials by ``trial_*/joints.csv``
and the executor's overwrite guard keys on it, so a broken trial is never
processed as recorded and can be played again into the same folder.

The joint log's ``t_s`` is the controller's ``getTimestamp()`` minus its value in
the first cycle (the first command of the pre-roll: the clock of the command
stream); rows whose timestamp did not advance (the receive thread had no new
package) are dropped and counted, so ``t_s`` is strictly increasing.

Not tried on hardware: see README.md, "Executor on a real UR arm". The
interfaces are injectable (``interfaces``) so the tests drive a recording stand-in.
"""
from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from stringcast.core import (ArmSpec, ConfigError, ExecutorSettings, JointLimitError, check_limits, write_joint_table,
                             write_json)

UR_JOINTS = ("base", "shoulder", "elbow", "wrist1", "wrist2", "wrist3")
Interfaces = Callable[[str, float], "tuple[Any, Any]"]
"""``interfaces(robot_ip, rate_hz) -> (control, receive)``: ur_rtde's RTDEControlInterface
and RTDEReceiveInterface, or stand-ins with the same methods."""


class StartPostureError(JointLimitError):
    """The arm's current posture is too far from the motion's start, or cannot be left safely."""


@dataclass(frozen=True)
class URMapping:
    """Planar joints <-> a UR arm's six joints.

    Attributes:
        joint_map: (J,) int, the UR joint index (0 base .. 5 wrist-3) of each planar joint.
        sign: (J,) +-1; offset: (J,) rad; ``q_planar = sign * q_ur + offset``.
    """

    joint_map: np.ndarray
    sign: np.ndarray
    offset: np.ndarray

    def __post_init__(self):
        j = len(self.joint_map)
        if np.shape(self.sign) != (j,) or np.shape(self.offset) != (j,):
            raise ConfigError(f"executor.ur: joint_map, sign and offset_deg must have {j} entries each")
        if len(set(self.joint_map.tolist())) != j or np.any((self.joint_map < 0) | (self.joint_map > 5)):
            raise ConfigError(f"executor.ur.joint_map must be distinct UR joint indices 0..5, got {self.joint_map.tolist()}")
        if not np.all(np.abs(self.sign) == 1):
            raise ConfigError(f"executor.ur.sign must be +1 or -1 per joint, got {self.sign.tolist()}")

    def to_planar(self, q6: np.ndarray) -> np.ndarray:
        """(..., 6) UR joint angles, rad -> (..., J) planar angles, rad."""
        return self.sign * np.asarray(q6, float)[..., self.joint_map] + self.offset

    def to_ur(self, q: np.ndarray, held: np.ndarray) -> np.ndarray:
        """(..., J) planar angles + (6,) posture of the held joints, rad -> (..., 6) UR angles, rad."""
        q = np.asarray(q, float)
        q6 = np.broadcast_to(np.asarray(held, float), q.shape[:-1] + (6,)).copy()
        q6[..., self.joint_map] = self.sign * (q - self.offset)
        return q6


@dataclass(frozen=True)
class URSettings:
    """The backend's settings (``executor.ur`` and ``executor.start_tolerance_rad``), SI units, built by
    :meth:`from_settings`: their defaults are declared once, in :class:`~stringcast.core.ExecutorSettings`."""

    mapping: URMapping
    lookahead_time_s: float
    gain: float
    servo_speed: float                # rad/s, servoJ's speed argument (unused by URScript's servoj)
    servo_acceleration: float         # rad/s^2, likewise
    start_tolerance_rad: float
    move_speed: float                 # rad/s, moveJ to the start (--move-to-start)
    move_acceleration: float          # rad/s^2
    settle_s: float                   # unlogged servoJ ramp from the actual posture to the start

    def __post_init__(self):
        if not 0.03 <= self.lookahead_time_s <= 0.2:
            raise ConfigError(f"executor.ur.lookahead_time_s must be in [0.03, 0.2] (URScript servoj), got {self.lookahead_time_s}")
        if not 100 <= self.gain <= 2000:
            raise ConfigError(f"executor.ur.gain must be in [100, 2000] (URScript servoj), got {self.gain}")
        if not 0 <= self.settle_s <= 2.0:
            raise ConfigError(f"executor.ur.settle_s must be in [0, 2] s, got {self.settle_s}")
        if not (0 < self.start_tolerance_rad <= 0.2 and 0 < self.move_speed <= 1.0 and 0 < self.move_acceleration <= 2.0):
            raise ConfigError("executor: start_tolerance_rad must be in (0, 0.2], ur.move_to_start_speed_rad_s in (0, 1] "
                              "and ur.move_to_start_acceleration_rad_s2 in (0, 2]")

    @classmethod
    def from_settings(cls, executor: ExecutorSettings, arm: ArmSpec) -> URSettings:
        """Read ``executor.ur`` and ``executor.start_tolerance_rad`` for ``arm``.

        The default mapping (joint_map (1, 2, 3), sign -1, offsets (0, 0, -90) deg: a UR5e's
        shoulder-lift, elbow and wrist-1) is cut to an arm of fewer joints, the last offset kept
        at -90 deg.

        Raises:
            ConfigError: wrong lengths, out-of-range values.
        """
        u, default = executor.ur, ExecutorSettings().ur
        j = arm.n_joints
        fitted = {"joint_map": [1, 2, 3][:j], "sign": [-1.0] * j, "offset_deg": ([0.0] * j)[:-1] + [-90.0]}
        pick = {k: (fitted[k] if tuple(u[k]) == tuple(default[k]) else u[k]) for k in fitted}
        try:
            mapping = URMapping(np.asarray(pick["joint_map"], dtype=int), np.asarray(pick["sign"], float),
                                np.radians(np.asarray(pick["offset_deg"], float)))
            if len(mapping.joint_map) != j:
                raise ConfigError(f"executor.ur.joint_map has {len(mapping.joint_map)} entries, arm {arm.name} has {j} joints")
            return cls(mapping, float(u["lookahead_time_s"]), float(u["gain"]),
                       float(u["servo_speed_rad_s"]), float(u["servo_acceleration_rad_s2"]),
                       float(executor.start_tolerance_rad), float(u["move_to_start_speed_rad_s"]),
                       float(u["move_to_start_acceleration_rad_s2"]), float(u["settle_s"]))
        except (TypeError, ValueError, KeyError) as exc:
            raise ConfigError(f"executor.ur: {exc}") from exc


def rtde_interfaces(robot_ip: str, rate_hz: float) -> tuple[Any, Any]:
    """Connect ur_rtde's ``RTDEControlInterface(ip, frequency)`` and ``RTDEReceiveInterface(ip, frequency)``.

    Raises:
        ConfigError: ``ur_rtde`` is not installed (``pip install stringcast[ur]``).
    """
    try:
        import rtde_control
        import rtde_receive
    except ImportError as exc:
        raise ConfigError("executor: the ur-rtde backend needs the ur_rtde package: "
                          "pip install 'stringcast[ur]'") from exc
    control = rtde_control.RTDEControlInterface(robot_ip, float(rate_hz))
    try:
        receive = rtde_receive.RTDEReceiveInterface(robot_ip, float(rate_hz))
    except BaseException:
        control.stopScript()
        raise
    return control, receive


def _check_start(arm: ArmSpec, settings: URSettings, q_now: np.ndarray, q0: np.ndarray, move_to_start: bool,
                 after_move: bool = False) -> bool:
    """True if a moveJ to the start is needed; raise StartPostureError if refused. q_now, q0: (J,) rad."""
    err = np.abs(q_now - q0)
    if np.max(err) <= settings.start_tolerance_rad:
        return False
    where = ", ".join(f"q{j + 1} {np.degrees(q_now[j]):.1f} deg (start {np.degrees(q0[j]):.1f})" for j in range(len(q0)))
    if not move_to_start:
        hint = "after moveJ; check executor.ur's joint_map/sign/offset_deg" if after_move else \
            "move it there (pendant) or pass --move-to-start"
        raise StartPostureError(f"ur-rtde: refused, the arm is {np.max(err):.3f} rad from the motion's start posture "
                                f"(tolerance {settings.start_tolerance_rad} rad): {where}; {hint}")
    # moveJ interpolates linearly in joint space: check positions and floor along that path
    path = q_now + np.linspace(0.0, 1.0, 50)[:, None] * (q0 - q_now)
    rep = check_limits(arm, path, 1e6)  # a huge dt: only positions and the floor matter here
    if not rep.ok:
        raise StartPostureError(f"ur-rtde: refused to moveJ to the start: the straight joint path from the current "
                                f"posture ({where}) leaves the limits: {rep.describe()}; move the arm by hand (pendant)")
    return True


def _settle_ramp(q_from: np.ndarray, q_to: np.ndarray, n: int) -> np.ndarray:
    """(n, J) rad: a rest-to-rest quintic from q_from to q_to (J,), ending on q_to (empty if n = 0).

    Commanding the start posture at once from up to ``start_tolerance_rad`` away would
    jerk the arm in the pre-roll, where the estimation expects the string at rest.
    """
    s = np.arange(1, n + 1) / max(n, 1)
    return q_from + (10 * s**3 - 15 * s**4 + 6 * s**5)[:, None] * (q_to - q_from)


def _stop(control: Any, receive: Any, servo: bool) -> list[str]:
    """servoStop (if servoing), stopScript, disconnect; every step tried, failures returned (never raised)."""
    failed = []
    steps = ((control, "servoStop"),) if servo else ()
    for obj, name in steps + ((control, "stopScript"), (receive, "disconnect"), (control, "disconnect")):
        try:
            getattr(obj, name)()
        except BaseException as exc:  # noqa: BLE001 - stopping goes on, even past a second Ctrl-C
            failed.append(f"{name}: {exc!r}")
    return failed


def _write_log(out_dir: Path, arm: ArmSpec, settings: URSettings, stamps: np.ndarray, q6: np.ndarray,
               q_cmd: np.ndarray, n: int, meta: dict) -> Path:
    """Write the first n measured rows (duplicates of the controller timestamp dropped) and executor.json."""
    partial = bool(meta["partial"])
    path = out_dir / ("joints.partial.csv" if partial else "joints.csv")
    keep = np.zeros(n, bool)
    last = -np.inf
    for k in range(n):
        if stamps[k] > last:
            keep[k], last = True, stamps[k]
    t = stamps[:n][keep] - (stamps[0] if n else 0.0)
    q = settings.mapping.to_planar(q6[:n][keep])
    held = [i for i in range(6) if i not in settings.mapping.joint_map]
    drift = np.max(np.abs(q6[:n][keep][:, held] - q6[0, held]), axis=0) if n else np.zeros(len(held))
    write_joint_table(path, t, q, {f"q{j + 1}_cmd_rad": q_cmd[:n][keep, j] for j in range(arm.n_joints)})
    meta.update(joints=path.name, rows=int(keep.sum()), duplicate_stamps_dropped=int(n - keep.sum()),
                max_period_s=float(np.max(np.diff(t))) if len(t) > 1 else None,
                held_joint_drift_rad={UR_JOINTS[i]: float(d) for i, d in zip(held, drift)},
                created=datetime.now(UTC).isoformat(timespec="seconds"))
    write_json(out_dir / "executor.json", meta)
    return path


def play_ur(t_cmd: np.ndarray, q_cmd: np.ndarray, arm: ArmSpec, settings: URSettings, out_dir: Path, robot_ip: str,
            move_to_start: bool = False, interfaces: Interfaces | None = None) -> dict:
    """Play a command stream on a UR arm with servoJ and log the measured joints.

    Args:
        t_cmd: (K,) s from 0 at the controller period (pre-roll, motion, post-roll).
        q_cmd: (K, J) planar joint angles, rad (already checked against the arm's limits).
        arm: the planar arm (its ``controller_rate`` is the servo rate, 500 Hz on e-Series).
        settings: the backend's settings (:meth:`URSettings.from_settings`).
        out_dir: the trial folder: ``joints.csv`` (or ``joints.partial.csv``) and ``executor.json``.
        robot_ip: the controller's address.
        move_to_start: moveJ (slowly) to the start posture if the arm is not within
            ``executor.start_tolerance_rad`` of it; otherwise refuse.
        interfaces: ``(robot_ip, rate_hz) -> (control, receive)``; default :func:`rtde_interfaces`.

    Returns:
        executor.json's dict (joints file, rows, duplicate stamps dropped, held joints, ...).

    Raises:
        ConfigError: ur_rtde missing, bad ``executor.ur`` settings.
        StartPostureError: the arm is not at the start (nothing sent but stopScript).
        RuntimeError: servoJ or moveJ refused by the controller (partial log written).
        KeyboardInterrupt: Ctrl-C; the arm was stopped and the partial log written.
    """
    t_cmd, q_cmd, out_dir = np.asarray(t_cmd, float), np.asarray(q_cmd, float), Path(out_dir)
    rate = float(arm.controller_rate)
    control, receive = (interfaces or rtde_interfaces)(robot_ip, rate)
    meta: dict = {"backend": "ur-rtde", "robot_ip": robot_ip, "partial": True, "reason": None,
                  "samples_commanded": len(t_cmd), "servoj_calls": 0, "moved_to_start": False,
                  "joint_map": {f"q{j + 1}": UR_JOINTS[i] for j, i in enumerate(settings.mapping.joint_map)},
                  "sign": settings.mapping.sign, "offset_rad": settings.mapping.offset,
                  "lookahead_time_s": settings.lookahead_time_s, "gain": settings.gain, "rate_hz": rate}
    K = len(t_cmd)
    stamps, q6_meas = np.zeros(K), np.zeros((K, 6))
    n = 0
    started = servoing = False
    try:
        q6_now = np.asarray(receive.getActualQ(), float)
        if _check_start(arm, settings, settings.mapping.to_planar(q6_now), q_cmd[0], move_to_start):
            started = True  # the arm moves from here on: any failure leaves a (partial) record
            target = settings.mapping.to_ur(q_cmd[0], q6_now)
            print(f"ur-rtde: moveJ to the start posture at {settings.move_speed} rad/s", file=sys.stderr)
            if control.moveJ(target.tolist(), settings.move_speed, settings.move_acceleration) is False:
                raise RuntimeError("ur-rtde: moveJ to the start posture was refused by the controller")
            meta["moved_to_start"] = True
            q6_now = np.asarray(receive.getActualQ(), float)
            _check_start(arm, settings, settings.mapping.to_planar(q6_now), q_cmd[0], False, after_move=True)
        meta["start_posture_ur_rad"] = {name: float(v) for name, v in zip(UR_JOINTS, q6_now)}
        settle = _settle_ramp(settings.mapping.to_planar(q6_now), q_cmd[0], round(settings.settle_s * rate))
        meta["settle_samples"] = len(settle)
        commands = settings.mapping.to_ur(np.concatenate([settle, q_cmd]), q6_now).tolist()  # built before the loop
        started = servoing = True
        dt, s, k0 = 1.0 / rate, settings, len(settle)
        for i, q6 in enumerate(commands):
            t0 = control.initPeriod()
            meta["servoj_calls"] += 1
            if control.servoJ(q6, s.servo_speed, s.servo_acceleration, dt, s.lookahead_time_s, s.gain) is False:
                raise RuntimeError(f"ur-rtde: servoJ refused by the controller at sample {i - k0} of the stream")
            if i >= k0:  # the settle ramp is not logged: t = 0 is the first command of the pre-roll
                k = i - k0
                stamps[k] = receive.getTimestamp()
                q6_meas[k] = receive.getActualQ()
                n = k + 1
            control.waitPeriod(t0)
    except BaseException as exc:
        failed = _stop(control, receive, servoing)
        if not started:
            raise
        meta.update(reason=f"{type(exc).__name__}: {exc}", stop_failures=failed)
        try:
            path = _write_log(out_dir, arm, settings, stamps, q6_meas, q_cmd, n, meta)
            print(f"ur-rtde: stopped after {n} of {K} samples ({type(exc).__name__}); partial joint log -> {path}"
                  f"{'; STOP FAILED: ' + '; '.join(failed) if failed else ''}", file=sys.stderr)
        except Exception as write_exc:  # noqa: BLE001 - the original error is the one to raise
            print(f"ur-rtde: could not write the partial joint log: {write_exc!r}", file=sys.stderr)
        raise
    failed = _stop(control, receive, True)
    meta.update(partial=False, stop_failures=failed)
    path = _write_log(out_dir, arm, settings, stamps, q6_meas, q_cmd, n, meta)
    print(f"ur-rtde: played {K} samples; joint log ({meta['rows']} rows) -> {path}"
          f"{'; STOP FAILED: ' + '; '.join(failed) if failed else ''}", file=sys.stderr)
    return meta
