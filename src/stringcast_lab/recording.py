"""What a lab physics hands the camera: the string's points and the arm's joints on an even clock.

Both physics write it, :func:`.physics.simulate` (the MuJoCo chain) and :func:`.rod.simulate_rod`
(the PyElastica Cosserat rod), so that the camera, the video and the ground truth do not learn
which of them ran. It holds data only, no physics.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Recording:
    """String points on the physics time grid.

    Attributes:
        t: (N,) s, controller-clock times of the samples (even, step dt).
        points: (N, S, 2) world (x, y) of the S = n_links + 1 sites, m (site k at arc k * l_link
            of the unstretched string, site 0 the grasp).
        q_arm: (N, J) the lagged (true) arm joint angles, rad.
        settle_speed: the largest point speed left after settling, m/s.
        steps_per_s: physics steps per wall second while recording.
        physics: which physics made it, ``"mujoco"`` or ``"elastica"``.
        detail: the physics' own figures for the ground truth (time step, material; JSON-able).

    Raises:
        ValueError: points not (N, S, 2) or q_arm without N rows.
    """

    t: np.ndarray
    points: np.ndarray
    q_arm: np.ndarray
    settle_speed: float
    steps_per_s: float
    physics: str = "mujoco"
    detail: dict = field(default_factory=dict)

    def __post_init__(self):
        n = len(self.t)
        if self.points.ndim != 3 or self.points.shape[0] != n or self.points.shape[2] != 2:
            raise ValueError(f"Recording: points must be ({n}, S, 2), got {self.points.shape}")
        if self.q_arm.shape[0] != n:
            raise ValueError(f"Recording: q_arm must have {n} rows, got {self.q_arm.shape}")

    def at(self, times: np.ndarray) -> np.ndarray:
        """(len(times), S, 2) site positions linearly interpolated in time, m."""
        times = np.asarray(times, float)
        dt = self.t[1] - self.t[0]
        f = np.clip((times - self.t[0]) / dt, 0, len(self.t) - 1 - 1e-9)
        i = np.floor(f).astype(int)
        w = (f - i)[:, None, None]
        return self.points[i] * (1 - w) + self.points[i + 1] * w

    def arm_at(self, times: np.ndarray) -> np.ndarray:
        """(len(times), J) lagged joint angles at ``times``, rad (linear interpolation)."""
        times = np.asarray(times, float)
        return np.stack([np.interp(times, self.t, self.q_arm[:, j]) for j in range(self.q_arm.shape[1])], axis=1)


def command_arrays(t_cmd, q_cmd, n_joints: int, caller: str) -> tuple[np.ndarray, np.ndarray]:
    """The controller's set-points as float arrays, checked: t_cmd (K,) s, q_cmd (K, n_joints) rad.

    The one check of :func:`.trial.run_trial` and of both physics' simulate functions; ``caller``
    names the function in the message.

    Raises:
        ValueError: t_cmd not (K,) strictly increasing with K >= 2, or q_cmd not (K, n_joints)
            (both shapes named).
    """
    t_cmd = np.asarray(t_cmd, float)
    q_cmd = np.asarray(q_cmd, float)
    if t_cmd.ndim != 1 or len(t_cmd) < 2 or np.any(np.diff(t_cmd) <= 0):
        raise ValueError(f"{caller}: t_cmd must be (K,) strictly increasing, K >= 2")
    if q_cmd.shape != (len(t_cmd), n_joints):
        raise ValueError(f"{caller}: q_cmd must be ({len(t_cmd)}, {n_joints}), got {q_cmd.shape}")
    return t_cmd, q_cmd
