"""Joint motions (paper Section V): Bezier velocity curves, postures and motion files.

A motion is one joint-velocity Bezier curve per joint over [0, T]:

* T is snapped to the controller period (:func:`time_grid`).
* Eq. (1): N = ``motion.n_control_points`` heights V_k = V_{k-1} + alpha_k T/N,
  alpha_k ~ U(-alpha_max, alpha_max), V_0 = 0, at times t_k = k T / N. Our choice:
  the last height V_N is forced to 0 so that the arm stops at T. The velocity is
  the degree-N Bezier curve of (V_0 = 0, V_1, ..., V_N = 0); because the t_k are
  evenly spaced the curve's time is linear in its parameter, v(t) = B(t / T).
  ``control_points`` (J, N) holds V_1..V_N.
* Angles: cumulative trapezoid of v at the controller rate from the initial
  posture q0.
* Initial postures: random within the joint limits, rejecting those whose grasp
  or hanging string (length L straight down) would come within
  ``motion.floor_margin_m`` of the floor.

Limits: :func:`valid_curves` keeps the curves the arm can play from a given posture.

Files: ``motion.csv`` (t_s, q1_rad..) and its ``motion.json`` sidecar, read here
(:func:`read_motion`, :func:`read_motion_json`) and written by
:func:`stringcast.plan.planning.write_motion`. The search for a motion that hits the
target is :mod:`stringcast.plan.planning`.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.special import comb

from stringcast.core import (Campaign, ConfigError, DataError, MotionSettings, check_limits, forward_kinematics,
                             read_joint_table, read_json, read_motion_sidecar)


@dataclass(frozen=True)
class Motion:
    """A planned joint motion sampled at the controller rate.

    Attributes:
        t: (K,) s from 0 at the controller period. q: (K, J) rad.
        T: motion time, s (t[-1]). control_points: (J, N) Bezier heights V_1..V_N, rad/s
            ((J, 0) when unknown, e.g. a motion file from elsewhere). q0: (J,) rad.
    """

    t: np.ndarray
    q: np.ndarray
    T: float
    control_points: np.ndarray
    q0: np.ndarray

    def __post_init__(self):
        k = len(self.t)
        j = np.shape(self.q0)[0] if np.ndim(self.q0) == 1 else -1
        if np.shape(self.t) != (k,) or np.shape(self.q) != (k, j) or np.ndim(self.control_points) != 2 \
                or np.shape(self.control_points)[0] != j:
            raise ValueError(f"Motion: shapes t (K,), q (K, J), control_points (J, N), q0 (J,) expected; got "
                             f"{np.shape(self.t)}, {np.shape(self.q)}, {np.shape(self.control_points)}, "
                             f"{np.shape(self.q0)}")
        if not self.T > 0:
            raise ValueError(f"Motion: T must be > 0, got {self.T}")


# ---------------------------------------------------------------------------
# Curves (eq. 1)
# ---------------------------------------------------------------------------
def sample_control_points(rng: np.random.Generator, T: float, n_joints: int, n_control: int, alpha_max: float,
                          size: int) -> np.ndarray:
    """Eq. (1) heights V_1..V_N: (size, J, N) rad/s, V_N forced to 0."""
    alpha = rng.uniform(-alpha_max, alpha_max, (size, n_joints, n_control))
    v = np.cumsum(alpha * (T / n_control), axis=-1)
    v[..., -1] = 0.0
    return v


def bezier_velocity(control_points: np.ndarray, T: float, t: np.ndarray) -> np.ndarray:
    """Bezier velocity of (V_0 = 0, V_1..V_N) at times t (S,): (..., S, J) for control_points (..., J, N)."""
    cp = np.asarray(control_points, float)
    n = cp.shape[-1]
    heights = np.concatenate([np.zeros(cp.shape[:-1] + (1,)), cp], axis=-1)  # (..., J, N+1)
    s = np.clip(np.asarray(t, float) / T, 0.0, 1.0)[:, None]
    k = np.arange(n + 1)
    basis = comb(n, k) * s ** k * (1.0 - s) ** (n - k)  # (S, N+1) Bernstein
    return np.swapaxes(heights @ basis.T, -1, -2)


def time_grid(T: float, rate: float) -> tuple[np.ndarray, float]:
    """Controller-rate samples over [0, T]: t (K,) and T snapped to a whole number of periods."""
    k = max(2, int(round(T * rate)))
    return np.arange(k + 1) / rate, k / rate


def joint_paths(control_points: np.ndarray, T: float, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Angle change from q0 and velocity: dq, qd (..., K, J) for control_points (..., J, N)."""
    t, _ = time_grid(T, rate)
    qd = bezier_velocity(control_points, T, t)
    # the trapezoid rule summed from 0, as scipy.integrate.cumulative_trapezoid(qd, t, axis=-2, initial=0)
    # computes it (the same operations, so the same bits; tests/plan hold it to SciPy's): importing
    # scipy.integrate loads SciPy's optimizers too, 0.25 s of every plan job
    steps = np.diff(t)[:, None] * (qd[..., 1:, :] + qd[..., :-1, :]) / 2.0
    dq = np.concatenate([np.zeros(qd.shape[:-2] + (1, qd.shape[-1])), np.cumsum(steps, axis=-2)], axis=-2)
    return dq, qd


