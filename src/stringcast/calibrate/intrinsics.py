"""The calibration stage's intrinsics: fit, judge, hold what the views cannot determine, or refuse.

:func:`judged_intrinsics` fits the views (:func:`~stringcast.calibrate.charuco.fit_views`)
and judges the fit (:func:`~stringcast.calibrate.quality.assess`). What the views do not
determine is held, one step at a time, each refit on the same views:

1. k3 at 0 (``cv2.CALIB_FIX_K3``) when the coverage is poor or the distortion uncertain;
2. the principal point at the image centre ((w - 1) / 2, (h - 1) / 2,
   ``cv2.CALIB_FIX_PRINCIPAL_POINT``) when the coverage is poor, or the principal point or
   fx is uncertain;
3. k2 at 0 (``cv2.CALIB_FIX_K2``) when the distortion is still uncertain.

The limits (``calibration.max_*``) are shares of the image or of fx, the standard
deviations per view (:mod:`~stringcast.calibrate.quality`).

A held value must fit the views: holding two parameters at their true values raises the
rms by a share of the order of 1 / (2 N) (N the corners, hundreds), so a rise beyond
``hold_rms_tol`` says the views place the parameter elsewhere; the step is undone and the
free fit kept (``refused_hold``). A held calibration is ``warn`` (the held values are
assumptions, and say so), as is one poorly determined (or covering the image poorly) with
nothing held; one whose standard deviations stay above ``fail_factor`` times their limits
is ``fail``; each reason says which shots to add. Little tilt variety alone is no problem
when the deviations (a jackknife over the views) are within their limits: it is named as
the likely cause, and the shots to add, when they are not.

:func:`board_view_check` reads the trial's board (in the swing plane) under the
intrinsics: its reprojection error with the board's pose as the only freedom
(``cv2.solvePnP``, ``SOLVEPNP_IPPE``, then ``cv2.solvePnPRefineLM``) against its own
noise (the rms of a free homography of the undistorted corners, ``cv2.findHomography``)
and against the calibration views' median error.
"""
from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from stringcast.core import CalibrationSettings, Verdict

from .charuco import Intrinsics, Views, fit_views
from .quality import assess

_PP_KINDS = ("coverage", "principal_point", "fx")
_DIST_KINDS = ("coverage", "distortion")
_STEPS = ((cv2.CALIB_FIX_K3, "k3 at 0", _DIST_KINDS), (cv2.CALIB_FIX_PRINCIPAL_POINT,
          "the principal point at the image centre", _PP_KINDS), (cv2.CALIB_FIX_K2, "k2 at 0", ("distortion",)))


def _unique(items) -> list[str]:
    return list(dict.fromkeys(items))


