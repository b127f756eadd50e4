"""Planar arm: forward kinematics, hand trajectories and joint-limit checks.

Convention (see ``config/config.yaml``): q_1 is link 1's angle from the robot's
+x axis, q_j (j > 1) is relative to link j-1, counter-clockwise positive; the
gripper continues the last link, so the hand angle is phi_h = sum_j q_j and the
grasp point p_0 = sum_j l_j e(sum_{i<=j} q_i) + gripper e(phi_h).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .specs import ArmSpec


class JointLimitError(ValueError):
    """A joint trajectory violates position, velocity or acceleration limits."""


def forward_kinematics(arm: ArmSpec, q: np.ndarray) -> np.ndarray:
    """Joint positions of the planar arm.

    Args:
        arm: the arm.
        q: (..., J) joint angles, rad.

    Returns:
        (..., J + 2, 2): base, each joint after it, and the grasp point (last), m.
    """
    q = np.asarray(q, dtype=float)
    if q.shape[-1] != arm.n_joints:
        raise ValueError(f"q has {q.shape[-1]} joints, arm {arm.name} has {arm.n_joints}")
    phi = np.cumsum(q, axis=-1)
    lengths = np.concatenate([arm.link_lengths, [arm.gripper]])
    phis = np.concatenate([phi, phi[..., -1:]], axis=-1)
    steps = np.stack([np.cos(phis), np.sin(phis)], axis=-1) * lengths[:, None]
    pts = np.cumsum(steps, axis=-2)
    base = np.zeros(q.shape[:-1] + (1, 2))
    return np.concatenate([base, pts], axis=-2)


def joints_at(t, t_j: np.ndarray, q_j: np.ndarray) -> np.ndarray:
    """Joint angles at times t (scalar or (...,) s) from a joint log t_j (K,) s, q_j (K, J) rad,
    by linear interpolation, held at the log's ends (``np.interp``): (..., J) rad."""
    t = np.asarray(t, float)
    return np.stack([np.interp(t, t_j, q_j[:, j]) for j in range(q_j.shape[1])], axis=-1)


def hand_pose(arm: ArmSpec, q: np.ndarray) -> np.ndarray:
    """Grasp point and hand angle: (..., 3) = (x_m, y_m, phi_h_rad) for q (..., J)."""
    pts = forward_kinematics(arm, q)
    phi = np.sum(np.asarray(q, float), axis=-1)
    return np.concatenate([pts[..., -1, :], phi[..., None]], axis=-1)


def joint_rates(q: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and acceleration by central differences: (K, J) each, rad/s, rad/s^2."""
    q = np.asarray(q, float)
    qd = np.gradient(q, dt, axis=0)
    qdd = np.gradient(qd, dt, axis=0)
    return qd, qdd


@dataclass(frozen=True)
class LimitReport:
    """The worst use of each limit: ratios to the limit (<= 1 is allowed), per joint."""

    position_low: np.ndarray
    position_high: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    floor_clearance_m: float

    @property
    def ok(self) -> bool:
        return bool(np.all(self.position_low <= 0) and np.all(self.position_high <= 0)
                    and np.all(self.velocity <= 1 + 1e-9) and np.all(self.acceleration <= 1 + 1e-9)
                    and self.floor_clearance_m >= 0)

    def describe(self) -> str:
        msgs = []
        for j in range(len(self.velocity)):
            if self.position_low[j] > 0:
                msgs.append(f"q{j + 1} goes {np.degrees(self.position_low[j]):.1f} deg below its minimum")
            if self.position_high[j] > 0:
                msgs.append(f"q{j + 1} goes {np.degrees(self.position_high[j]):.1f} deg above its maximum")
            if self.velocity[j] > 1 + 1e-9:
                msgs.append(f"q{j + 1} speed reaches {self.velocity[j]:.2f}x its limit")
            if self.acceleration[j] > 1 + 1e-9:
                msgs.append(f"q{j + 1} acceleration reaches {self.acceleration[j]:.2f}x its limit")
        if self.floor_clearance_m < 0:
            msgs.append(f"the arm goes {-self.floor_clearance_m * 1000:.0f} mm below the floor")
        return "; ".join(msgs) if msgs else "within all limits"


def check_limits(arm: ArmSpec, q: np.ndarray, dt: float) -> LimitReport:
    """Compare a sampled joint trajectory with the arm's limits.

    Args:
        q: (K, J) joint angles at a fixed period ``dt`` (s).

    Returns:
        A :class:`LimitReport`; ``report.ok`` is False if any limit is exceeded.
        Velocity and acceleration are by finite differences of the samples.
    """
    q = np.asarray(q, float)
    if q.ndim != 2 or q.shape[1] != arm.n_joints:
        raise ValueError(f"q must be (K, {arm.n_joints}), got {q.shape}")
    qd, qdd = joint_rates(q, dt) if len(q) > 2 else (np.zeros_like(q), np.zeros_like(q))
    pts = forward_kinematics(arm, q)
    return LimitReport(
        position_low=np.max(arm.q_min - q, axis=0),
        position_high=np.max(q - arm.q_max, axis=0),
        velocity=np.max(np.abs(qd), axis=0) / arm.qd_max,
        acceleration=np.max(np.abs(qdd), axis=0) / arm.qdd_max,
        floor_clearance_m=float(np.min(pts[:, 1:, 1]) - arm.floor_y),
    )


def assert_within_limits(arm: ArmSpec, q: np.ndarray, dt: float, source: str = "motion") -> None:
    """Raise :class:`JointLimitError` naming ``source`` if ``q`` breaks any limit."""
    rep = check_limits(arm, q, dt)
    if not rep.ok:
        raise JointLimitError(f"{source}: refused, outside the limits of arm {arm.name}: {rep.describe()}")


def motion_start(t: np.ndarray, q: np.ndarray, speed_threshold: float = 0.05) -> float:
    """Controller time at which a joint log starts to move.

    Args:
        t: (K,) s; q: (K, J) rad (a measured log: noise is smoothed over ~10 samples).
        speed_threshold: rad/s; the first sample where any joint's smoothed speed
            exceeds it marks the start.

    Returns:
        The start time in s (t[0] if the log moves from its first sample).

    Raises:
        ValueError: if the log never moves.
    """
    t = np.asarray(t, float)
    q = np.asarray(q, float)
    w = min(10, max(1, len(t) // 10))
    kernel = np.ones(w) / w
    qs = np.stack([np.convolve(q[:, j], kernel, mode="same") for j in range(q.shape[1])], axis=1)
    speed = np.max(np.abs(np.gradient(qs, t, axis=0)), axis=1)
    speed[: w] = speed[w]  # edge effects of the smoothing
    moving = np.nonzero(speed > speed_threshold)[0]
    if len(moving) == 0:
        raise ValueError(f"the joint log never moves (no joint exceeds {speed_threshold:.3g} rad/s)")
    return float(t[max(0, moving[0] - w // 2)])


def motion_window(t: np.ndarray, q: np.ndarray, speed_threshold: float = 0.05) -> tuple[float, float]:
    """Controller times (s) a joint log starts and stops moving: :func:`motion_start` run
    forwards and on the time-reversed log. t: (K,) s; q: (K, J) rad.

    Raises:
        ValueError: if the log never moves.
    """
    t = np.asarray(t, float)
    q = np.asarray(q, float)
    return motion_start(t, q, speed_threshold), -motion_start(-t[::-1], q[::-1], speed_threshold)
