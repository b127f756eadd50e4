"""Board-to-robot check: where the still arm is seen vs where config's board pose and the FK put it.

The calibration maps pixels to the robot frame through the ChArUco board, whose pose in
the robot frame comes from config (``setup.board_to_robot``). If that pose is wrong (the
board moved, a typo in ``board_origin_mm``), every tracked point is off by as much. The
arm itself is the check: before the motion it stands still at the joint log's first row
q_rest, so the forward kinematics (:func:`stringcast.core.arm.forward_kinematics`) say where it
is in the robot frame; :func:`check_board_to_robot` measures where the calibration sees
it, from the rest image alone, with two kinds of feature (no model of the arm's colours):

* **link and gripper edges**: across each link (and the gripper) the image is sampled on
  rows normal to its FK axis, over the arm outline's width (the arm's ``link_widths``,
  ``gripper_widths``) plus ``margin_mm`` each side, clear of the
  joint discs. On each row the strongest pair of edges whose spacing fits
  the outline (``width_range`` of it) is the segment as seen; the median of their
  midpoints over the rows (the largest group within ``max_spread_mm`` of each other, at
  least ``min_share`` of the rows: rows where clutter behind the arm won drop out) is the
  segment's offset o_s along its normal n_s: one equation ``n_s . d = o_s``.
* **joint discs** (if ``use_discs``): around each joint but the base, rays from the FK
  centre find the disc's rim (the strongest edge from 0.3 outline radii,
  the arm's ``joint_radii``, to the radius + ``disc_reach_mm``); a circle fit (Huber-reweighted) gives the centre's
  2-D offset: two equations, which a posture with all links nearly parallel needs.
* **the gripper's end** (if ``use_end``), only when the edges and discs leave a direction
  undetermined (links all nearly parallel, an arm without joint discs): on lines along the
  gripper's axis, either side of its centre line (clear of the string), the edge where
  the gripper ends (the strongest edge within ``end_reach_mm`` of the expected end, whose
  inner side looks like the gripper and outer side does not); their consensus gives
  ``e . d = o_e`` along the axis e. The outline ends between the grasp point and the
  arm's ``gripper_mask_extend`` past it (a mask's margin, not a measured end): the middle
  is expected, so the end is sure to +- half that (``end_uncertainty_mm``), less than
  the sides; hence only when needed.
* **the hanging string** (if ``use_string``): at rest the string hangs straight down from
  the grasp point (gravity), so its centreline x is the grasp point's x. On rows
  ``string_rows_mm`` below the grasp point (clear of the arm's outline) the darkest or
  lightest thin line within ``string_search_mm`` of the grasp x is found (a ridge of the
  second derivative); the median offset gives ``(1, 0) . d = o_x``. Off by default: the
  lab's string leaves a horizontal gripper sideways and bends down 5-16 mm away from the
  grasp x (the grasp's bending stiffness), so the assumption is only good for a gripper
  pointing down.

d = (dx, dy) is the least-squares (Huber-reweighted) translation between where the arm is
seen and where config's board pose puts it; ``residual_mm`` = |d|. A board pose shifted by
20 mm in x makes d ~ (20, 0) mm. With the true pose d is the calibration's own error near
the arm (about 1-2 mm with intrinsics; lens distortion uncorrected, 10-20 mm).

The result carries a verdict: ``warn`` when |d| exceeds ``warn_mm``, and ``warn`` "not
checked: <why>" when the features found do not determine d (an unchecked board pose is a
risk the user should know of, not silence).

**Which cause** (issue 51): a wrong board pose moves every point of the plane alike (a rigid
shift or turn of the frame); an error of the intrinsics leaves the board's own corners right (the
homography is fitted to them) and grows with the distance from the board, so a weak calibration
set alone puts an arm far from the board many millimetres off (the issue's field footage: 6-36 mm
with a right board pose). Where the calibration knows its intrinsics' uncertainty, the caller
passes ``spread`` (:func:`stringcast.calibrate.intrinsics_spread.mapping_modes`): how the
intrinsics' uncertainty moves the mapping at each feature's place on the rest arm, read as the
features read it (their normals' share) and fitted as d is: the covariance Sigma of d from the
intrinsics alone, plus the check's own noise (fit_rms^2 / features). An offset inside its 99 %
ellipse (d^T Sigma^-1 d <= :data:`EXPLAINED_CHI2`, chi-square with 2 degrees of freedom) is what
those intrinsics may do there: the warning names the weak intrinsics and says to recalibrate
before touching the board pose. Outside it, the board pose, unless the calibration found its own
intrinsics undetermined (``weak_intrinsics``: parameters held, deviations over their limits): a
weak set's stated deviations are what it gets wrong (issue 25: 4-13 times too small), so they do
not rule its error out; the warning then names the intrinsics first and the board pose as what to
check if the offset stays after recalibrating (the issue's field footage: principal point held,
the arm 23 mm off, 5 sd of the stated spread, with a right board pose). ``likely_cause``:
``intrinsics`` or ``board_pose``; ``intrinsics_sd_mm``: Sigma's standard deviation along d.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import gaussian_filter1d

from stringcast.core import BoardCheckSettings, Verdict, forward_kinematics

from .link_profiles import _consensus, _refine, _sample, link_consensus, link_profiles

METHOD = "rest image: link/gripper edge pairs across their FK axes, joint-disc rims, the gripper's end"
EXPLAINED_CHI2 = 9.21
"""The 99 % point of chi-square with 2 degrees of freedom: an offset d with d^T Sigma^-1 d at most this
lies inside the 99 % ellipse of what the intrinsics' uncertainty Sigma moves the arm by (module doc)."""
MIN_SINGULAR = 0.3
"""The features' unit directions must give a 2 x 2 system whose smaller singular value reaches
this (a second direction at least ~17 deg from the first, one feature each)."""