LIMIT_MARGIN = 1e-3
"""Planned motions use at most (1 - LIMIT_MARGIN) of the speed and acceleration limits: the executor
re-checks the file after its 9-digit CSV rounding, which moves finite-difference accelerations."""


def valid_curves(arm, control_points: np.ndarray, T: float, rate: float, postures: np.ndarray,
                 rng: np.random.Generator) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, int]]:
    """The control-point sets whose motion fits the arm's limits from one of the given postures.

    A fast vectorised test first (speed and acceleration of every curve, and the box of
    initial postures that keeps the angle change inside the position limits); each survivor
    then takes a random posture inside its box and is checked in full by
    :func:`stringcast.core.arm.check_limits` (positions, speed and acceleration at
    (1 - :data:`LIMIT_MARGIN`) of the limits, floor).

    Args:
        arm: :class:`stringcast.core.specs.ArmSpec`.
        control_points: (B, J, N) rad/s, V_1..V_N per joint (eq. (1)).
        T: duration, s (on the controller grid, :func:`time_grid`).
        rate: controller rate, Hz.
        postures: (P, J) rad, candidate initial postures q0.
        rng: picks the posture among those that fit.

    Returns:
        A list of (control_points (J, N), q0 (J,), q (K, J) rad, posture index) for the sets that fit;
        empty when none does.
    """
    dq, qd = joint_paths(control_points, T, rate)
    qdd = np.gradient(qd, 1.0 / rate, axis=-2)
    ok = np.all(np.max(np.abs(qd), axis=-2) <= arm.qd_max, axis=-1)
    ok &= np.all(np.max(np.abs(qdd), axis=-2) <= arm.qdd_max, axis=-1)
    lo, hi = arm.q_min - dq.min(axis=-2), arm.q_max - dq.max(axis=-2)     # (B, J) the q0 that keep q inside
    ok &= np.all(lo <= hi, axis=-1)
    out = []
    for b in np.nonzero(ok)[0]:
        fits = np.nonzero(np.all((postures >= lo[b] - 1e-12) & (postures <= hi[b] + 1e-12), axis=1))[0]
        if len(fits) == 0:
            continue
        i = int(rng.choice(fits))
        q = postures[i] + dq[b]
        rep = check_limits(arm, q, 1.0 / rate)
        if rep.ok and max(rep.velocity.max(), rep.acceleration.max()) <= 1.0 - LIMIT_MARGIN:
            out.append((control_points[b], postures[i], q, i))
    return out


# ---------------------------------------------------------------------------
# Postures
# ---------------------------------------------------------------------------
def postures_ok(campaign: Campaign, q0: np.ndarray, margin: float, box: np.ndarray | None = None,
                clearance: float = 0.0) -> np.ndarray:
    """For postures q0 (..., J): within limits, arm above the floor, the hanging string
    (L straight down from the grasp) above floor + margin, and, if ``box`` ((2, 2) m:
    [[x_min, x_max], [y_min, y_max]]) is given, the grasp inside it; with ``clearance`` > 0
    (m), the hanging string below its first ``clearance`` at least that far from every
    link's and the gripper's centre line. Returns bool (...).

    The box and the clearance keep the start posture where the camera sees the hanging
    string, so the estimation starts from the tracked rest state (config
    ``motion.start_grasp_box_mm``, ``motion.hang_clearance_mm``): a string hanging across
    the arm (a gripper pointing up, the string down over the wrist) is hidden behind it
    in the picture, and would lie on it in reality, which neither model has."""
    arm = campaign.arm
    q0 = np.asarray(q0, float)
    pts = forward_kinematics(arm, q0)
    inside = np.all((q0 >= arm.q_min) & (q0 <= arm.q_max), axis=-1)
    arm_up = np.min(pts[..., 1:, 1], axis=-1) >= arm.floor_y + margin
    string_up = pts[..., -1, 1] - campaign.string.length >= arm.floor_y + margin
    ok = inside & arm_up & string_up
    if clearance > 0:
        g = pts[..., -1, :]
        top = g - [0.0, clearance]
        bottom = g - [0.0, campaign.string.length]
        ok &= _vertical_clearance(top, bottom, pts) >= clearance
    if box is not None:
        g = pts[..., -1, :]
        ok &= (g[..., 0] >= box[0][0]) & (g[..., 0] <= box[0][1]) & (g[..., 1] >= box[1][0]) & (g[..., 1] <= box[1][1])
    return ok


