"""The arm's servo: joint lag behind the commanded set-points, and the hand's path."""
from __future__ import annotations

import numpy as np

from stringcast.core import ArmSpec, hand_pose


def servo_lag(t_cmd: np.ndarray, q_cmd: np.ndarray, lag_s: float,
              t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint angles of a servo following set-points through a critically damped 2nd-order filter.

    q'' = w^2 (u - q) - 2 w q', w = 2 / lag_s, u = the set-points interpolated
    linearly in time; starts at rest at q_cmd[0]. Integrated exactly for a
    piecewise-linear input (``scipy.signal.lsim``).

    Args:
        t_cmd: (K,) s, q_cmd: (K, J) rad set-points; lag_s: ramp lag, s (0: no lag).
        t: (N,) s, equally spaced output times starting at or after t_cmd[0].

    Returns:
        q, qd, qdd: (N, J) each, rad, rad/s, rad/s^2.
    """
    from scipy.signal import lsim

    t = np.asarray(t, float)
    u = np.stack([np.interp(t, t_cmd, q_cmd[:, j]) for j in range(q_cmd.shape[1])], axis=1)
    if lag_s <= 0:
        qd = np.gradient(u, t, axis=0)
        return u, qd, np.gradient(qd, t, axis=0)
    w = 2.0 / lag_s
    A = np.array([[0.0, 1.0], [-w * w, -2 * w]])
    B = np.array([[0.0], [w * w]])
    C = np.eye(2)
    D = np.zeros((2, 1))
    q = np.empty_like(u)
    qd = np.empty_like(u)
    for j in range(u.shape[1]):
        _, y, _ = lsim((A, B, C, D), u[:, j] - u[0, j], t - t[0], X0=[0.0, 0.0], interp=True)
        q[:, j] = y[:, 0] + u[0, j]
        qd[:, j] = y[:, 1]
    qdd = w * w * (u - q) - 2 * w * qd
    return q, qd, qdd


def hand_trajectory(arm: ArmSpec, q: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hand pose (x, y, phi_h), its velocity and acceleration on an even time grid.

    Args:
        q: (N, J) joint angles every ``dt`` s (a smooth, lagged trajectory).

    Returns:
        pose, vel, acc: (N, 3) each (m, m, rad and their rates); phi_h unwrapped.
    """
    pose = hand_pose(arm, q)
    pose[:, 2] = np.unwrap(pose[:, 2])
    vel = np.gradient(pose, dt, axis=0)
    acc = np.gradient(vel, dt, axis=0)
    return pose, vel, acc
