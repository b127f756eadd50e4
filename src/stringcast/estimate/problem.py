"""The estimation problem of one trial (paper Section VI): what the fit compares, and E as a function of chi.

:func:`build_problem` turns the pipeline's files (``tracks.parquet`` and the measured joint
log, never the lab's ground truth) into an :class:`EstimationProblem`: the hand's path from
the forward kinematics of the measured joints, the rest state, and the tracked points 1..n
of the frames to compare. :func:`make_objective` is E (eqs. 4-6,
:func:`stringcast.estimate.evaluation.evaluation_value`) of the string model
(:func:`stringcast.model.string_model.simulate_batch`) driven along that path, for a batch of chi (eq. 2).

Choices where the paper is silent: the rest state p_init is the median of the
valid tracked positions over the last ``tracking.rest_frames`` frames before the
motion starts (:func:`stringcast.core.arm.motion_start`); points never valid there are
filled with l0 segments between the known points around them
(:func:`stringcast.model.rest_state.fill_rest_pose`, reported in ``Estimate.message``).
The simulation starts at the first of those frames and is compared at every later
frame up to the end of the joint log, or (``estimation.compare_after_motion_s``, our
option) up to that long after the arm stops (:func:`stringcast.core.arm.motion_window`).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Callable, Mapping

import numpy as np
import pandas as pd

from stringcast.core import (Campaign, DataError, EstimationSettings, EvaluationSettings, ModelSettings,
                             TrackingSettings, hand_pose, motion_start, motion_window, tracks_arrays)
from stringcast.model import decode
from stringcast.model import fill_rest_pose, simulate_batch
from .evaluation import evaluation_value, per_point_errors

MIN_REST_FRAMES = 3


@dataclass(frozen=True)
class EstimationProblem:
    """Everything the search needs, from the pipeline's files (never ground truth).

    Attributes:
        hand_t: (K,) s, controller clock; hand_t[0] == frame_t[0].
        hand: (K, 3) grasp point x, y (m) and hand angle phi_h (rad) from FK.
        p_init: (n, 2) m, the rest state at frame_t[0].
        frame_t: (F,) s, frame times compared (frame_t[0] = simulation start).
        frames: (F,) int, the frame numbers of ``frame_t``.
        tracked: (F, n, 2) m, tracked points 1..n (0 where not valid).
        valid: (F, n) bool.
        l0: rest segment length, m. psi0: rest direction in the hand frame, rad.
        dt: integration step, s. mass_groups: (n,) int (0 = mu_others).
        w: tip weighting of eq. (6).
        fallback_points: points (1..n) never valid at rest (p_init filled by ``fill_rest_pose``).
        t_motion_start: s, when the joint log starts to move.
        drag: the model's air drag law (``model.drag``: normal or isotropic).
        halvings: ``model.blowup_halvings``, a blown-up candidate's reruns at half the step.
    """

    hand_t: np.ndarray
    hand: np.ndarray
    p_init: np.ndarray
    frame_t: np.ndarray
    frames: np.ndarray
    tracked: np.ndarray
    valid: np.ndarray
    l0: float
    psi0: float
    dt: float
    mass_groups: np.ndarray
    w: float
    fallback_points: tuple = ()
    t_motion_start: float = 0.0
    drag: str = "isotropic"
    halvings: int = 0

    def __post_init__(self):
        k, f, n = len(self.hand_t), len(self.frame_t), len(self.p_init)
        shapes = {"hand_t": (k,), "hand": (k, 3), "p_init": (n, 2), "frame_t": (f,), "frames": (f,),
                  "tracked": (f, n, 2), "valid": (f, n), "mass_groups": (n,)}
        for name, shape in shapes.items():
            if np.shape(getattr(self, name)) != shape:
                raise ValueError(f"EstimationProblem.{name}: expected shape {shape}, got {np.shape(getattr(self, name))}")
        if k < 2 or f < 2:
            raise ValueError("EstimationProblem: needs at least two joint samples and two frames")
        if not np.all(np.isfinite(self.p_init)) or not np.all(np.isfinite(self.hand)):
            raise ValueError("EstimationProblem: p_init and hand must be finite")

    @property
    def n_points(self) -> int:
        return len(self.p_init)

    @property
    def n_groups(self) -> int:
        return int(self.mass_groups.max()) + 1



def build_problem(tracks_df: pd.DataFrame, t_joints: np.ndarray, q_joints: np.ndarray,
                  campaign: Campaign, model: ModelSettings, evaluation: EvaluationSettings,
                  estimation: EstimationSettings, tracking: TrackingSettings,
                  source: str = "tracks.parquet") -> EstimationProblem:
    """Assemble the estimation problem from tracked points and the measured joint log.

    Parameters
    ----------
    tracks_df : DataFrame
        Long table ``frame, t_s, point, x_m, y_m, valid`` ((n + 1) rows per frame; t_s s on the controller
        clock, x_m and y_m m in the robot frame, point 0 the grasp).
    t_joints, q_joints : ndarray, (K,) and (K, J)
        The measured joint log, s and rad.
    campaign : Campaign
        The resolved campaign (the string's n points and rest length, the arm).
    model, evaluation, estimation, tracking : settings
        The settings read (:class:`~stringcast.core.ModelSettings`: ``dt_s``, ``psi0_deg``, ``drag``;
        :class:`~stringcast.core.EvaluationSettings`: ``w``; :class:`~stringcast.core.EstimationSettings`:
        ``compare_after_motion_s``; :class:`~stringcast.core.TrackingSettings`: ``rest_frames``).
    source : str
        How messages name the tracks.

    Returns
    -------
    EstimationProblem
        The frames compared, the tracked points and their validity, the hand's path from the forward
        kinematics and the rest state the model starts from.

    Raises
    ------
    DataError
        Missing columns, a log that never moves, fewer than 3 frames at rest before the motion, fewer
        than 2 frames overlapping the joint log, or no valid tracked point to compare.
    """
    s, arm = campaign.string, campaign.arm
    n = s.n_points
    frames, t, xy, valid = tracks_arrays(tracks_df, n, source)
    t_joints = np.asarray(t_joints, float)
    q_joints = np.asarray(q_joints, float)
    try:
        t_move = motion_start(t_joints, q_joints)
    except ValueError as exc:
        raise DataError(f"joints.csv: {exc}") from exc
    rest = np.nonzero(t < t_move)[0]   # frames before a log that starts at the motion: the arm still (sync.json)
    n_rest = int(tracking.rest_frames)
    rest = rest[-max(n_rest, MIN_REST_FRAMES):]
    if len(rest) < MIN_REST_FRAMES:
        raise DataError(f"{source}: only {len(rest)} frames before the motion starts at t = {t_move:.3f} s "
                        f"(need {MIN_REST_FRAMES})")
    use = np.arange(rest[0], len(t))
    use = use[t[use] <= t_joints[-1]]
    window_s = estimation.compare_after_motion_s
    if window_s is not None:
        use = use[t[use] <= motion_window(t_joints, q_joints)[1] + float(window_s)]
    if len(use) < 2:
        raise DataError(f"{source}: fewer than two frames overlap the joint log")
    t0 = t[use[0]]
    q0 = np.array([np.interp(t0, t_joints, q_joints[:, j]) for j in range(q_joints.shape[1])])
    after = t_joints > t0
    hand_t = np.concatenate([[t0], t_joints[after]])
    hand = hand_pose(arm, np.vstack([q0, q_joints[after]]))

    known = np.full((n, 2), np.nan)
    for i in range(1, n + 1):
        ok = valid[rest, i]
        if ok.any():
            known[i - 1] = np.median(xy[rest[ok], i], axis=0)
    psi0 = np.radians(float(model.psi0_deg))
    p_init, fallback = fill_rest_pose(hand[0, :2], hand[0, 2] + psi0, known, s.l0)
    if not valid[use, 1:].any():
        raise DataError(f"{source}: no valid tracked point 1..{n} in the frames to compare")
    tracked = np.where(valid[use, 1:, None], xy[use, 1:], 0.0)
    return EstimationProblem(
        hand_t=hand_t, hand=hand, p_init=p_init, frame_t=t[use], frames=frames[use], tracked=tracked,
        valid=valid[use, 1:], l0=s.l0, psi0=psi0,
        dt=float(model.dt_s), mass_groups=s.mass_groups(),
        w=float(evaluation.w), fallback_points=tuple(fallback), t_motion_start=t_move, drag=str(model.drag),
        halvings=int(model.blowup_halvings))


def upstream_causes(upstream: Mapping[str, str | Path]) -> str:
    """The first reason of each earlier stage (``{stage: its JSON file}``: geometry, clock, tracking)
    whose verdict is not ok, joined for an error message (``""`` where none is, or a file cannot be
    read): why a problem could not be built, in the words of the stage that saw it (a string of another
    length than the campaign's: tracking's)."""
    said = []
    for stage, path in upstream.items():
        try:
            verdict = json.loads(Path(path).read_text()).get("verdict") or {}
        except (OSError, ValueError, AttributeError):
            continue
        reasons = verdict.get("reasons") if isinstance(verdict, dict) else None
        if isinstance(verdict, dict) and verdict.get("status") in ("warn", "fail") and reasons:
            said.append(str(reasons[0]) if str(reasons[0]).startswith(f"{stage}:") else f"{stage}: {reasons[0]}")
    return "; the earlier stages said: " + "; ".join(said) if said else ""


def build_problem_explained(tracks_df: pd.DataFrame, t_joints: np.ndarray, q_joints: np.ndarray,
                            campaign: Campaign, source: str | Path, upstream: Mapping[str, str | Path],
                            **settings) -> EstimationProblem:
    """:func:`build_problem` on ``source`` (a tracks.parquet), whose DataError carries the earlier stages'
    reasons (:func:`upstream_causes` of ``upstream``) where they say why no problem could be built."""
    try:
        return build_problem(tracks_df, t_joints, q_joints, campaign, **settings, source=str(source))
    except DataError as exc:
        raise DataError(f"{exc}{upstream_causes(upstream)}") from exc


def _simulate(problem: EstimationProblem, coeffs: np.ndarray, mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(B, F, n, 2) m and (B,) ok: B sets along the problem's hand path from p_init."""
    return simulate_batch(coeffs, mu, problem.hand_t, problem.hand[None], np.zeros(len(coeffs), np.int64),
                          problem.p_init[None], problem.l0, problem.psi0, problem.dt, problem.frame_t,
                          drag=problem.drag, halvings=problem.halvings)


def make_objective(problem: EstimationProblem, model: ModelSettings) -> Callable[[np.ndarray], np.ndarray]:
    """The evaluation value E (eqs. 4-6) of a batch of parameter sets, as a function of chi.

    Parameters
    ----------
    problem : EstimationProblem
        The trial's problem (:func:`build_problem`).
    model : ModelSettings
        The ranges chi is decoded over (eq. 2, :class:`~stringcast.core.ModelSettings`).

    Returns
    -------
    callable
        ``objective(chi)``: chi ndarray, (B, D) in [0, 1] (the ten coefficients, mu_others, one mu per
        special point) -> E ndarray, (B,) m; +inf where the simulation blew up.
    """

    def objective(chi: np.ndarray) -> np.ndarray:
        coeffs, mu = decode(chi, model, problem.mass_groups)
        b = len(chi)
        pos, ok = _simulate(problem, np.ascontiguousarray(coeffs), np.ascontiguousarray(mu))
        E = np.asarray(evaluation_value(problem.tracked, problem.valid, pos, problem.w), float).reshape(b)
        return np.where(np.asarray(ok, bool) & np.isfinite(E), E, np.inf)

    return objective


def simulate_fit(problem: EstimationProblem, model: ModelSettings, chi: np.ndarray) -> tuple[np.ndarray, bool]:
    """The model at one parameter set along the trial's hand path.

    Parameters
    ----------
    problem : EstimationProblem
        The trial's problem (:func:`build_problem`).
    model : ModelSettings
        The ranges chi is decoded over (eq. 2).
    chi : ndarray, (D,)
        The parameter set's exponents in [0, 1].

    Returns
    -------
    positions : ndarray, (F, n, 2)
        The simulated points at ``problem.frame_t``, m in the robot frame (NaN from a blow-up on).
    ok : bool
        Whether the run stayed valid.
    """

    coeffs, mu = decode(np.atleast_2d(chi), model, problem.mass_groups)
    pos, ok = _simulate(problem, np.ascontiguousarray(coeffs), np.ascontiguousarray(mu))
    return np.asarray(pos)[0], bool(np.asarray(ok)[0])


def point_errors(problem: EstimationProblem, model: ModelSettings, chi: np.ndarray) -> np.ndarray:
    """E_i of eq. (5) for one chi: (n,) m (:func:`stringcast.estimate.evaluation.per_point_errors`)."""

    pos, _ = simulate_fit(problem, model, chi)
    return np.asarray(per_point_errors(problem.tracked, problem.valid, pos), float)
