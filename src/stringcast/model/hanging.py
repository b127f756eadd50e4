"""The string hanging at rest from a fixed hand: the model's static equilibrium (the planner's start
state; docs/string_model.md, "Initial state"), found by dynamic relaxation of the model's own equations
(:func:`stringcast.model.kernels.settle`)."""
from __future__ import annotations

import math

import numpy as np

from . import kernels as _k
from .string_model import G, _batch, _f64, _scalars


def _relaxation(relax: float | None, g: float, n: int, l0: float, dt: float) -> tuple[float, int]:
    """The dynamic relaxation's damping, 1/s (default 2 sqrt(g / (n l0)), about critical for the
    pendulum mode), and its rest test's interval in steps (every millisecond of simulated time):
    one definition for the planner's equilibrium."""
    if relax is None:
        relax = 2.0 * math.sqrt(max(g, 1e-9) / (n * l0))
    return float(relax), max(1, int(round(1e-3 / dt)))


def straight_hanging(coeffs, mu, hand_pose, l0, n, *, g: float = G) -> np.ndarray:
    """Points 1..n straight down from the hand, each segment stretched by its load.

    Segment s carries the weight of points s..n, g sum_j mu_j, so its length is
    l0 + g sum_{j>=s} mu_j / k_s. Exact equilibrium when the hand spring's rest
    direction points down; the start of :func:`hanging_equilibrium`. Returns (n, 2) m.
    """
    c, m = _batch(coeffs, mu, int(n))
    load = g * np.cumsum(m[0][::-1])[::-1]
    lengths = l0 + load / c[0, 0]
    hp = _f64(hand_pose, "hand_pose", 1, 3)
    return np.stack([np.full(int(n), hp[0]), hp[1] - np.cumsum(lengths)], axis=1)


def hanging_equilibrium(coeffs, mu, hand_pose, l0, psi0, n, dt=1e-4, tol=1e-4, t_max=20.0,
                        *, g: float = G, max_stretch: float = 3.0, relax: float | None = None):
    """Static equilibrium of the string hanging from a fixed hand.

    Starts straight down (segments stretched by their load, :func:`straight_hanging`)
    and runs the model with the hand fixed, with an added mass-proportional damping
    -relax * v (dynamic relaxation; it vanishes at rest, so the rest state is the
    model's own), until every speed is below ``tol`` and every acceleration below
    ``tol * max(relax, 1)`` (checked every millisecond of simulated time).

    Parameters
    ----------
    coeffs : ndarray, (10,)
        Coefficients (Table 2 units).
    mu : ndarray, (n,)
        Relative masses.
    hand_pose : ndarray, (3,)
        The fixed hand, (x m, y m, phi rad).
    l0 : float
        Rest segment length, m.
    psi0 : float
        Rest direction in the hand frame, rad.
    n : int
        Points.
    dt : float
        Time step, s.
    tol : float
        Speed below which the string is at rest, m/s.
    t_max : float
        Longest settling run, s.
    g, max_stretch : float
        As in :func:`simulate_batch`.
    relax : float, optional
        The relaxation's damping, 1/s; default 2 sqrt(g / (n l0)) (about critical for the pendulum mode).

    Returns
    -------
    ndarray, (n, 2)
        Positions of points 1..n at rest, m.

    Raises
    ------
    RuntimeError
        The string blows up, or is still moving after ``t_max``.
    """
    c, m = _batch(coeffs, mu, int(n))
    hp = _f64(hand_pose, "hand_pose", 1, 3)
    l0, dt, lmax = _scalars(l0, dt, max_stretch)
    p0 = straight_hanging(c[0], m[0], hp, l0, n, g=g)
    relax, check = _relaxation(relax, g, n, l0, dt)
    pos, status = _k.settle(c[0], m[0], hp, p0, l0, float(psi0), dt, float(g), lmax,
                            relax, float(tol), float(t_max), check)
    if status == 1:
        top = np.linalg.norm(p0[0] - hp[:2]) / l0
        raise RuntimeError(
            f"hanging_equilibrium: the string blew up while settling (a segment beyond "
            f"{max_stretch} l0 or a non-finite value); under its own weight the top segment "
            f"is {top:.2f} l0 long (k_s = {c[0, 0]:g}, sum of mu = {m[0].sum():g})")
    if status == 2:
        raise RuntimeError(f"hanging_equilibrium: speeds still above {tol} m/s after {t_max} s")
    return pos
