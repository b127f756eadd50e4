"""How far to trust the video's offset, and whether it overrules the recording's trigger time.

Both candidates are judged by one measure, the arm-match residual
(:func:`stringcast.sync.arm_match.match_residual`: the robust spread of the distance across
each arm segment between where a frame shows it and where the forward kinematics put it),
over the frames and agreeing segments the video's estimate rests on. Its noise is measured
on the clip itself, by a **moving-block bootstrap** over the frames (Kuensch 1989): the
frames' errors are not independent (a calibration or board-pose error, a shadow, biases a
whole stretch of the motion the same way), so frames are resampled in runs whose length is
where the autocorrelation of the frames' own match errors first reaches zero. A run of
correlated frames then counts as one piece of evidence, as it should.

* :func:`compare_residuals`: the residual at the trigger's offset minus that at the video's,
  over the block resamples. The video overrules the trigger only when the trigger's residual
  is as small as the video's in fewer than ``norm.sf(evidence_k)`` of them (0.13 % at k = 3):
  a one-sided test at ``evidence_k`` standard errors' confidence, in units of the clip's own
  noise, not a millisecond threshold tuned on one camera.
* :func:`systematic_ms`: what no resampling of the frames sees (issue 51: on another lab's footage
  the video overruled the trigger 6 times "as well in 0 of 4000 block resamples", 5 of them wrongly,
  the video's offset 2.8-10.9 ms off): an error of the mapping where the arm is, common to the
  whole clip. A segment displaced by e across itself while it moves at v across itself matches
  best e / v away from the true offset; the summed score's peak weighs each frame's and segment's
  match by its sharpness, which grows as v^2, so a displacement of at most E everywhere biases the
  peak by at most E sum v / sum v^2 = E / v_eff. E is the board check's |d| (the mapping's error at
  the still arm; the strips are moved by d, which takes off only the part of the error that is
  the same everywhere, and an error of the intrinsics is not: it changes over the region the arm
  sweeps by as much as it is), or, where the check found d to be the board pose's (a rigid shift
  beyond what the intrinsics explain, its ``likely_cause``), which the shift takes off, the
  features' own scatter about that shift (``fit_rms_mm``); without a board check, the arm-match
  residual. The video's
  **uncertainty** is then ``evidence_k`` standard errors plus that bound, and the video overrules a
  trigger time only when the trigger lies outside it too (:func:`choose_offset`).
* :func:`video_quality`: the video estimate's own standard error (the same bootstrap of the
  summed match score's peak), a second peak of similar height (ambiguous), too few frames,
  segments that disagree, and a residual or an uncertainty larger than ``match_warn_px``
  pixels at the arm (edges of a sharp arm localise to a fraction of a pixel; more means the
  calibration or the forward kinematics do not fit the images, or the frames disagree).
"""
from __future__ import annotations

import math

import numpy as np

from . import arm_match as sync_arm
from stringcast.core import SyncSettings, Verdict

BOOTSTRAP_SAMPLES = 4000
"""Block-bootstrap resamples (seeded: the same clip gives the same verdict); enough to resolve the
one-sided tail norm.sf(evidence_k) (0.13 % at k = 3: about 5 resamples)."""
MIN_SPEED = 1e-3
"""m/s: a segment slower than this across itself says nothing about the offset (as in match_residual)."""


