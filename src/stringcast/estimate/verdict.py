"""The fit's verdict: is the estimate usable, and if not, what is the likely cause.

:func:`fit_verdict` judges the figures of :func:`stringcast.estimate.fitcheck.fit_figures`
(never ground truth) and the verdicts the earlier stages wrote (``calibration.json``,
``sync.json``, ``tracking.json``: their ``"verdict"``; a missing one is ok). params.json carries
the result under ``"verdict"``: ``status`` (ok, warn, fail: "the estimate is not usable"),
``reasons``, and ``likely_cause``: ``geometry`` (calibration), ``clock`` (sync), ``tracking``,
``model`` or ``recording`` (the string ignores the grasp's acceleration; ``""`` when ok).

Status (thresholds in :class:`~stringcast.core.EstimationSettings`, ``verdict_*``; why each is
general):

* **E not finite** (every candidate blew up): fail.
* **Error share** (median distance tracked - fitted over the moving frames / L) at or above
  ``verdict_error_share`` = [0.18, 0.25]: warn, fail. A share of L is the same statement on any
  string and camera: at 0.25 L the tip's direction from the grasp is off by about 15 deg
  (2 asin(1/8)) at the median frame, a point half-way along by 30 deg: the model does not say
  where the string went. The lab's own fits are at 0.08-0.11 (the demo, string 1).
* **Skill** (1 - error / the error of a string carried rigidly by the grasp, no swing) at or
  below ``verdict_skill`` = [0.45, 0.25]: warn, fail. The yardstick is the trial's own motion:
  at 0.25 the fit explains a quarter of what a model without dynamics misses. The lab's fits
  are at 0.69-0.77. A fit at or below skill 0 (no closer than the rigidly carried string) fails
  also below ``verdict_floor_share``: however small its error, the model then explains nothing of
  the motion (issue 52: such a fit is never a usable estimate).
* **Time shift** (clock): when shifting the frames' times by ``SHIFT_FRAMES`` = 3 frame periods
  or more cuts the error to ``verdict_shift_gain`` = [0.7, 0.5] of itself or less: warn, fail.
  A right sync is within a frame period (the frame's exposure); a fitted model that agrees far
  better with the frames re-timed by several is being compared at the wrong times. The lab's
  fits gain 0.88-0.98 at best (the model's own phase error) where their error exceeds
  ``verdict_floor_share`` (0.05) of L. Below that share the fit is close and a model's own phase
  error weighs more (string 7's first fit on the lab, 1.6 % of L, sync right within 0.7 ms:
  +8 ms gains 0.64), so there the shift only warns, and only at the fail gain (0.5): when
  re-timing explains most of a small error. Under ``SHIFT_FLOOR_SHARE`` (0.01) of L it is not
  judged at all.
* **Offset** (geometry): when taking one constant offset off every entry cuts the error to
  ``OFFSET_GAIN`` (0.7) of itself or less, more than the best time shift does, and the offset
  is at least ``verdict_floor_share`` of L: warn. No parameter set makes a string hanging from
  the measured grasp sit a constant vector away from it over a whole cast; the camera's mapping
  (calibration, board pose) does. The demo's fits: 0.94 and 1.0; its tracks shifted by 30 mm
  (10 % of L): 0.68, by 60 mm: 0.48.
* Skill, the offset and the evidence from the error at rest and early vs late judge only fits
  whose error share exceeds ``verdict_floor_share`` (0.05): a fit within 5 % of L (the tip's direction
  within 3 deg) is usable whatever its ratios say, and on a slow
  motion the non-swinging string's error (the skill's yardstick) is itself small.
* **Valid share** (the string's points tracked in the moving frames) under
  ``verdict_min_valid_share`` = 0.5: warn, cause tracking: E then rests on less than half of
  the string's path, and the points lost are the fast ones the fit is judged by.
* **Rest gap**: a tracked rest point farther from the grasp point than the string up to it,
  by more than ``verdict_rest_gap_share`` (0.05) of L: warn, cause geometry. A hanging string
  cannot do that; 5 % is the stretch the first plan allows a string under its own load
  (``motion.first_max_strain``).
* The earlier stages' warnings and failures are carried over as reasons ("sync: ..."), with
  their status: an estimate made from a failed calibration is not usable either.

Likely cause (named when the fit's own status is not ok): each piece of evidence scores 2
(the trial's own figures) or 1 (an earlier stage's verdict); a correction that explains part of
the error (a time shift, a constant offset) scores 2 plus the share it explains, so the one
that explains more wins; ties go in the order geometry, clock, tracking, model.

* geometry: the offset and the rest gap above; the error at rest at least ``REST_RATIO`` (0.5)
  of the moving frames' (the model cannot be wrong about a still, hanging string by much),
  unless the tracked string folds within a segment at rest (``rest_folded_points``): then the
  model can, and that evidence is the model's; calibration's verdict.
* clock: the time shift above (at the gain that warns); sync's verdict.
* tracking: the valid share above; tracking's verdict.
* **pinned** (overrules the above): when the arm's sweep pinned the geometry and the clock
  (``geometry.json`` and ``clock.json`` not failed, their stated uncertainties ``uncertainty_p95_mm`` and
  ``clock_uncertainty_ms`` given, :func:`sweep_bounds`) and tracking is ok or pinned, an error the sweep
  bounds cannot be the cause of a larger one: a mapping known to u mm moves a tracked point by at
  most u, a clock known to c ms by at most c times the string's speed (``speed_median_mm_s``). One
  at most ``PINNED_SHARE`` (1/4) of the fit's median error would leave at least 3/4 of it if taken
  off: it is not the likely cause, and its evidence counts for nothing. A stage's warn is about its
  own tolerance (a mapping known to 2.6 mm where the sweep asks for 1 mm), not about the bound it
  states, whose coverage :mod:`benchmarks.certainty` checks over the lab's family: a warned stage's
  bound still pins; a failed stage's does not. Tracking is pinned likewise by the error scale its
  figures state (``tracking.json``'s ``error_scale_mm``: :func:`stringcast.track.quality.error_scale_mm`;
  none where too few points were tracked or the string ran out of the region tracked). When the
  geometry and the clock are pinned, and tracking is ok or pinned (and the fit's valid share is ok),
  the cause is the model, whatever a constant offset or
  the error at rest suggests (a model that starts from the wrong rest shape or hangs the string
  wrongly also errs at rest and in one direction). The reason says so, with the skill against the
  rigidly carried string where the fit is worse than it, and that recalibrating will not help
  (the issue's field footage: "geometry" in 20 of 33 trials whose sweep-refined mapping was within
  0.4 mm at the string).
* model: the early third of the moving frames fits (error at most ``EARLY_RATIO`` = 0.5 of the
  late third's): the model follows the motion and loses the string later; the error at rest
  where the string folds within a segment (above: of ours' fits in the loop runs of stops 45-47,
  seeds 0-9 of both physics on the lab's exact points, whose strings started curled under a
  gripper pointing left of down, 86 of the 94 with an error at rest over 2 mm had a folded point,
  2 of the 46 others); and, when nothing
  else stands out, the model by default.

* **recording** (overrules a model cause): the tracked string's chords tilt under the grasp's
  acceleration at under ``INERTIA_SHARE_MAX`` (1/4) of what a pendulum of their own swing period does
  (``inertia_share``, :mod:`stringcast.estimate.inertia`, stated on at least ``INERTIA_MIN_POINTS``
  chords). Any string hanging in air feels the grasp's acceleration as a pseudo-force; one that swings
  at a pendulum's period yet does not tilt under it is moving as if carried in the gripper's frame
  without its inertial forces (a simulator that omits them, or a joint log of another motion), and no
  string model's parameters can follow it. Over the lab's string family (five material classes, seven
  string types, ours' first motions, both engines: ``benchmarks/inertia.py``; and the field's motion)
  the chords' shares are 0.81-1.43 where stated; the field recording of issue 52 gives 0.01-0.06 with
  a rotation coupling near 1 (its fit: skill -0.52, the model's cause until then).

Reported in ``fit_check`` but not judged: ``speed_correlation`` (the error's rank correlation
with the model's speed; a clock error makes the error follow the speed) ranges from -0.6 to +0.5
over the demo's fits and their offset and re-timed variants, with no clock fault behind the
high ones; the time shift's gain is the sharper test of the clock. ``bias_share`` likewise gives
way to ``offset_gain``: a time shift during a one-way swing also errs in one direction.
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from stringcast.core import EstimationSettings, Verdict, worst

SHIFT_FRAMES = 3
"""A time shift counts only from this many frame periods (a right sync is within one)."""
SHIFT_FLOOR_SHARE = 0.01
"""The time shift is judged from this error share on (a warn below ``verdict_floor_share``)."""
OFFSET_GAIN = 0.7
"""Geometry: one constant offset taken off cuts the error to at most this share of itself."""
REST_RATIO = 0.5
"""Geometry: the error at rest is at least this share of the moving frames' error."""
EARLY_RATIO = 0.5
"""Model: the early frames' error is at most this share of the late frames'."""
CAUSES = ("geometry", "clock", "tracking", "model", "recording")
UPSTREAM_CAUSE = {"calibration": "geometry", "geometry": "geometry", "sync": "clock", "clock": "clock",
                  "tracking": "tracking"}