def judged_intrinsics(views: Views, flags: int, st: CalibrationSettings, min_views: int = 3
                      ) -> tuple[Intrinsics, dict, Verdict]:
    """Fit the views, hold what they do not determine, and judge the result.

    Args:
        views: :class:`~stringcast.calibrate.charuco.Views` (>= ``min_views``).
        flags: ``cv2.calibrateCamera`` flags the camera's config asks for (``CALIB_FIX_K3``).
        st: :class:`~stringcast.core.CalibrationSettings`.

    Returns:
        (the intrinsics used, their measures for ``calibration.json`` (``held``, ``covariance``, and
        ``free_fit`` with the unheld fit's K, dist, rms and covariance when something was held), the verdict).
    """
    free = fit_views(views, flags, min_views)
    doc, problems = assess(free, st)
    free_covariance = doc["covariance"]
    found, fit, held, refused = dict(problems), free, [], None
    for flag, what, kinds in _STEPS:
        if fit.flags & flag or not any(k in problems for k in kinds):
            continue
        trial = fit_views(free.views, fit.flags | flag, min_views)   # the views the free fit kept:
        trial = replace(trial, views_rejected=free.views_rejected + trial.views_rejected)  # count its drops too
        if trial.rms_px > free.rms_px * (1 + st.hold_rms_tol):
            refused = what, trial.rms_px
            break
        fit, held = trial, held + [what]
        doc, problems = assess(fit, st)
    why = "; ".join(_unique(v[0] for v in found.values()))
    advice = "; ".join(_unique(v[1] for v in found.values()))
    verdict = Verdict()
    if held:
        doc["free_fit"] = {"K": free.K.tolist(), "dist": free.dist.tolist(), "rms_px": free.rms_px,
                           "covariance": free_covariance}
        verdict = verdict.add("warn", f"intrinsics: {' and '.join(held)} held, as the calibration views do not "
                                      f"determine them ({why}); {advice}")
    over = {k: v for k, v in problems.items() if k not in ("coverage", "tilt")}
    left = {k: v for k, v in over.items() if v[2] > st.fail_factor}
    if refused:
        doc["refused_hold"] = {"what": refused[0], "rms_px": refused[1]}
    if left:
        pre = f"even with {' and '.join(held)} held, " if held else ""
        why_not = (f" (holding {refused[0]} would raise the reprojection error from {free.rms_px:.3f} to "
                   f"{refused[1]:.3f} px, > {st.hold_rms_tol:.0%}: the views place it elsewhere)") if refused else ""
        verdict = verdict.add("fail", f"intrinsics: {pre}{'; '.join(v[0] for v in left.values())} "
                                      f"(over {st.fail_factor:g} times the limit){why_not}; "
                                      f"{'; '.join(_unique(v[1] for v in left.values()))}")
    elif not held and (over or "coverage" in problems):
        verdict = verdict.add("warn", f"intrinsics: {why}; {advice}")
    return fit, doc, verdict


def board_view_check(intr: Intrinsics, obj: np.ndarray, img: np.ndarray, st: CalibrationSettings
                     ) -> tuple[dict, str | None]:
    """The trial's board (in the swing plane) reprojected under the intrinsics.

    Args:
        intr: the intrinsics to check (with ``per_view_rms_px``).
        obj: (N, 3) board points, m (z = 0). img: (N, 2) their detected corners, px.
        st: :class:`~stringcast.core.CalibrationSettings` (``board_view_ratio``).

    Returns:
        (``{"rms_px" (pose under the intrinsics), "homography_rms_px" (free homography of the
        undistorted corners: the board's own noise), "views_median_rms_px", "ratio"}``, a
        warning sentence or None).
    """
    o = np.asarray(obj, np.float64).reshape(-1, 3)
    i = np.asarray(img, np.float64).reshape(-1, 1, 2)
    ok, rvec, tvec = cv2.solvePnP(o, i, intr.K, intr.dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        return {"rms_px": None}, "the trial's board gives no pose under the intrinsics"
    rvec, tvec = cv2.solvePnPRefineLM(o, i, intr.K, intr.dist, rvec, tvec)
    proj = cv2.projectPoints(o, rvec, tvec, intr.K, intr.dist)[0].reshape(-1, 2)
    rms = float(np.sqrt(np.mean(np.sum((proj - i.reshape(-1, 2)) ** 2, axis=1))))
    und = cv2.undistortPoints(i, intr.K, intr.dist, P=intr.K).reshape(-1, 2)
    H = cv2.findHomography(o[:, :2], und, 0)[0]
    back = cv2.perspectiveTransform(o[:, :2].reshape(-1, 1, 2), H).reshape(-1, 2)
    own = float(np.sqrt(np.mean(np.sum((back - und) ** 2, axis=1))))
    views = float(np.median(intr.per_view_rms_px)) if intr.per_view_rms_px else 0.0
    noise = max(own, views, 1e-9)
    doc = {"rms_px": rms, "homography_rms_px": own, "views_median_rms_px": views, "ratio": rms / noise}
    if rms > st.board_view_ratio * noise:
        return doc, (f"the trial's board reprojects at {rms:.2f} px under the intrinsics, {rms / noise:.1f} times its "
                     f"own noise and the calibration views' ({noise:.2f} px): the intrinsics do not fit this trial's "
                     "camera (another zoom, focus or camera?) or are poorly determined; recalibrate")
    return doc, None
