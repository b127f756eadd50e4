"""The swing plane's mapping checked across the image by the moving arm (issue 25).

The calibration maps pixels to the swing plane through one view of the board; away from the
board that mapping extrapolates, and a weak calibration set bends it (2-7 mm at the far side
of the swing region on the band-shot setups of the generalization benchmark). The arm sweeps
the same plane with known forward kinematics, so every synced frame says where the arm's
links are. Across each link (rows normal to its FK axis, as in
:mod:`~stringcast.calibrate.link_profiles`) the pair of edges of its outline gives the link's
centre line as the calibration sees it; its offset o along the link's normal n, at the row's
point p on the FK axis, is one equation

    n . e(p) = o,      e(p) = (the calibration's plane point of the pixel that sees p) - p,

on the mapping's error field e, plus v_n dt where the frame's clock is dt off and the point
moves at v_n along n. Rows are kept only where the row agrees with the link's other rows
(clutter behind the link). :func:`sweep_rows` collects the rows of the frames;
:func:`stringcast.calibrate.refine.refine_mapping` fits the mapping and the clock to them, in
the sweep stage (:mod:`stringcast.sync.sweep`). On the generalization setups the rows measure
the error to 0.1-0.4 mm (``benchmarks/arm_sweep.py``, docs/results.md).
"""
from __future__ import annotations

import numpy as np

from stringcast.core import BoardCheckSettings, chunked, forked_map, forward_kinematics, joints_at

from .link_profiles import link_consensus, link_profiles

ROW_FIELDS = ("frame", "px_m", "py_m", "nx", "ny", "offset_m", "speed_m_s")
"""The columns of :func:`sweep_rows`'s table."""


def _link_rows(image, calibration, arm, q, st: BoardCheckSettings) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per link (and gripper) whose rows agree: (points (R, 2) m on the FK axis, normal (2,),
    offsets (R,) m) of the agreeing rows (:func:`~stringcast.calibrate.link_profiles.link_profiles`)."""
    out = []
    for a, b, nrm, u, centres, tried in link_profiles(image, calibration, arm, q, st):
        c = link_consensus(centres, tried, st)
        if c is None:
            continue
        keep = np.abs(centres - c[0]) <= st.max_spread_mm / 1000
        out.append((a + u[keep, None] * (b - a), nrm, centres[keep]))
    return out


def sweep_rows(frames, calibration, arm, t_frames: np.ndarray, t_j: np.ndarray, q_j: np.ndarray,
               st: BoardCheckSettings, dt_s: float = 5e-3, workers: int = 1) -> np.ndarray:
    """The arm's link rows in the given frames.

    Args:
        frames: iterable of (frame index, (H, W) grey image).
        calibration: :class:`~stringcast.calibrate.mapping.Calibration` (robot_to_pixel).
        arm: :class:`~stringcast.core.specs.ArmSpec` with its outline.
        t_frames: (N,) s, every frame's controller-clock time (:func:`stringcast.sync.frame_times`).
        t_j, q_j: (M,) s, (M, J) rad: the joint log.
        st: the board check's profile settings (:class:`~stringcast.core.BoardCheckSettings`).
        dt_s: the half-step of the rows' speed (central difference of the FK), s: a few of the
            log's samples, so that its encoder noise does not read as speed.
        workers: forked processes reading the frames' rows side by side
            (:func:`~stringcast.core.forked_map`; the same rows for any number).

    Returns:
        (K, 7) array, columns :data:`ROW_FIELDS`: frame, the row's point on the FK axis (m,
        robot frame), the link's unit normal, the seen centre's offset along it (m), and the
        point's velocity along the normal (m/s, signed: a clock error of dt s adds velocity * dt
        to the offset).
    """
    def rows(part):
        out = []
        for k, image in part:
            t = float(t_frames[k])
            q_minus, q_mid, q_plus = joints_at(np.array([t - dt_s, t, t + dt_s]), t_j, q_j)
            mid = forward_kinematics(arm, q_mid)
            ends = (forward_kinematics(arm, q_minus), forward_kinematics(arm, q_plus))
            for pts, nrm, off in _link_rows(np.asarray(image, np.float32), calibration, arm, q_mid, st):
                # the same material points a little earlier and later: their motion along the normal
                speed = (point_motions(mid, ends, pts) @ nrm / (2 * dt_s)).tolist()
                out += [[k, p[0], p[1], nrm[0], nrm[1], o, v] for p, o, v in zip(pts, off, speed)]
        return out

    frames = list(frames)
    out = [r for part in forked_map(rows, chunked(frames, -(-len(frames) // max(1, workers))), workers)
           for r in part]
    return np.asarray(out, float).reshape(-1, len(ROW_FIELDS))


def point_motions(mid: np.ndarray, ends: tuple[np.ndarray, np.ndarray], pts) -> np.ndarray:
    """Displacements (n, 2) m of the arm's material points at pts (n, 2) m on the posture ``mid``
    (FK points (J + 2, 2) m) from the posture ends[0] to ends[1]: each point is carried by the link
    nearest to it (the first of equals). :func:`point_motion_reference` point by point, at once."""
    p = np.asarray(pts, float).reshape(-1, 2)
    a, ab = mid[:-1], mid[1:] - mid[:-1]                                 # (S, 2) the links
    rel = p[:, None, :] - a[None]                                        # (n, S, 2)
    u = np.clip((rel * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0, 1)
    seg = np.argmin(np.linalg.norm(rel - u[..., None] * ab, axis=-1), axis=1)
    a0, b0 = mid[seg], mid[seg + 1]
    e0 = (b0 - a0) / np.linalg.norm(b0 - a0, axis=1, keepdims=True)
    r = p - a0
    lon, lat = (r * e0).sum(1), r[:, 1] * e0[:, 0] - r[:, 0] * e0[:, 1]
    moved = []
    for f in ends:
        a1, b1 = f[seg], f[seg + 1]
        e1 = (b1 - a1) / np.linalg.norm(b1 - a1, axis=1, keepdims=True)
        moved.append(a1 + lon[:, None] * e1 + lat[:, None] * np.c_[-e1[:, 1], e1[:, 0]])
    return moved[1] - moved[0]


def point_motion_reference(mid: np.ndarray, ends: tuple[np.ndarray, np.ndarray], p) -> np.ndarray:
    """Displacement (2,) m of the arm's material point at p on the posture ``mid`` (FK points
    (J + 2, 2) m) from the posture ends[0] to ends[1]: the point is carried by the link nearest to it.
    One point in plain steps: the reference :func:`point_motions` is held to."""
    seg = int(np.argmin([_dist_to_segment(p, mid[s], mid[s + 1]) for s in range(len(mid) - 1)]))
    moved = []
    for f in ends:
        a0, b0, a1, b1 = mid[seg], mid[seg + 1], f[seg], f[seg + 1]
        e0, e1 = (b0 - a0) / np.linalg.norm(b0 - a0), (b1 - a1) / np.linalg.norm(b1 - a1)
        r = p - a0
        lon, lat = r @ e0, r @ np.array([-e0[1], e0[0]])
        moved.append(a1 + lon * e1 + lat * np.array([-e1[1], e1[0]]))
    return moved[1] - moved[0]


def _dist_to_segment(p, a, b) -> float:
    ab = b - a
    u = np.clip((p - a) @ ab / max(ab @ ab, 1e-12), 0, 1)
    return float(np.linalg.norm(p - a - u * ab))