def _segment_offsets(image, calibration, arm, q_rest, st: BoardCheckSettings) -> list[tuple]:
    """[(normal (2,), offset m, spread m, the segment's midpoint (2,) m)] for each link/gripper whose
    edges were found."""
    out = []
    for a, b, nrm, _, centres, tried in link_profiles(image, calibration, arm, q_rest, st):
        c = link_consensus(centres, tried, st)
        if c is not None:
            out.append((nrm, *c, 0.5 * (np.asarray(a, float) + np.asarray(b, float))))
    return out


def _disc_offsets(image, calibration, arm, q_rest, st: BoardCheckSettings) -> list[tuple[np.ndarray, np.ndarray]]:
    """[(the disc's FK centre (2,) m, its offset (2,) m)] of the joint discs (base excluded) whose rim was found.

    Rays from the FK joint centre at ``disc_rays`` angles; on each, the strongest edge
    between 0.3 outline radii (the arm's ``joint_radii``) and the radius + ``disc_reach_mm``
    (a board pose that far off is still found); the rim
    r(theta) = r0 + (cos theta, sin theta) . c is fitted by Huber-reweighted least squares
    for (r0, c), kept if r0 fits the outline, most rays agree and the rim is round.
    """
    pts = forward_kinematics(arm, np.asarray(q_rest, float))
    radii = arm.joint_radii
    step = st.step_mm / 1000
    th = np.linspace(0, 2 * np.pi, int(st.disc_rays), endpoint=False)
    ray = np.stack([np.cos(th), np.sin(th)], axis=1)
    out = []
    for j in range(1, arm.n_joints + 1):
        R = float(radii[min(j, len(radii) - 1)])
        r = np.arange(0.3 * R, R + st.disc_reach_mm / 1000, step)
        centre, ok = np.zeros(2), False
        for _ in range(3):  # re-centre: the rim model is linear in the offset only for small ones
            fit = _rim_fit(image, calibration, pts[j] + centre, r, ray, step, st)
            if fit is None:
                break
            r0, c, inl = fit
            centre = centre + c
            ok = inl >= st.min_share * 1.5 and 0.7 * R <= r0 <= 1.1 * R
            if np.hypot(*c) < 0.001:
                break
        if ok:
            out.append((pts[j], centre))
    return out


