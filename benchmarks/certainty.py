"""The generalization benchmark's errors against the lab's truth, and its check of the stated uncertainties (issue 51).

:func:`calibration_errors`, :func:`mapping_error` and :func:`plane_errors` measure the calibration
and the pixel -> swing-plane mapping against the draw's true camera.

Each stage that states how well it knows a figure is held to it, per setup, where the truth is
known (``ground_truth.json``, read here by the benchmark only). The **stated interval** of each
quantity is the one its verdict's message quotes:

* ``sync`` (``sync.json``'s ``offset_s``): ``sync.json``'s ``uncertainty_ms`` where it writes one.
  Code that wrote none (before issue 51) stated only the video's: ``evidence_k`` x the video
  estimate's standard error (the "+-" its message quotes); its stated interval of the chosen offset
  is then that, for the video's offset, and ``|trigger - video|`` + that for a trigger kept against
  the video (the video found it no worse than its own offset). Not determined (no interval) where
  the video gave no estimate.
* ``sync_video`` (the video's own estimate, chosen or not): the video candidate's
  ``uncertainty_ms`` where written, else ``evidence_k`` x its standard error.
* ``clock`` (``clock.json``'s ``offset_s``): the sweep's ``clock_uncertainty_ms`` ("known to").
* ``mapping`` (``geometry.json``'s pixel -> swing-plane mapping): the sweep's
  ``uncertainty_p95_mm`` ("known there to"), against the p95 of the true error over the same points
  (:func:`stringcast.sync.sweep.reach_points`, where the string can be).

A setup **covers** a quantity when |true error| <= its stated uncertainty; :func:`coverage` gives
the share over the setups with a stated interval, the count of those without one, and the median
stated uncertainty. :func:`overrule_confusion` counts the sync's decisions (trigger kept or
overruled by the video) against which candidate was truly nearer. Both also under the rules before
issue 51, recomputed from the same run's figures (``before_*``: the same video estimate, standard
error and resampling test, and the sweep's iid standard errors and splits), so that one run of the
new code gives the comparison on every setup.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np


def calibration_errors(cal: dict, setup) -> tuple[float | None, float | None]:
    """(fx error %, principal-point error px) of the calibration against the draw's true camera."""
    K = cal.get("K")
    if K is None:
        return None, None
    K = np.asarray(K, float)
    cx0 = setup.width_px / 2 - 0.5 + setup.principal_offset_px[0]
    cy0 = setup.height_px / 2 - 0.5 + setup.principal_offset_px[1]
    fx_err = (K[0, 0] - setup.focal_px) / setup.focal_px * 100
    return float(fx_err), float(np.hypot(K[0, 2] - cx0, K[1, 2] - cy0))


def swing_grid(n: int = 13) -> np.ndarray:
    """(n * n, 2) m: a grid over the lab's swing region (robot frame)."""
    from stringcast_lab.view import SWING_REGION_M

    (x0, x1), (y0, y1) = SWING_REGION_M
    return np.stack(np.meshgrid(np.linspace(x0, x1, n), np.linspace(y0, y1, n)), -1).reshape(-1, 2)


def mapping_error(cal, camera: dict, points: np.ndarray) -> np.ndarray:
    """(N, 2) m: where the calibration ``cal`` maps the pixels at which the lab's true ``camera``
    (``ground_truth.json``'s, read by the benchmarks only) sees the swing-plane ``points`` (N, 2) m,
    less those points."""
    import cv2

    uv = cv2.projectPoints(np.c_[points, np.zeros(len(points))], *(np.asarray(camera[k], float) for k in (
        "rvec", "tvec", "K", "dist")))[0].reshape(-1, 2)
    return cal.pixel_to_robot(uv) - points


def plane_errors(calibration_json: Path, camera: dict) -> tuple[float, float]:
    """(median, max) mm of the calibration's pixel -> swing-plane mapping over the swing region,
    at the pixels where the lab's true camera sees a 13 x 13 grid of the region's points."""
    from stringcast.calibrate import Calibration

    e = np.linalg.norm(mapping_error(Calibration.from_json(calibration_json), camera, swing_grid()), axis=1) * 1000
    return float(np.median(e)), float(np.max(e))


QUANTITIES = ("sync", "sync_video", "clock", "mapping")
"""The quantities whose stated uncertainty the benchmark checks (module doc)."""


def _finite(x) -> float | None:
    return None if x is None or not np.isfinite(x) else float(x)