CAUSE_WORDS = {"geometry": "geometry (the camera calibration or board pose)", "clock": "the clock (sync)",
               "tracking": "tracking", "model": "the model (it could not follow this motion)",
               "recording": "the recording (the string does not move as a string under gravity and inertia does)"}
PINNED_SHARE = 0.25
"""The sweep pinned an error source when its bound is at most this share of the fit's median error:
taking it off would leave at least 3/4 of the error (module doc, "pinned")."""
INERTIA_SHARE_MAX = 0.25
"""The recording, not the model: the tracked string's tilt answers the grasp's acceleration at under a
quarter of a pendulum's of its own swing period (:mod:`stringcast.estimate.inertia`). Over the lab's
string family the stated chords' shares are 0.97-1.21 (benchmarks/inertia.py: 40 strings, both engines,
ours' first motions; 32 chords on 11 of them) and 0.81-1.43 under the field's motion (MuJoCo, 21
strings, 14 chords); the field recording of issue 52 gives 0.01-0.06."""
INERTIA_MIN_POINTS = 2
"""The recording is named only where the share is stated on at least this many chords."""
MODEL_ADVICE = ("recalibrating will not help; look at the model instead: widen model.ranges, or plan a gentler "
                "motion")


def _get(fig: Mapping, key: str) -> float | None:
    v = fig.get(key)
    return None if v is None or not np.isfinite(v) else float(v)