def _huber_lstsq(A: np.ndarray, y: np.ndarray, scale: float = 0.002, iters: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Huber least squares by iteratively reweighted least squares: A (N, P), y (N,) (m) ->
    (solution (P,), residuals A x - y (N,)); residuals beyond ``scale`` (2 mm) weigh as |r|, not r^2."""
    w = np.ones(len(y))
    for _ in range(iters):
        x = np.linalg.lstsq(A * w[:, None], y * w, rcond=None)[0]
        r = A @ x - y
        w = np.sqrt(np.minimum(1.0, scale / np.maximum(np.abs(r), 1e-12)))
    return x, r


def _rim_fit(image, calibration, centre, r, ray, step, st: BoardCheckSettings):
    """(r0 m, centre correction (2,) m, inlier share) of a disc rim seen on rays from centre; None off-image."""
    prof = _sample(image, calibration, centre + r[None, :, None] * ray[:, None, :])  # (rays, r)
    if not np.all(np.isfinite(prof)):
        return None
    g = np.abs(np.gradient(gaussian_filter1d(prof, 1.0 / st.step_mm, axis=1), axis=1))
    idx = np.argmax(g, axis=1)
    r_obs = r[0] + step * np.array([_refine(g[i], int(idx[i])) for i in range(len(ray))])
    A = np.column_stack([np.ones(len(ray)), ray])
    sol, res = _huber_lstsq(A, r_obs)
    inl = np.abs(res) <= st.max_spread_mm / 1000
    if inl.sum() >= 3:
        sol = np.linalg.lstsq(A[inl], r_obs[inl], rcond=None)[0]
    return float(sol[0]), sol[1:], float(inl.mean())


def _string_offset(image, calibration, arm, q_rest, st: BoardCheckSettings) -> float | None:
    """x offset (m) of the hanging string below the grasp point, seen minus FK; None if unclear."""
    pts = forward_kinematics(arm, np.asarray(q_rest, float))
    grasp = pts[-1]
    step = st.step_mm / 1000
    half = st.string_search_mm / 1000
    x = np.arange(-half, half + step / 2, step)
    # clear of the arm: farther than the outline's half-width (+ clear_mm) from every segment
    widths = list(arm.link_widths[:arm.n_joints]) + [max(arm.gripper_widths)]
    widths += [arm.link_widths[-1]] * (arm.n_joints + 1 - len(widths))
    offs = []
    for dy in np.arange(st.string_rows_mm[0], st.string_rows_mm[1], 5.0) / 1000:
        row = np.column_stack([grasp[0] + x, np.full_like(x, grasp[1] - dy)])
        near = False
        for s in range(len(pts) - 1):
            a, b = pts[s], pts[s + 1]
            d = b - a
            t = np.clip(((row - a) @ d) / max(d @ d, 1e-12), 0, 1)
            dist = np.linalg.norm(row - (a + t[:, None] * d), axis=1)
            if np.any(dist < widths[min(s, len(widths) - 1)] / 2 + st.clear_mm / 1000):
                near = True
                break
        if near:
            continue
        prof = _sample(image, calibration, row)
        if not np.all(np.isfinite(prof)):
            continue
        ridge = gaussian_filter1d(prof, 1.5 / st.step_mm, order=2)  # a thin line: |2nd derivative| peak
        i = int(np.argmax(np.abs(ridge)))
        if 0 < i < len(x) - 1:
            offs.append(x[0] + step * _refine(ridge, i))
    c = _consensus(np.asarray(offs), st.max_spread_mm / 1000, int(st.min_rows))
    return None if c is None else c[0]


def _end_offset(image, calibration, arm, q_rest, st: BoardCheckSettings) -> tuple[np.ndarray, float] | None:
    """(the gripper's axis e (2,), offset m of its end along e, seen minus the outline's) or None."""
    pts = forward_kinematics(arm, np.asarray(q_rest, float))
    a, b = pts[-2], pts[-1]
    L = float(np.hypot(*(b - a)))
    if L <= 0:
        return None
    e = (b - a) / L
    nrm = np.array([-e[1], e[0]])
    end = b + e * 0.5 * float(arm.gripper_mask_extend)  # the outline ends between b and b + extend
    step, reach = st.step_mm / 1000, st.end_reach_mm / 1000
    inner = min(reach + 0.02, 0.8 * L)  # the gripper's own grey, sampled inside it before the window
    v = np.arange(-reach, reach + step / 2, step)
    tip = float(arm.gripper_widths[-1])
    offs = []
    for s in tip * np.array([-0.35, -0.25, -0.15, 0.15, 0.25, 0.35]):  # clear of the string on the centre line
        prof = _sample(image, calibration, end + s * nrm + v[:, None] * e)
        ref = _sample(image, calibration, end + s * nrm - np.linspace(inner, reach, 5)[:, None] * e)
        if not (np.all(np.isfinite(prof)) and np.all(np.isfinite(ref))):
            continue
        prof = gaussian_filter1d(prof, 1.0 / st.step_mm)
        g_in, g = float(np.median(ref)), np.gradient(prof)
        a_g = np.abs(g)
        peaks = np.nonzero((a_g[1:-1] >= a_g[:-2]) & (a_g[1:-1] > a_g[2:]))[0] + 1
        k = max(1, int(round(0.004 / step)))                  # 4 mm either side of an edge
        for i in peaks[np.argsort(a_g[peaks])[::-1]][:6]:
            if i - k < 0 or i + k >= len(prof):
                continue
            if abs(prof[i - k] - g_in) < 0.5 * abs(prof[i + k] - g_in):  # gripper inside, not outside
                offs.append(v[0] + step * _refine(g, int(i)))
                break
    c = _consensus(np.asarray(offs), st.max_spread_mm / 1000, 3)
    return None if c is None else (e, c[0])


def check_board_to_robot(rest_image: np.ndarray, calibration, arm, q_rest: np.ndarray,
                         board_check: BoardCheckSettings, spread=None, weak_intrinsics: str | None = None) -> dict:
    """Translation between where the still arm is seen and where config's board pose + the FK put it.

    Args:
        rest_image: (H, W) grey image (any dtype) of the arm still at ``q_rest``, e.g. the
            median of the frames before the motion.
        calibration: :class:`~stringcast.calibrate.calibration.Calibration` (robot_to_pixel).
        arm: :class:`~stringcast.core.specs.ArmSpec`, with its outline (``link_widths``,
            ``joint_radii``, ``gripper_widths``). q_rest: (J,) rad, ``joints.csv``'s first row.
        board_check: board-check settings (:class:`~stringcast.core.BoardCheckSettings`).
        spread: ``(N, 2) m -> (N, 2, M) m or None``, the modes of how the intrinsics' uncertainty
            moves where the mapping puts plane points (module doc, "Which cause";
            :func:`~stringcast.calibrate.intrinsics_spread.mapping_modes`), or None.
        weak_intrinsics: why the calibration found its intrinsics undetermined (a clause), or None.

    Returns:
        ``{"residual_mm": |d| or None, "dx_mm", "dy_mm" (seen minus FK, robot frame),
        "method", "n_used" (features used), "segment_offsets_mm", "disc_offsets_mm",
        "string_offset_mm", "end_offset_mm", "fit_rms_mm", "warn_mm", "intrinsics_sd_mm",
        "intrinsics_chi2", "likely_cause", "verdict"}``; residual_mm None when the features found
        do not determine d (verdict ``warn``, "not checked: <why>", also in ``method``); verdict
        ``warn`` when |d| > ``warn_mm``, naming the likely cause (``intrinsics`` where they explain d,
        else ``board_pose``; None within ``warn_mm``).

    Raises:
        ValueError: rest_image not 2-D, or q_rest not (J,).
    """

    img = np.asarray(rest_image, np.float32)
    if img.ndim != 2:
        raise ValueError(f"check_board_to_robot: rest_image must be (H, W), got {img.shape}")
    q_rest = np.asarray(q_rest, float)
    if q_rest.shape != (arm.n_joints,):
        raise ValueError(f"check_board_to_robot: q_rest must be ({arm.n_joints},), got {q_rest.shape}")
    st = board_check
    segs = _segment_offsets(img, calibration, arm, q_rest, st)
    rows = [n for n, _, _, _ in segs]
    rhs = [o for _, o, _, _ in segs]
    where = [m for _, _, _, m in segs]     # each equation's place on the arm, for the intrinsics' spread
    grasp = forward_kinematics(arm, q_rest)[-1]
    discs: list = []
    if st.use_discs:
        for p, c in _disc_offsets(img, calibration, arm, q_rest, st):
            rows += [np.array([1.0, 0.0]), np.array([0.0, 1.0])]
            rhs += [float(c[0]), float(c[1])]
            where += [p, p]
            discs.append([float(c[0] * 1000), float(c[1] * 1000)])
    x_str = _string_offset(img, calibration, arm, q_rest, st) if st.use_string else None
    if x_str is not None:
        rows.append(np.array([1.0, 0.0]))
        rhs.append(x_str)
        where.append(grasp)
    end = None
    if st.use_end and _weakest(rows) < MIN_SINGULAR:
        end = _end_offset(img, calibration, arm, q_rest, st)
        if end is not None:
            rows.append(end[0])
            rhs.append(end[1])
            where.append(grasp)
    doc = {"method": METHOD, "n_used": len(segs) + len(discs) + (x_str is not None) + (end is not None),
           "warn_mm": float(st.warn_mm), "segment_offsets_mm": [float(o * 1000) for _, o, _, _ in segs],
           "disc_offsets_mm": discs, "string_offset_mm": None if x_str is None else float(x_str * 1000),
           "end_offset_mm": None if end is None else float(end[1] * 1000),
           "end_uncertainty_mm": None if end is None else float(arm.gripper_mask_extend * 500),
           "residual_mm": None, "dx_mm": None, "dy_mm": None, "fit_rms_mm": None}
    A, y = np.asarray(rows, float).reshape(-1, 2), np.asarray(rhs, float)
    if _weakest(rows) < MIN_SINGULAR:
        why = _why_not(segs, arm, st)
        doc["method"] += f" (not checked: {why})"
        doc["verdict"] = Verdict("warn", (f"not checked: {why}",)).as_dict()
        return doc
    d, r = _huber_lstsq(A, y)
    doc.update(dx_mm=float(d[0] * 1000), dy_mm=float(d[1] * 1000), residual_mm=float(math.hypot(*d) * 1000),
               fit_rms_mm=float(np.sqrt(np.mean(r ** 2)) * 1000))
    cov = None if spread is None else _translation_covariance(A, np.asarray(where, float), spread)
    doc.update(_cause(d, cov, float(np.sqrt(np.mean(r ** 2))), len(y), doc["residual_mm"] > st.warn_mm,
                      weak_intrinsics is not None))
    doc["verdict"] = _offset_verdict(doc, st.warn_mm, weak_intrinsics).as_dict()
    return doc


def _offset_verdict(doc: dict, warn_mm: float, weak_intrinsics: str | None) -> Verdict:
    """The board-to-robot check's verdict from its figures ``doc`` (:func:`check_board_to_robot`): ``warn``
    beyond ``warn_mm``, the reason naming the likely cause (the intrinsics, where they explain the offset,
    or the board pose) and what to do; ``ok`` within it."""
    verdict = Verdict()
    if doc["residual_mm"] > warn_mm:
        seen = (f"the still arm is seen {doc['residual_mm']:.1f} mm (dx {doc['dx_mm']:+.1f}, dy {doc['dy_mm']:+.1f} mm) "
                f"from where the configured board pose puts it (> {warn_mm:g} mm)")
        sd = doc["intrinsics_sd_mm"]
        if doc["likely_cause"] == "intrinsics" and (doc["intrinsics_chi2"] or 0.0) <= EXPLAINED_CHI2:
            verdict = verdict.add("warn", f"{seen}: the calibration's intrinsics are too weak to place the arm so far "
                                          f"from the board (their own uncertainty carried there: "
                                          f"{_mm_or_undetermined(sd)} along the offset, 1 sd), so they, not the board "
                                          "pose, may explain it; recalibrate with shots that cover the image where "
                                          "the arm is, before changing setups.*.board_origin_mm")
        elif doc["likely_cause"] == "intrinsics":
            verdict = verdict.add("warn", f"{seen}: likely the calibration's weak intrinsics ({weak_intrinsics}), whose "
                                          "error grows from the board to the arm and is not ruled out by their stated "
                                          f"uncertainty ({_mm_or_undetermined(sd)} along the offset, 1 sd: a weak set's "
                                          "deviations understate its error); recalibrate with shots that cover the "
                                          "image where the arm is, and check setups.*.board_origin_mm / "
                                          "board_angle_deg only if the offset stays")
        else:
            chi2 = doc["intrinsics_chi2"]
            known = "" if chi2 is None else (f" ({math.sqrt(chi2):.1f} standard deviations of what the intrinsics' "
                                             "own uncertainty moves the arm by: more than they explain)")
            verdict = verdict.add("warn", f"{seen}{known}: check setups.*.board_origin_mm / board_angle_deg")
    return verdict


def _mm_or_undetermined(sd: float | None) -> str:
    return "not determined" if sd is None or not np.isfinite(sd) else f"{sd:.1f} mm"


def _translation_covariance(A: np.ndarray, where: np.ndarray, spread) -> np.ndarray | None:
    """(2, 2) m^2: the covariance of the translation d that the features (rows A (F, 2), at ``where`` (F, 2) m)
    give when the mapping moves by the intrinsics' modes ``spread(where)`` (F, 2, M) m: each feature reads
    its normal's share of the move at its place, d their least-squares translation. None without modes."""
    G = spread(where)
    if G is None:
        return None
    Y = np.einsum("fa,fam->fm", A, G)                  # each feature's offset per mode
    D = np.linalg.pinv(A) @ Y                         # (2, M): the translation per mode
    return D @ D.T


def _cause(d: np.ndarray, cov, rms_m: float, n: int, off: bool, weak: bool = False) -> dict:
    """``intrinsics_sd_mm`` (the intrinsics' spread at the arm along d, 1 sd; None where not determined),
    ``intrinsics_chi2`` (d^T Sigma^-1 d) and ``likely_cause`` (module doc, "Which cause"; None when not
    ``off``; ``weak``: the calibration found its intrinsics undetermined)."""
    out = {"intrinsics_sd_mm": None, "intrinsics_chi2": None, "likely_cause": None}
    if cov is None:
        out["likely_cause"] = ("intrinsics" if weak else "board_pose") if off else None
        return out
    cov = np.asarray(cov, float)
    if not np.all(np.isfinite(cov)):
        out.update(intrinsics_sd_mm=None, likely_cause="intrinsics" if off else None)
        return out
    S = cov + np.eye(2) * rms_m ** 2 / max(n, 1)
    u = d / max(float(np.hypot(*d)), 1e-12)
    chi2 = float(d @ np.linalg.solve(S + np.eye(2) * 1e-12, d))
    out.update(intrinsics_sd_mm=float(np.sqrt(max(u @ S @ u, 0.0)) * 1000), intrinsics_chi2=chi2)
    if off:
        out["likely_cause"] = "intrinsics" if chi2 <= EXPLAINED_CHI2 or weak else "board_pose"
    return out


def _weakest(rows: list) -> float:
    """The smaller singular value of the features' directions (0 with fewer than two)."""
    return 0.0 if len(rows) < 2 else float(np.linalg.svd(np.asarray(rows, float).reshape(-1, 2), compute_uv=False)[-1])


def _why_not(segs: list, arm, st: BoardCheckSettings) -> str:
    """Why the features found do not determine the translation, in one clause."""
    n_seg = arm.n_joints + 1
    if not segs:
        return (f"no arm segment showed a pair of edges of its configured width ({st.width_range[0]:g}-"
                f"{st.width_range[1]:g} x arms.*.link_widths_mm / gripper_widths_mm) where the forward kinematics "
                "put it; check the arm's outline in the config, and that the first frames show the arm at rest")
    ang = np.degrees(np.arctan2([n[1] for n, _, _, _ in segs], [n[0] for n, _, _, _ in segs]))
    spread = float(np.ptp((ang - ang[0] + 90) % 180 - 90))
    return (f"the edges of {len(segs)} of {n_seg} arm segments were found (the others lie outside the image, "
            f"behind clutter or are too short), all within {spread:.0f} deg of one "
            "direction, and no joint disc nor the gripper's end was found to fix the other; a rest posture with "
            "the links at different angles makes the check possible")