def sync_figures(sync_doc: dict, truth_s: float, evidence_k: float) -> dict:
    """The sync's stated uncertainties and true errors (ms), and its decision (module doc, ``sync``).

    Args:
        sync_doc: ``sync.json``. truth_s: the lab's true ``trigger_time_s`` (frame 0's exposure centre).
        evidence_k: ``sync.evidence_k`` (the old interval's width in standard errors).
    """
    c = sync_doc.get("candidates") or {}
    video, trig = c.get("video") or {}, c.get("trigger") or {}
    v_s, t_s = video.get("offset_s"), trig.get("offset_s")
    se = _finite(video.get("standard_error_ms"))
    u_video = _finite(video.get("uncertainty_ms"))
    if u_video is None and "uncertainty_ms" not in video and se is not None:
        u_video = evidence_k * se
    if "uncertainty_ms" in sync_doc:
        stated = _finite(sync_doc["uncertainty_ms"])
    elif v_s is None or u_video is None:
        stated = None
    elif sync_doc.get("chosen") == "video":
        stated = u_video
    else:
        stated = abs(t_s - v_s) * 1000 + u_video
    before = _sync_before(sync_doc, truth_s, evidence_k, se)
    return {**before, "sync_chosen": sync_doc.get("chosen"), "sync_stated_ms": stated,
            "sync_offset_error_ms": (float(sync_doc["offset_s"]) - truth_s) * 1000,
            "sync_video_error_ms": None if v_s is None else (v_s - truth_s) * 1000,
            "sync_video_stated_ms": u_video, "sync_video_standard_error_ms": se,
            "sync_trigger_error_ms": None if t_s is None else (t_s - truth_s) * 1000,
            "sync_excess_p": trig.get("excess_p"), "sync_residual_mm": video.get("residual_mm"),
            "sync_time_residual_ms": video.get("time_residual_ms"),
            "sync_systematic_ms": video.get("systematic_ms"),
            "sync_reasons": list((sync_doc.get("verdict") or {}).get("reasons") or [])}


def _sync_before(sync_doc: dict, truth_s: float, evidence_k: float, se: float | None) -> dict:
    """The sync's decision and stated uncertainties under the rules before issue 51, from the same
    ``sync.json`` (its video estimate, standard error and resampling test): the video overruled the
    trigger where the trigger fitted as well in fewer than ``excess_p_needed`` of the resamples (the
    estimate not ambiguous), and stated ``evidence_k`` standard errors."""
    c = sync_doc.get("candidates") or {}
    video, trig = c.get("video") or {}, c.get("trigger") or {}
    v_s, t_s = video.get("offset_s"), trig.get("offset_s")
    if v_s is None or se is None:
        return {"before_sync_chosen": "trigger" if t_s is not None else None, "before_sync_stated_ms": None,
                "before_sync_video_stated_ms": None,
                "before_sync_offset_error_ms": None if t_s is None else (t_s - truth_s) * 1000}
    p, need = trig.get("excess_p"), trig.get("excess_p_needed")
    over = (t_s is None or (not video.get("ambiguous") and p is not None and (trig.get("excess_mm") or 0) > 0
                            and p < need))
    chosen = v_s if over else t_s
    return {"before_sync_chosen": "video" if over else "trigger", "before_sync_video_stated_ms": evidence_k * se,
            "before_sync_stated_ms": evidence_k * se + (0.0 if over else abs(t_s - v_s) * 1000),
            "before_sync_offset_error_ms": (chosen - truth_s) * 1000}


def sweep_figures(geo_doc: dict, clock_doc: dict, truth_s: float, truth_camera: dict, calibration_json: Path,
                  geometry_json: Path, campaign, joints_csv: Path) -> dict:
    """The sweep's stated clock and mapping uncertainties and their true errors (module doc)."""
    from stringcast.calibrate import Calibration
    from stringcast.core import read_joint_table
    from stringcast.sync.sweep import reach_points

    block = geo_doc.get("sweep") or {}
    out = {"clock_error_ms": (clock_doc["offset_s"] - truth_s) * 1000,
           "clock_stated_ms": _finite(block.get("clock_uncertainty_ms")),
           "mapping_stated_mm": _finite(block.get("uncertainty_p95_mm")), "mapping_error_p95_mm": None,
           "clock_split_ms": block.get("clock_split_ms"), "clock_mapping_bound_ms": block.get("clock_mapping_bound_ms"),
           "clock_lens_ms": (block.get("lens") or {}).get("clock_disagreement_ms"),
           "speed_eff_m_s": block.get("speed_eff_m_s"),
           "before_clock_stated_ms": None, "before_mapping_stated_mm": None,
           "clock_reasons": list((clock_doc.get("verdict") or {}).get("reasons") or [])}
    if block.get("clock_standard_error_iid_ms") is not None:   # the rules before issue 51, on the same fit
        out["before_clock_stated_ms"] = max(2 * block["clock_standard_error_iid_ms"], block["clock_halves_ms"])
        out["before_mapping_stated_mm"] = max(2 * block["standard_error_iid_p95_mm"], block["halves_p95_mm"],
                                              (block.get("lens") or {}).get("disagreement_p95_mm") or 0.0)
    _, q_j = read_joint_table(joints_csv, n_joints=campaign.arm.n_joints)
    points = reach_points(campaign, q_j, Calibration.from_json(calibration_json))
    if len(points):
        e = np.linalg.norm(mapping_error(Calibration.from_json(geometry_json), truth_camera, points), axis=1)
        out["mapping_error_p95_mm"] = float(np.percentile(e, 95) * 1000)
    return out