def _shift(fig: Mapping) -> float | None:
    """The time shift's gain when it counts (>= SHIFT_FRAMES, error share >= SHIFT_FLOOR_SHARE), else None."""
    share, frames, gain = _get(fig, "error_share"), _get(fig, "best_shift_frames"), _get(fig, "shift_gain")
    if share is None or frames is None or gain is None or share < SHIFT_FLOOR_SHARE or abs(frames) < SHIFT_FRAMES:
        return None
    return gain


def _offset(fig: Mapping, est: EstimationSettings) -> float | None:
    """The constant offset's gain when it counts (module doc, "Offset"), else None."""
    share, gain, L = _get(fig, "error_share"), _get(fig, "offset_gain"), float(fig.get("length_mm") or 0.0)
    if share is None or gain is None or share <= est.verdict_floor_share or gain > OFFSET_GAIN:
        return None
    if np.hypot(*fig["bias_mm"]) < est.verdict_floor_share * L or gain >= (_shift(fig) or 1.0):
        return None
    return gain


def _status_reasons(fig: Mapping, E_mm: float, est: EstimationSettings) -> Verdict:
    """The fit's own status from its figures (module doc, "Status")."""
    v = Verdict()
    if not np.isfinite(E_mm):
        v = v.add("fail", "every parameter set blew up or was invalid (E = inf): the estimate is not usable; "
                          "check the tracked rest state and the model's parameter ranges")
    share, L, err = _get(fig, "error_share"), float(fig.get("length_mm") or 0.0), _get(fig, "error_median_mm")
    if share is not None and share >= est.verdict_error_share[0]:
        status = "fail" if share >= est.verdict_error_share[1] else "warn"
        v = v.add(status, f"the fitted string is {err:.0f} mm from the tracked one at the median moving frame "
                          f"({share:.0%} of its {L:.0f} mm length; E = {E_mm:.0f} mm): "
                          + ("the estimate is not usable" if status == "fail" else "the estimate is doubtful"))
    judged = share is not None and share > est.verdict_floor_share
    skill = _get(fig, "skill")
    if skill is not None and skill <= 0 and not judged:            # worse than no dynamics: never usable
        v = v.add("fail", f"the fit is no closer to the tracked string than the string carried rigidly without "
                          f"swinging ({err:.1f} against {fig['null_error_median_mm']:.1f} mm at the median frame): "
                          "the model adds nothing to no dynamics at all, and its predictions are not to be trusted")
    if judged and skill is not None and skill <= est.verdict_skill[0]:
        v = v.add("fail" if skill <= est.verdict_skill[1] else "warn",
                  f"the fit explains only {max(skill, 0):.0%} of the tracked motion: a string carried without "
                  f"swinging is {fig['null_error_median_mm']:.0f} mm off at the median frame, the fit {err:.0f} mm")
    gain = _shift(fig)
    if gain is not None and gain <= est.verdict_shift_gain[0 if judged else 1]:
        v = v.add("fail" if gain <= est.verdict_shift_gain[1] and judged else "warn",
                  f"shifting the frames' times by {fig['best_shift_ms']:+.1f} ms ({int(fig['best_shift_frames']):+d} "
                  f"frame periods) cuts the fit's error to {gain:.0%} of itself: the video and the joint log are "
                  "likely compared at the wrong times; check sync.json")
    if _offset(fig, est) is not None:
        dx, dy = fig["bias_mm"]
        v = v.add("warn", f"the tracked string is offset by ({dx:+.0f}, {dy:+.0f}) mm from the fitted one over the "
                          f"whole motion (taking it off cuts the error to {fig['offset_gain']:.0%}): no parameter "
                          "set moves a string hanging from the measured grasp so; check the calibration")
    valid = _get(fig, "valid_share")
    if valid is not None and valid < est.verdict_min_valid_share:
        v = v.add("warn", f"only {valid:.0%} of the string's points were tracked in the moving frames (under "
                          f"{est.verdict_min_valid_share:.0%}): check the tracking overlay")
    gap = _get(fig, "rest_gap_share")
    if gap is not None and gap > est.verdict_rest_gap_share:
        v = v.add("warn", f"at rest a tracked point hangs {gap * L:.0f} mm farther from the grasp point than the "
                          "string up to it is long: check the calibration (board pose, intrinsics)")
    return v