def block_length(series: np.ndarray) -> int:
    """Frames per bootstrap block: the first lag at which the autocorrelation of ``series`` (N,)
    (the frames' own match errors, in frame order) reaches zero; 1 for white noise, at most N // 2."""
    x = np.asarray(series, float)
    x = x[np.isfinite(x)] - np.nanmean(x)
    den = float(np.sum(x * x))
    if len(x) < 4 or den <= 0:
        return 1
    for lag in range(1, len(x) // 2):
        if np.sum(x[:-lag] * x[lag:]) <= 0:
            return lag
    return max(1, len(x) // 2)


def block_counts(n: int, length: int, samples: int = BOOTSTRAP_SAMPLES, seed: int = 0) -> np.ndarray:
    """(samples, n) how often each of n frames is drawn in a moving-block bootstrap resample
    (ceil(n / length) runs of ``length`` consecutive frames, starts uniform, cut to n)."""
    length = int(min(max(1, length), n))
    rng = np.random.default_rng(seed)
    n_blocks = -(-n // length)
    starts = rng.integers(0, n - length + 1, (samples, n_blocks))
    picks = (starts[:, :, None] + np.arange(length)).reshape(samples, -1)[:, :n]
    return np.stack([np.bincount(p, minlength=n) for p in picks])


def _weighted_mad_mm(d: np.ndarray, frame_of: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """1.4826 x the weighted median of |d| (E,) m, each entry weighted by its frame's count
    (B, F) (frame_of (E,) its frame) -> (B,) mm."""
    order = np.argsort(np.abs(d))
    w = counts[:, frame_of[order]].astype(float)
    cum = np.cumsum(w, axis=1)
    idx = np.argmax(cum >= 0.5 * cum[:, -1:], axis=1)
    return 1.4826 * np.abs(d)[order][idx] * 1000


def _equations(evidence) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The matches of the agreeing segments (all segments if none agrees): tau (F, S') s, speeds
    (F, S') m/s, ok (F, S') bool, and each ok entry's frame (E,)."""
    keep = evidence.keep if evidence.keep.any() else np.ones_like(evidence.keep)
    tau, a = evidence.tau_ks[:, keep], evidence.speeds[:, keep]
    ok = np.isfinite(tau) & np.isfinite(a) & (a > MIN_SPEED)
    return tau, a, ok, np.nonzero(ok)[0]


def frame_errors(evidence, offset_s: float) -> np.ndarray:
    """(F,) m: each motion frame's mean signed distance across the agreeing segments between the
    arm seen and the arm predicted at ``offset_s`` (NaN where no segment matched): the series
    whose autocorrelation sets the bootstrap's block length."""
    tau, a, ok, _ = _equations(evidence)
    d = np.where(ok, a * (tau - offset_s), 0.0)
    n = ok.sum(axis=1)
    return np.where(n > 0, d.sum(axis=1) / np.maximum(n, 1), np.nan)


def compare_residuals(evidence, video_s: float, trigger_s: float) -> dict:
    """The arm-match residual at the video's and at the trigger's offset, and how sure the difference is.

    Both from the same matches (every motion frame's and agreeing segment's own best offset,
    times the segment's speed across itself at the video's offset: a paired comparison), as in
    :func:`~stringcast.sync.arm_match.match_residual`. The frames are resampled in blocks
    (:func:`block_counts`); ``p`` is the share of resamples in which the trigger's residual is no
    larger than the video's: a one-sided bootstrap test, which assumes no normal law (at a wrong
    offset the residual grows with the arm's speed, which varies over the motion, so the excess
    is skewed and its standard deviation alone understates how rarely it reaches zero).

    Returns:
        ``{"video_mm", "trigger_mm", "excess_mm"`` (trigger minus video), ``"standard_error_mm"``
        (of the excess over the resamples), ``"p"``, ``"resamples", "block_frames", "matches"}``;
        residuals None with fewer than 3 matches.
    """
    tau, a, ok, frame_of = _equations(evidence)
    out = {"video_mm": None, "trigger_mm": None, "excess_mm": None, "standard_error_mm": None, "p": None,
           "resamples": BOOTSTRAP_SAMPLES, "block_frames": None, "matches": int(ok.sum())}
    if ok.sum() < 3:
        return out
    length = block_length(frame_errors(evidence, video_s))
    counts = block_counts(tau.shape[0], length)
    d_v, d_t = (a * (tau - video_s))[ok], (a * (tau - trigger_s))[ok]
    r_v = sync_arm.match_residual(tau, a, video_s)[0]
    r_t = sync_arm.match_residual(tau, a, trigger_s)[0]
    boot = _weighted_mad_mm(d_t, frame_of, counts) - _weighted_mad_mm(d_v, frame_of, counts)
    out.update(video_mm=r_v, trigger_mm=r_t, excess_mm=r_t - r_v, standard_error_mm=float(np.std(boot)),
               p=float(np.mean(boot <= 0)), block_frames=length)
    return out


def _score_bootstrap(evidence, offset_s: float) -> tuple[np.ndarray, np.ndarray, int]:
    """The summed match score of the agreeing segments (T,), its block-bootstrap resamples (B, T),
    and the block length in frames."""
    keep = evidence.keep if evidence.keep.any() else np.ones_like(evidence.keep)
    curves = evidence.per_frame[:, :, keep].sum(axis=2)  # (C, T)
    length = block_length(frame_errors(evidence, offset_s))
    return curves.sum(axis=0), block_counts(len(curves), length) @ curves, length


def _second_peak(taus: np.ndarray, score: np.ndarray, boot: np.ndarray, k: float) -> float | None:
    """The offset s of a second maximum of ``score`` (T,) that is a peak of its own (above the
    valley towards the highest by more than k standard errors) and as high as the highest within
    k standard errors (of the paired differences over the resamples ``boot`` (B, T)); else None."""
    i = int(np.argmax(score))
    best = None
    for j in range(1, len(score) - 1):
        if j == i or score[j] < score[j - 1] or score[j] < score[j + 1]:
            continue
        lo, hi = sorted((i, j))
        v = lo + int(np.argmin(score[lo:hi + 1]))
        rises = score[j] - score[v] > k * np.std(boot[:, j] - boot[:, v])
        similar = score[i] - score[j] <= k * np.std(boot[:, i] - boot[:, j])
        if rises and similar and (best is None or score[j] > score[best]):
            best = j
    return None if best is None else float(taus[best])


def systematic_ms(evidence, est: dict) -> tuple[float | None, float | None, float | None]:
    """The bound on the video offset's error from the mapping's error at the arm (module doc):
    (bound ms, E mm, v_eff m/s); None where no matches move (no speed) or no E is known.

    Args:
        evidence: :class:`~stringcast.sync.video_offset.VideoEvidence` (the agreeing segments' speeds).
        est: the estimate's dict: ``board_check`` (its ``residual_mm`` |d|, ``likely_cause``, ``fit_rms_mm``)
            and ``residual_mm``.
    """
    _, a, ok, _ = _equations(evidence)
    v = np.abs(a[ok])
    v_eff = float(np.sum(v ** 2) / np.sum(v)) if v.size and np.sum(v) > 0 else None
    bc = est.get("board_check") or {}
    E = bc.get("fit_rms_mm") if bc.get("likely_cause") == "board_pose" else bc.get("residual_mm")
    if E is None or not np.isfinite(E):
        E = est.get("residual_mm")
    if v_eff is None or E is None or not np.isfinite(E):
        return None, None, v_eff
    return float(E) / v_eff, float(E), v_eff


def video_quality(evidence, est: dict, st: SyncSettings) -> tuple[dict, list[str]]:
    """The video estimate's standard error and what makes it doubtful.

    Args:
        evidence: :class:`~stringcast.sync.video_offset.VideoEvidence`; est: the estimate
            (:func:`~stringcast.sync.video_offset.estimate_offset`'s dict); st: the sync settings.

    Returns:
        (figures, reasons): figures ``{"standard_error_ms", "ambiguous", "second_peak_s",
        "block_frames", "residual_px", "arm_width_px", "uncertainty_px", "systematic_ms",
        "mapping_error_mm", "speed_eff_m_s", "uncertainty_ms"}`` (:func:`systematic_ms`; the
        uncertainty ``evidence_k`` standard errors plus the systematic bound, None where that is
        not known); reasons, one
        sentence per cause (empty when the estimate is sound): an ambiguous or edge peak, fewer
        than ``min_frames`` frames, agreeing segments not a majority of those with a peak of their
        own, a residual or an uncertainty (``evidence_k`` standard errors times the arm's median
        speed across itself) over ``match_warn_px``.
    """
    k, taus, px = float(st.evidence_k), evidence.taus, evidence.mm_per_px
    score, boot, length = _score_bootstrap(evidence, est["offset_s"])
    peaks = np.array([sync_arm.parabola_peak(taus, b) for b in boot])
    se_s = float(np.std(peaks))
    second = _second_peak(taus, score, boot, k)
    _, a, ok, _ = _equations(evidence)
    speed = float(np.median(a[ok])) if ok.any() else 0.0
    residual = est.get("residual_mm")
    sys_ms, e_mm, v_eff = systematic_ms(evidence, est)
    fig = {"standard_error_ms": se_s * 1000, "ambiguous": second is not None, "second_peak_s": second,
           "block_frames": length, "residual_px": None if residual is None else residual / px,
           "arm_width_px": evidence.arm_width_mm / px, "uncertainty_px": k * se_s * speed * 1000 / px,
           "systematic_ms": sys_ms, "mapping_error_mm": e_mm, "speed_eff_m_s": v_eff,
           "uncertainty_ms": None if sys_ms is None else k * se_s * 1000 + sys_ms}
    reasons = []
    i = int(np.argmax(score))
    if i in (0, len(score) - 1):
        fig["ambiguous"] = True
        reasons.append(f"the video's match score peaks at the edge of its search window ({taus[i]:.4f} s): the offset "
                       "lies outside it or the arm's match does not depend on it; widen sync.search_ms or check the "
                       "calibration")
    if second is not None:
        reasons.append(f"the video's match has two peaks of similar height, at {est['offset_s']:.4f} s and "
                       f"{second:.4f} s (within {k:g} standard errors): the offset is ambiguous")
    if est["frames_used"] < st.min_frames:
        reasons.append(f"only {est['frames_used']} frames show the arm's match depend on the offset (sync.min_frames: "
                       f"{st.min_frames}): film more of the motion, or a faster one")
    seg_peaks = np.asarray(est["segment_offsets_s"])
    inside = (seg_peaks > taus[0] + 0.5 * (taus[1] - taus[0])) & (seg_peaks < taus[-1] - 0.5 * (taus[1] - taus[0]))
    agree = int(np.sum(inside & evidence.keep))
    if 2 * agree <= int(inside.sum()):
        reasons.append(f"only {agree} of the {int(inside.sum())} arm segments with a peak of their own agree on the "
                       f"offset (within sync.segment_agree_ms): the arm's match is inconsistent along the arm")
    if fig["residual_px"] is not None and fig["residual_px"] > st.match_warn_px:
        reasons.append(f"the arm-match residual is {residual:.2f} mm = {fig['residual_px']:.1f} px "
                       f"(sync.match_warn_px: {st.match_warn_px:g}; the arm is {fig['arm_width_px']:.0f} px wide): "
                       "the arm is not where the calibration and the forward kinematics put it; check the "
                       "calibration and the board pose")
    if fig["uncertainty_px"] > st.match_warn_px:
        reasons.append(f"the video's offset is uncertain by +-{k * se_s * 1000:.2f} ms ({k:g} standard errors over "
                       f"runs of {length} frames), {fig['uncertainty_px']:.1f} px at the arm's speed "
                       f"(sync.match_warn_px: {st.match_warn_px:g}): the frames disagree on the offset")
    return fig, reasons


def choose_offset(est: dict | None, failure: str | None, trigger_s: float | None, st: SyncSettings) -> dict:
    """The offset to use: the video's estimate or the recording's trigger time, and the verdict.

    * No trigger time: the video's estimate; ``warn`` with :func:`video_quality`'s reasons.
    * The video gave no estimate (``failure``) or an ambiguous one: the trigger time, ``warn``.
    * Otherwise the trigger time is kept unless the arm matches the frames clearly worse at it
      (:func:`compare_residuals`: as well in fewer than ``norm.sf(evidence_k)`` of the block
      resamples) **and** it lies outside the video's uncertainty (:func:`video_quality`'s
      ``uncertainty_ms``: the frames' noise plus the bound of :func:`systematic_ms`, which the
      resamples cannot see; a trigger kept for that reason alone gets a note saying so);
      overruled, the verdict stays ``ok`` (unless the video's quality warns) with a
      reason naming both offsets and residuals: the choice is recorded with both candidates, never
      silent, and a sound video estimate that clearly fits better is the better offset (a wrong
      trigger is common: its delay, the camera's own). Kept, the verdict is ``ok`` when the video's
      estimate is sound (it would have seen a trigger that is off), else ``warn``: not confirmed.

    Args:
        est: :func:`~stringcast.sync.video_offset.estimate_offset`'s dict (with its evidence), or None.
        failure: why the video gave no estimate (with est None).
        trigger_s: video.yaml's trigger time, s, or None.
        st: the sync settings.

    Returns:
        ``{"chosen": "trigger" | "video", "offset_s", "uncertainty_ms", "candidates": {"trigger": {...},
        "video": {...}}, "verdict": Verdict}``; a candidate that is absent is missing from ``candidates``.
        ``uncertainty_ms`` bounds the chosen offset's error: the video's uncertainty for the video's
        offset, and the trigger's distance from the video's offset plus that for a trigger kept against
        it (the video found it no worse than its own offset); None where not determined (no video
        estimate, or its systematic bound unknown).

    Raises:
        ValueError: neither an estimate nor a trigger time.
    """
    if est is None and trigger_s is None:
        raise ValueError("choose_offset needs the video's estimate or a trigger time")
    cands, v = {}, Verdict()
    if est is None:
        cands["video"] = {"offset_s": None, "residual_mm": None, "error": failure}
        cands["trigger"] = {"offset_s": float(trigger_s), "residual_mm": None}
        v = v.add("warn", f"the video gave no offset ({failure}); video.yaml's trigger time {trigger_s:.5f} s is used "
                          "unchecked")
        return {"chosen": "trigger", "offset_s": float(trigger_s), "uncertainty_ms": None, "candidates": cands,
                "verdict": v}
    ev, video_s, k = est["evidence"], float(est["offset_s"]), float(st.evidence_k)
    fig, reasons = video_quality(ev, est, st)
    tau, a, _, _ = _equations(ev)
    cands["video"] = {"offset_s": video_s, "residual_mm": sync_arm.match_residual(tau, a, video_s)[0],
                      "time_residual_ms": est["time_residual_ms"], "frames_used": est["frames_used"],
                      "segments_used": est["segments_used"], **fig}
    if trigger_s is None:
        for r in reasons:
            v = v.add("warn", r)
        return {"chosen": "video", "offset_s": video_s, "uncertainty_ms": fig["uncertainty_ms"], "candidates": cands,
                "verdict": v}
    cmp = compare_residuals(ev, video_s, float(trigger_s))
    alpha = 0.5 * math.erfc(k / math.sqrt(2.0))   # the normal tail norm.sf(k), without importing scipy.stats (0.8 s)
    gap_ms, u = (float(trigger_s) - video_s) * 1000, fig["uncertainty_ms"]
    cands["trigger"] = {"offset_s": float(trigger_s), "residual_mm": cmp["trigger_mm"],
                        "minus_video_ms": gap_ms, "excess_mm": cmp["excess_mm"],
                        "excess_standard_error_mm": cmp["standard_error_mm"], "excess_p": cmp["p"],
                        "excess_p_needed": alpha, "resamples": cmp["resamples"], "block_frames": cmp["block_frames"],
                        "beyond_video_uncertainty": None if u is None else abs(gap_ms) > u}
    fits_better = not fig["ambiguous"] and cmp["p"] is not None and cmp["excess_mm"] > 0 and cmp["p"] < alpha
    if fits_better and u is not None and abs(gap_ms) > u:   # clearly better evidence: a note, not a warning
        v = v.add("ok", _overruled(float(trigger_s), video_s, cmp, fig, k, alpha))
        for r in reasons:
            v = v.add("warn", r)
        return {"chosen": "video", "offset_s": video_s, "uncertainty_ms": u, "candidates": cands, "verdict": v}
    if fits_better:
        v = v.add("ok", f"video.yaml's trigger time {trigger_s:.5f} s is kept: the arm matches the frames better at "
                        f"the video's offset {video_s:.5f} s ({gap_ms:+.2f} ms; residual {cmp['video_mm']:.2f} against "
                        f"{cmp['trigger_mm']:.2f} mm), but the trigger lies within the video's uncertainty "
                        f"{_uncertainty_words(fig, k)}")
    for r in reasons:
        v = v.add("warn", f"video.yaml's trigger time {trigger_s:.5f} s is kept, but the video cannot confirm it: {r}")
    return {"chosen": "trigger", "offset_s": float(trigger_s), "uncertainty_ms": None if u is None else abs(gap_ms) + u,
            "candidates": cands, "verdict": v}


def _uncertainty_words(fig: dict, k: float) -> str:
    """The video's uncertainty and its two parts, in words (``+-U ms: ...``); "not determined" without it."""
    u, sys_ms = fig["uncertainty_ms"], fig["systematic_ms"]
    if u is None:
        return "(not determined)"
    return (f"+-{u:.2f} ms: {k:g} standard errors over the frames (+-{u - sys_ms:.2f} ms) and +-{sys_ms:.2f} ms from a "
            f"mapping error of up to {fig['mapping_error_mm']:.1f} mm at the arm (the board check), seen by a match "
            f"at {fig['speed_eff_m_s']:.2f} m/s, which no resampling of the frames sees")


def _overruled(trigger_s: float, video_s: float, cmp: dict, fig: dict, k: float, alpha: float) -> str:
    """The note of an overruled trigger time: both offsets and residuals, the video's uncertainty, and the
    resampling test's count only where the frames' own noise, not the systematic bound, dominates it."""
    u, sys_ms = fig["uncertainty_ms"], fig["systematic_ms"]
    resampled = "" if sys_ms >= u - sys_ms else (
        f", and as well in {round(cmp['p'] * cmp['resamples'])} of {cmp['resamples']} block resamples of the frames "
        f"(fewer than {alpha:.2%} needed, sync.evidence_k: {k:g})")
    return (f"video.yaml's trigger time {trigger_s:.5f} s is overruled by the video's offset {video_s:.5f} s "
            f"({(trigger_s - video_s) * 1000:+.2f} ms, beyond the video's uncertainty {_uncertainty_words(fig, k)}): "
            f"the arm matches the frames with a residual of {cmp['trigger_mm']:.2f} mm at the trigger's offset against "
            f"{cmp['video_mm']:.2f} mm at the video's{resampled}; check the trigger's wiring and delay")