def _vertical_clearance(top: np.ndarray, bottom: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Distance (...,) m between the vertical segments top -> bottom (..., 2) (same x) and the
    polyline pts (..., P, 2): 0 where they cross, else the least point-to-segment distance."""
    a, b = pts[..., :-1, :], pts[..., 1:, :]                           # (..., P-1, 2) arm segments
    x, y0, y1 = top[..., None, 0], bottom[..., None, 1], top[..., None, 1]
    # crossing: the arm segment spans x, and meets it within [y0, y1]
    dx = b[..., 0] - a[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        w = (x - a[..., 0]) / dx
        y_at = a[..., 1] + w * (b[..., 1] - a[..., 1])
    cross = (w >= 0) & (w <= 1) & (y_at >= y0) & (y_at <= y1)

    def point_seg(p, s0, s1):                                          # point (..., k, 2) to segments
        d = s1 - s0
        t = np.clip(np.sum((p - s0) * d, -1) / np.maximum(np.sum(d * d, -1), 1e-18), 0, 1)
        return np.linalg.norm(s0 + t[..., None] * d - p, axis=-1)

    ends = np.minimum(point_seg(top[..., None, :], a, b), point_seg(bottom[..., None, :], a, b))
    vt, vb = top[..., None, :], bottom[..., None, :]
    arm_ends = np.minimum(point_seg(a, vt, vb), point_seg(b, vt, vb))
    return np.where(cross, 0.0, np.minimum(ends, arm_ends)).min(axis=-1)


def start_box(motion: MotionSettings) -> np.ndarray | None:
    """``motion.start_grasp_box_mm`` as (2, 2) m, or None when not set."""
    box = motion.start_grasp_box_mm
    return None if box is None else np.asarray(box, float) / 1000


def posture_ok(campaign: Campaign, q0: np.ndarray, margin: float) -> bool:
    """:func:`postures_ok` for one posture (J,)."""
    return bool(postures_ok(campaign, q0, margin))


def sample_postures(campaign: Campaign, rng: np.random.Generator, count: int, margin: float,
                    max_tries: int = 100000, box: np.ndarray | None = None, clearance: float = 0.0) -> np.ndarray:
    """(count, J) random initial postures, uniform within the joint limits, passing :func:`postures_ok`.

    Raises:
        ConfigError: if fewer than ``count`` are found in ``max_tries`` draws.
    """
    arm = campaign.arm
    found = np.zeros((0, arm.n_joints))
    for _ in range(0, max_tries, 5000):
        q0 = rng.uniform(arm.q_min, arm.q_max, (5000, arm.n_joints))
        found = np.vstack([found, q0[postures_ok(campaign, q0, margin, box, clearance)]])
        if len(found) >= count:
            return found[:count]
    raise ConfigError(f"arm {arm.name}: no initial posture keeps a {campaign.string.length * 1000:.0f} mm string "
                      f"above the floor (floor_y {arm.floor_y * 1000:.0f} mm + margin {margin * 1000:.0f} mm)"
                      + ("" if box is None else f" with the grasp inside start_grasp_box_mm {np.round(box * 1000).tolist()}")
                      + (f", hanging {clearance * 1000:.0f} mm clear of the arm" if clearance > 0 else ""))


# ---------------------------------------------------------------------------
# Motion files
# ---------------------------------------------------------------------------
def read_motion_json(path: Path, n_joints: int, rate: float) -> Motion:
    """Rebuild the planned :class:`Motion` from a ``motion.json`` sidecar (q0, T, control points;
    :func:`stringcast.core.read_motion_sidecar`, which raises DataError naming the file)."""
    q0, T, cp = read_motion_sidecar(path, n_joints)
    dq, _ = joint_paths(cp, T, rate)
    t, T = time_grid(T, rate)
    return Motion(t=t, q=q0 + dq, T=T, control_points=cp, q0=q0)


def read_motion(csv: Path, json: Path | None = None) -> Motion:
    """Read ``motion.csv`` (and its sidecar, ``json`` or ``motion.json`` beside it if present).

    Without a sidecar, T = t[-1], q0 = q[0] and control_points is (J, 0).

    Raises:
        DataError: unreadable files, or t not starting at 0.
    """
    t, q = read_joint_table(csv, "motion.csv")
    if abs(t[0]) > 1e-9:
        raise DataError(f"{csv}: a motion file starts at t_s = 0, got {t[0]}")
    json = Path(json) if json else Path(csv).with_suffix(".json")
    cp, q0, T = np.zeros((q.shape[1], 0)), q[0], float(t[-1])
    if json.exists():
        doc = read_json(json, mapping=True)
        try:
            cp = np.asarray(doc.get("control_points_rad_s", cp), float).reshape(q.shape[1], -1)
            q0 = np.asarray(doc.get("q0_rad", q0), float)
            T = float(doc.get("T_s", T))
        except (TypeError, ValueError) as exc:
            raise DataError(f"{json}: control_points_rad_s must be {q.shape[1]} x N, q0_rad {q.shape[1]} values and "
                            f"T_s a number ({exc})") from exc
    return Motion(t=t, q=q, T=T, control_points=cp, q0=q0)