PAIRS = {"sync": ("sync_offset_error_ms", "sync_stated_ms"),
         "sync_video": ("sync_video_error_ms", "sync_video_stated_ms"),
         "clock": ("clock_error_ms", "clock_stated_ms"), "mapping": ("mapping_error_p95_mm", "mapping_stated_mm")}
"""Per quantity: the row's keys of the true error and of the stated uncertainty."""
PAIRS_BEFORE = {"sync": ("before_sync_offset_error_ms", "before_sync_stated_ms"),
                "sync_video": ("sync_video_error_ms", "before_sync_video_stated_ms"),
                "clock": ("clock_error_ms", "before_clock_stated_ms"),
                "mapping": ("mapping_error_p95_mm", "before_mapping_stated_mm")}
"""The same under the rules before issue 51, recomputed from a run of the new code (module doc)."""


def coverage(rows: list[dict], pairs: dict | None = None) -> dict:
    """Per quantity: ``{"covered", "stated" (setups with an interval), "share", "not_determined",
    "median_stated", "median_abs_error", "missed" (seeds outside)}`` over the rows that have the error
    (``pairs``: :data:`PAIRS`, or :data:`PAIRS_BEFORE`)."""
    out = {}
    for q, (err_key, u_key) in (pairs or PAIRS).items():
        have = [r for r in rows if r.get(err_key) is not None]
        stated = [r for r in have if r.get(u_key) is not None]
        inside = [abs(r[err_key]) <= r[u_key] for r in stated]
        out[q] = {"covered": int(sum(inside)), "stated": len(stated),
                  "share": float(np.mean(inside)) if stated else None,
                  "not_determined": len(have) - len(stated),
                  "median_stated": float(np.median([r[u_key] for r in stated])) if stated else None,
                  "median_abs_error": float(np.median([abs(r[err_key]) for r in have])) if have else None,
                  "missed": [r["seed"] for r, ok in zip(stated, inside) if not ok]}
    return out


def overrule_confusion(rows: list[dict], chosen_key: str = "sync_chosen") -> dict:
    """The sync's decisions (``chosen_key``: ``sync_chosen``, or ``before_sync_chosen``) against the truth:
    counts of ``{overruled|kept}_{trigger|video}_better`` (the candidate truly nearer the true offset),
    ``no_trigger`` and ``no_video``, and the seeds of each."""
    out: dict = {}
    for r in rows:
        v, t = r.get("sync_video_error_ms"), r.get("sync_trigger_error_ms")
        if r.get(chosen_key) is None:
            continue
        if t is None:
            key = "no_trigger"
        elif v is None:
            key = "no_video"
        else:
            key = (f"{'overruled' if r[chosen_key] == 'video' else 'kept'}_"
                   f"{'trigger' if abs(t) < abs(v) else 'video'}_better")
        out.setdefault(key, []).append(r["seed"])
    return {k: {"count": len(s), "seeds": s} for k, s in sorted(out.items())}


def figure(rows: list[dict], path: Path) -> None:
    """Per quantity, each setup's |true error| against its stated uncertainty (log-log): dots under the
    rules of the code that ran (green inside, red outside), crosses under the rules before issue 51
    (recomputed from the same run, where it records them); the diagonal is the coverage limit."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    fig, axes = plt.subplots(1, len(PAIRS), figsize=(4 * len(PAIRS), 3.8))
    cov, old = coverage(rows), coverage(rows, PAIRS_BEFORE)
    for ax, q in zip(axes, PAIRS):
        drawn = []
        for (err_key, u_key), style in ((PAIRS_BEFORE[q], "before"), (PAIRS[q], "after")):
            pts = np.array([(r[u_key], abs(r[err_key])) for r in rows if r.get(u_key) is not None
                            and r.get(err_key) is not None], float).reshape(-1, 2)
            if not len(pts):
                continue
            pts = np.maximum(pts, 1e-3)
            drawn.append(pts)
            inside = pts[:, 1] <= pts[:, 0]
            if style == "before":
                ax.scatter(pts[:, 0], pts[:, 1], marker="x", c=np.where(inside, "0.6", "tab:red"), s=16, lw=0.8)
            else:
                ax.scatter(pts[:, 0], pts[:, 1], c=np.where(inside, "tab:green", "tab:red"), s=18)
        if drawn:
            allp = np.concatenate(drawn)
            lo, hi = allp.min() / 2, allp.max() * 2
            ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
            ax.set_xscale("log")
            ax.set_yscale("log")
            for axis in (ax.xaxis, ax.yaxis):
                axis.set_minor_formatter(NullFormatter())
        c, b = cov[q], old[q]
        def share(x):
            return "-" if x["share"] is None else f"{x['share']:.0%}"
        ax.set_title(f"{q}: {c['covered']}/{c['stated']} covered ({share(c)}); before {b['covered']}/{b['stated']}",
                     fontsize=9)
        unit = "mm" if q == "mapping" else "ms"
        ax.set_xlabel(f"stated uncertainty ({unit}); x: before issue 51")
        ax.set_ylabel(f"|true error| ({unit})")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
