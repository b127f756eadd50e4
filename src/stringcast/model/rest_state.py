"""The model's initial state for estimation: the tracked rest pose with its gaps filled.

docs/string_model.md ("Initial state", estimation) starts the model at the tracked
positions of the frames before the motion. Points never tracked there (hidden by the
gripper, the arm, a weight) need a guess, and the guess must keep the model's segments
at their rest length l0: the model's axial spring is stiff (k_s up to 1e6 N/m/kg), so a
segment started 15 mm short kicks the chain at ~1e4 m/s^2, and the simulation, and E,
then depend on the parameters to the 6th digit (measured on a lab trial of string
type 2 whose points 1-3 were hidden at rest: a chi step of 1e-6 moved the simulated
points by 30 mm within 0.2 s; E is then too rugged to search).

Our choice: a run of hidden points between two known ones (the grasp point counts as
known) is filled with the regular polygon of l0 segments that joins them (points on a
circular arc), bent to the side that continues the segment above (at the grasp: the
string's rest direction in the hand, phi_h + psi0). Where the two known points are
l0 x (segments) apart or more, the points are spaced evenly on the straight line. Hidden
points below the last known one hang straight down, l0 apart.

A tracked point can be as much at odds with the model as a missing one: where the string
bends within one segment (a curl near the clamp: the labs' strings under a gripper pointing
left of down had one until their start state was fixed at 3c83cc8; a cord stored coiled can),
the chord from the point above to it is far shorter than l0, and the model's straight segment
starts compressed by as much. :func:`folded_points` names such points, so
that the fit check can say why the model moves at rest (``fit_check.rest_folded_points``).
:data:`FOLD_CHORD_SHARE` is the share the fit's verdict reads such a fold at.
"""
from __future__ import annotations

import math

import numpy as np

FOLD_CHORD_SHARE = 0.9
"""A chord under 0.9 l0: the string turns by about 90 deg within the segment (an arc of length l0
turning by theta spans l0 sin(theta / 2) / (theta / 2)). A string hanging within 25 deg of
straight down had its first chord at most 2.3 mm (8 % of l0) short in 36 fits of the stored loop
runs (state mode, both physics)."""


def fill_rest_pose(grasp: np.ndarray, direction0: float, known: np.ndarray, l0: float) -> tuple[np.ndarray, tuple]:
    """Rest positions of points 1..n with the untracked ones filled (module doc).

    Args:
        grasp: (2,) m, the grasp point p_0.
        direction0: rad, world angle of the string's rest direction at the grasp (phi_h + psi0).
        known: (n, 2) m, tracked rest positions, NaN where a point was never tracked at rest.
        l0: m, rest segment length.

    Returns:
        (p (n, 2) m, filled: the 1-based numbers of the points filled).

    Raises:
        ValueError: bad shapes or l0 <= 0.
    """
    known = np.asarray(known, float)
    if known.ndim != 2 or known.shape[1] != 2 or np.shape(grasp) != (2,) or not l0 > 0:
        raise ValueError(f"fill_rest_pose: expected grasp (2,), known (n, 2), l0 > 0; got {np.shape(grasp)}, "
                         f"{known.shape}, {l0}")
    n = len(known)
    ok = np.all(np.isfinite(known), axis=1)
    p = np.vstack([np.asarray(grasp, float), np.where(ok[:, None], known, np.nan)])   # row i = point i
    above_dir = float(direction0)
    i = 1
    while i <= n:
        if ok[i - 1]:
            d = p[i] - p[i - 1]
            above_dir = math.atan2(d[1], d[0]) if np.hypot(*d) > 0 else above_dir
            i += 1
            continue
        below = next((j for j in range(i, n + 1) if ok[j - 1]), None)
        if below is None:                                  # nothing known below: hang straight down
            for j in range(i, n + 1):
                p[j] = p[j - 1] + (0.0, -l0)
            break
        p[i:below] = _polygon(p[i - 1], p[below], below - i + 1, l0, above_dir)[1:-1]
        i = below
    return p[1:], tuple(int(j) for j in np.nonzero(~ok)[0] + 1)


def folded_points(grasp: np.ndarray, known: np.ndarray, l0: float, min_share: float) -> tuple:
    """Tracked rest points whose chord to the point above is shorter than ``min_share`` l0 (module doc).

    Walks down from the grasp point; a point closer than ``min_share * l0`` to the last point kept
    (the grasp for point 1) is named and skipped, so the next one is measured from the same kept
    point (two or more segments, which an arc of l0 segments can always join). Untracked (NaN)
    points are skipped and never named.

    Args:
        grasp: (2,) m, the grasp point p_0. known: (n, 2) m, tracked rest positions (NaN: not tracked).
        l0: m, rest segment length. min_share: in (0, 1], the shortest chord of one segment, over l0.

    Returns:
        The 1-based numbers of the folded points, ascending.

    Raises:
        ValueError: bad shapes, l0 <= 0 or min_share outside (0, 1].
    """
    known = np.asarray(known, float)
    if known.ndim != 2 or known.shape[1] != 2 or np.shape(grasp) != (2,) or not l0 > 0 or not 0 < min_share <= 1:
        raise ValueError(f"folded_points: expected grasp (2,), known (n, 2), l0 > 0, 0 < min_share <= 1; got "
                         f"{np.shape(grasp)}, {known.shape}, {l0}, {min_share}")
    last, last_i, folded = np.asarray(grasp, float), 0, []
    for i, p in enumerate(known, start=1):
        if not np.all(np.isfinite(p)):
            continue
        if i - last_i == 1 and np.hypot(*(p - last)) < min_share * l0:
            folded.append(i)
            continue
        last, last_i = p, i
    return tuple(folded)


def _polygon(a: np.ndarray, b: np.ndarray, m: int, l0: float, above_dir: float) -> np.ndarray:
    """(m + 1, 2): a, m - 1 points, b, joined by m equal segments: l0 on a circular arc where |b - a| < m l0
    (bulging to the side whose first segment is nearer ``above_dir``), else |b - a| / m on the line."""
    chord = b - a
    c = float(np.hypot(*chord))
    s = np.arange(m + 1)[:, None] / m
    if c >= m * l0 * (1 - 1e-12) or m == 1 or c == 0.0:
        return a + s * chord
    # m chords of l0 turning by alpha each span sin(m alpha / 2) / sin(alpha / 2) l0: equal to c on (0, 2 pi / m)
    ratio = c / l0
    from scipy.optimize import brentq   # here: importing SciPy's optimizers costs estimate and plan 0.2 s each

    alpha = brentq(lambda x: math.sin(m * x / 2) / math.sin(x / 2) - ratio, 1e-12, 2 * math.pi / m - 1e-12)
    beta = math.atan2(chord[1], chord[0])
    # segment j leans sign ((m - 1) / 2 - j) alpha from the chord; the side whose first segment is nearer above_dir
    sign = max((1.0, -1.0), key=lambda sg: math.cos(beta + sg * (m - 1) * alpha / 2 - above_dir))
    angles = beta + sign * ((m - 1) / 2 - np.arange(m)) * alpha
    steps = l0 * np.column_stack([np.cos(angles), np.sin(angles)])
    pts = a + np.vstack([np.zeros(2), np.cumsum(steps, axis=0)])
    pts[-1] = b                                            # equal to b to rounding
    return pts
