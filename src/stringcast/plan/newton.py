"""The least change of the played motion that aims the corrected tip at the target's centre (an option,
``motion.newton_steps`` > 0; not the paper's).

The residual correction (:mod:`stringcast.plan.residual`) is first order: the model is wrong about the
next motion as it was about the played one, which holds near the played motion. The random
perturbation of Section V.B draws every control point up to +-``perturb`` rad/s from the played
one and keeps the candidate with the largest margin, often far from it, where the carried error
no longer holds. This step is the iterative-learning-control reading instead: Newton steps on the
corrected closest approach d(x) (the tip's, under the planning set, to the target minus the
residual; :func:`~stringcast.model.string_model.closest_approach_batch`) as a function of the control
points x = V_1..V_{N-1} (V_N and q0 kept), each the minimum-norm change that brings its linearisation
to zero,

    dx = -d(x) grad d / |grad d|^2,

grad d by forward differences of :data:`FD_STEP_RAD_S` (one numba batch per step). By the envelope
theorem grad d is the sensitivity of the tip at the closest approach along the miss, so the shift of
the closest approach's time as x changes is accounted for. The change from the played motion stays
within +-``perturb`` rad/s per control point (the perturbation's own box): a step that would leave it is
scaled back.
"""
from __future__ import annotations

import numpy as np

from .motion import Motion, joint_paths, valid_curves
from .prediction import Predictor

FD_STEP_RAD_S = 0.01
"""Forward-difference step of the control points for grad d, rad/s."""

HALVINGS = 4
"""A Newton step that does not bring the corrected tip closer is halved up to this many times."""

CONVERGED_M = 1e-3
"""Newton stops once the corrected closest approach is this close, m."""


def newton_perturbation(pl: Predictor, previous: Motion, p_init: np.ndarray, steps: int, perturb: float,
                        rng: np.random.Generator) -> list:
    """The played motion ``previous`` moved by Newton steps (module doc) towards a corrected tip through the
    target's centre.

    Args:
        pl: the plan's predictor, its residual correction set (:meth:`Predictor.set_residual`).
        previous: the played motion (q0 (J,), T, control_points (J, N) rad/s).
        p_init: (n, 2) m, the planning set's hanging equilibrium at ``previous.q0``.
        steps: Newton steps at most (fewer once d is within :data:`CONVERGED_M`).
        perturb: rad/s, the largest change of any control point from the played motion.
        rng: for :func:`~stringcast.plan.motion.valid_curves` (one posture: nothing is drawn).

    Returns:
        [] or one candidate as :func:`~stringcast.plan.motion.valid_curves` gives it (control points
        (J, N), q0 (J,), q (K, J), posture index 0); [] without a residual correction or control points,
        when the model blows up, or when the changed motion leaves the arm's limits.
    """
    cp0 = np.asarray(previous.control_points, float)
    if pl.residual is None or cp0.shape[1] < 2:
        return []
    shape = (cp0.shape[0], cp0.shape[1] - 1)
    x0 = cp0[:, :-1].ravel()
    x = x0.copy()
    d, grad = _distance_and_gradient(pl, previous, p_init, x, shape)
    for _ in range(int(steps)):
        if d is None or d < CONVERGED_M or not np.any(grad):
            break
        step = -d * grad / float(grad @ grad)
        for _ in range(HALVINGS + 1):                 # backtracking: a step must bring the tip closer
            x_new = x0 + _clip_box(x + step - x0, perturb)
            d_new, grad_new = _distance_and_gradient(pl, previous, p_init, x_new, shape)
            if d_new is not None and d_new < d:
                break
            step = step / 2
        else:
            break
        x, d, grad = x_new, d_new, grad_new
    if np.array_equal(x, x0):
        return []
    cp = np.concatenate([x.reshape(shape), cp0[:, -1:]], axis=1)
    return valid_curves(pl.arm, cp[None], previous.T, pl.rate, previous.q0[None], rng)


def _clip_box(change: np.ndarray, perturb: float) -> np.ndarray:
    """``change`` scaled back along itself until no component exceeds ``perturb`` in size."""
    big = float(np.max(np.abs(change)))
    return change if big <= perturb else change * (perturb / big)


def _distance_and_gradient(pl: Predictor, previous: Motion, p_init: np.ndarray, x: np.ndarray,
                           shape: tuple) -> tuple[float | None, np.ndarray | None]:
    """The corrected closest approach d m at control points x (J (N-1),) and its gradient (J (N-1),) m per
    rad/s; (None, None) when the model blows up on any of the runs."""
    xs = np.vstack([x, x + FD_STEP_RAD_S * np.eye(x.size)])                   # (1 + m, m)
    last = np.repeat(previous.control_points[None, :, -1:], len(xs), axis=0)
    cps = np.concatenate([xs.reshape(len(xs), *shape), last], axis=2)        # (1 + m, J, N)
    dq, _ = joint_paths(cps, previous.T, pl.rate)
    d, _, _, ok = pl.evaluate(previous.q0 + dq, previous.T, np.repeat(p_init[None], len(xs), axis=0))
    if not (np.all(ok) and np.all(np.isfinite(d))):
        return None, None
    return float(d[0]), (d[1:] - d[0]) / FD_STEP_RAD_S