def _evidence(fig: Mapping, est: EstimationSettings, upstream: Mapping[str, Verdict]) -> dict[str, list]:
    """Per cause: (score, sentence) pairs of evidence (module doc, "Likely cause")."""
    ev: dict[str, list] = {c: [] for c in CAUSES}
    share = _get(fig, "error_share")
    judged = share is not None and share > est.verdict_floor_share
    offset, shift = _offset(fig, est), _shift(fig)
    if offset is not None:
        dx, dy = fig["bias_mm"]
        ev["geometry"].append((3 - offset, f"one constant offset of the whole string ({dx:+.0f}, {dy:+.0f} mm) "
                                           f"takes off {1 - offset:.0%} of the error"))
    gap = _get(fig, "rest_gap_share")
    if gap is not None and gap > est.verdict_rest_gap_share:
        ev["geometry"].append((2, "the tracked string at rest does not hang from the grasp point"))
    err, rest = _get(fig, "error_median_mm"), _get(fig, "rest_error_mm")
    if judged and rest is not None and err and rest >= REST_RATIO * err:
        folds = list(fig.get("rest_folded_points") or [])
        if folds:
            ev["model"].append((2, f"the error is already {rest:.0f} mm at rest, where the string folds within a "
                                   f"segment (points {folds}): the model's straight segments cannot start so"))
        else:
            ev["geometry"].append((2, f"the error is already {rest:.0f} mm at rest, before the motion"))
    if shift is not None and shift <= est.verdict_shift_gain[0 if judged else 1]:
        ev["clock"].append((3 - shift, f"re-timing the frames by {fig['best_shift_ms']:+.1f} ms takes off "
                                       f"{1 - shift:.0%} of the error"))
    valid = _get(fig, "valid_share")
    if valid is not None and valid < est.verdict_min_valid_share:
        ev["tracking"].append((2, f"{1 - valid:.0%} of the string's points are not tracked"))
    early, late = _get(fig, "early_error_mm"), _get(fig, "late_error_mm")
    if judged and early is not None and late and early <= EARLY_RATIO * late:
        ev["model"].append((2, f"the early frames fit ({early:.0f} mm) and the error grows late ({late:.0f} mm)"))
    for stage, v in upstream.items():
        if not v.ok and stage in UPSTREAM_CAUSE:
            ev[UPSTREAM_CAUSE[stage]].append((1, f"{stage}'s verdict is {v.status}"))
    return ev


def sweep_bounds(geometry: Mapping | None, clock: Mapping | None, tracking: Mapping | None = None) -> dict:
    """The bounds the arm's sweep states on the geometry and the clock, from ``geometry.json`` and
    ``clock.json`` (their ``"sweep"`` blocks), and tracking's from ``tracking.json``:
    ``{"mapping_uncertainty_mm", "clock_uncertainty_ms"}``, each None where the sweep did not run (no
    block, ``applied`` false) or states none, and ``tracking_scale_mm``, ``tracking.json``'s stated
    error scale (None without one)."""
    def get(doc, key):
        block = (doc or {}).get("sweep") or {}
        v = block.get(key) if block.get("applied") else None
        return None if v is None or not np.isfinite(v) else float(v)
    scale = (tracking or {}).get("error_scale_mm")
    return {"mapping_uncertainty_mm": get(geometry, "uncertainty_p95_mm"),
            "clock_uncertainty_ms": get(clock, "clock_uncertainty_ms"),
            "tracking_scale_mm": None if scale is None or not np.isfinite(scale) else float(scale)}


def _pinned(fig: Mapping, upstream: Mapping[str, Verdict], sweep: Mapping | None) -> dict[str, str]:
    """The causes the sweep rules out (module doc, "pinned"): ``{"geometry" | "clock": how, in words}``
    for each whose verdict is not fail and whose bound is at most ``PINNED_SHARE`` of the fit's median error
    (tracking's: its stated error scale)."""
    err, speed = _get(fig, "error_median_mm"), _get(fig, "speed_median_mm_s")
    if err is None or err <= 0:
        return {}
    u_map, u_clock = ((sweep or {}).get(k) for k in ("mapping_uncertainty_mm", "clock_uncertainty_ms"))
    out = {}
    if (u_map is not None and "geometry" in upstream and upstream["geometry"].status != "fail"
            and u_map <= PINNED_SHARE * err):
        out["geometry"] = f"the mapping to {u_map:.2f} mm"
    if (u_clock is not None and speed is not None and "clock" in upstream and upstream["clock"].status != "fail"
            and u_clock * speed / 1000 <= PINNED_SHARE * err):
        out["clock"] = f"the clock to {u_clock:.2f} ms ({u_clock * speed / 1000:.1f} mm at the string's median speed)"
    u_track = (sweep or {}).get("tracking_scale_mm")
    if (u_track is not None and "tracking" in upstream and upstream["tracking"].status != "fail"
            and u_track <= PINNED_SHARE * err):
        out["tracking"] = f"its errors to {u_track:.1f} mm"
    return out


def _model_pinned(fig: Mapping, est: EstimationSettings, upstream: Mapping[str, Verdict], pinned: dict) -> str | None:
    """The evidence that the model is the cause because the sweep pinned the geometry and the clock and
    tracking is ok or pinned (and the fit's valid share is ok), in words; None where not."""
    valid = _get(fig, "valid_share")
    tracking_ok = "tracking" not in upstream or upstream["tracking"].ok or "tracking" in pinned
    if "geometry" not in pinned or "clock" not in pinned or not tracking_ok or (
            valid is not None and valid < est.verdict_min_valid_share):
        return None
    err, skill = _get(fig, "error_median_mm"), _get(fig, "skill")
    worse = "" if skill is None or skill > 0 else (
        f"; the fit is farther from the tracked string than the string carried rigidly without swinging "
        f"({err:.0f} against {fig['null_error_median_mm']:.0f} mm)")
    track = f", and tracking's own figures state {pinned['tracking']}" if "tracking" in pinned else ""
    ok = "" if "tracking" in pinned else ", and tracking is ok"
    return (f"the arm's sweep pinned {pinned['geometry']} and {pinned['clock']}{track}, each at most "
            f"{PINNED_SHARE:.0%} of the fit's {err:.0f} mm error{ok}: neither the geometry, the clock nor "
            f"tracking accounts for it{worse}; {MODEL_ADVICE}")


def _not_inertial(fig: Mapping) -> str | None:
    """The evidence that the tracked string ignores the grasp's acceleration (module doc, "recording"), in
    words; None where the share is not stated on :data:`INERTIA_MIN_POINTS` chords or is at least
    :data:`INERTIA_SHARE_MAX`."""
    share, points = _get(fig, "inertia_share"), list(fig.get("inertia_points") or [])
    if share is None or len(points) < INERTIA_MIN_POINTS or share >= INERTIA_SHARE_MAX:
        return None
    coupling, period = _get(fig, "rotation_coupling"), _get(fig, "swing_period_s")
    turn = "" if coupling is None else f" and takes {coupling:.0%} of the hand's angular acceleration"
    swing = "" if period is None else f" (it swings freely with a period of {period:.2f} s)"
    return (f"the tracked string tilts under the grasp's acceleration at {share:.0%} of what a pendulum of its "
            f"own swing period does{swing}{turn} (chords to points {points}); every string, rope or chain "
            f"hanging in air tilts at {INERTIA_SHARE_MAX:.0%} of it or more (the lab's string family on both "
            "engines, thread to chain: 81 % or more): it moves as if carried in the gripper's frame without that frame's inertial "
            "forces, which no parameter set of a string model follows. Check that the joint log is this "
            "video's motion and, on a simulator, that the string feels the gripper's acceleration")


def likely_cause(fig: Mapping, est: EstimationSettings, upstream: Mapping[str, Verdict],
                 sweep: Mapping | None = None) -> tuple[str, str]:
    """(cause, the evidence in words) of module doc's "Likely cause"; ``model`` with no evidence. A cause the
    sweep ruled out (``sweep``: :func:`sweep_bounds`; module doc, "pinned") has no evidence, and where it
    ruled out both the geometry and the clock and tracking is ok or pinned, the cause is the model; a model
    cause is the recording's where the tracked string ignores the grasp's acceleration (:func:`_not_inertial`)."""
    cause, why = _likely_cause(fig, est, upstream, sweep)
    recording = _not_inertial(fig) if cause == "model" else None
    return ("recording", recording) if recording else (cause, why)


def _likely_cause(fig: Mapping, est: EstimationSettings, upstream: Mapping[str, Verdict],
                  sweep: Mapping | None = None) -> tuple[str, str]:
    """:func:`likely_cause` before the inertia check."""
    pinned = _pinned(fig, upstream, sweep)
    model = _model_pinned(fig, est, upstream, pinned)
    if model is not None:
        return "model", model
    ev = _evidence(fig, est, upstream)
    for c in pinned:
        ev[c] = []
    score = {c: sum(w for w, _ in ev[c]) for c in CAUSES}
    best = max(CAUSES, key=lambda c: (score[c], -CAUSES.index(c)))
    if score[best] == 0:
        swept = [v for c, v in pinned.items() if c != "tracking"]
        ruled = (f" (the arm's sweep pinned {' and '.join(swept)})" if swept else "") + (
            f" (tracking's own figures state {pinned['tracking']})" if "tracking" in pinned else "")
        return "model", f"no sign of a geometry, clock or tracking fault in this trial's figures{ruled}"
    return best, "; ".join(s for _, s in ev[best])


def fit_verdict(fig: Mapping, E_mm: float, estimation: EstimationSettings,
                upstream: Mapping[str, Verdict] | None = None, sweep: Mapping | None = None) -> tuple[Verdict, str]:
    """The fit's verdict and its likely cause (module doc).

    Args:
        fig: :func:`stringcast.estimate.fitcheck.fit_figures`' figures of this trial's fit.
        E_mm: E of the estimate, mm (inf: every candidate blew up).
        estimation: the ``verdict_*`` thresholds (:class:`~stringcast.core.EstimationSettings`).
        upstream: the earlier stages' verdicts by stage name ("geometry", "clock", "tracking"; older
            results: "calibration", "sync").
        sweep: the sweep's bounds on the geometry and the clock (:func:`sweep_bounds`), or None.

    Returns:
        (verdict, likely cause): the cause is one of :data:`CAUSES`, or "" when the verdict is ok.
    """
    upstream = dict(upstream or {})
    own = _status_reasons(fig, E_mm, estimation)
    cause = ""
    if not own.ok:
        cause, why = likely_cause(fig, estimation, upstream, sweep)
        own = own.add(own.status, f"likely cause: {CAUSE_WORDS[cause]}: {why}")
    carried = [Verdict(v.status, tuple(r if r.startswith(f"{stage}: ") else f"{stage}: {r}" for r in v.reasons))
               for stage, v in upstream.items() if not v.ok]   # each stage named once
    verdict = worst(own, *carried)
    if not cause and not verdict.ok:
        cause = next((UPSTREAM_CAUSE[s] for s, v in upstream.items() if not v.ok and s in UPSTREAM_CAUSE), "")
    return verdict, cause
