"""Settings: one frozen, typed object per config section, with every default in one place.

``config/config.yaml`` describes the lab (arms, cameras, set-ups, strings, targets, and the
virtual lab's hidden physics); the stages' settings default to the classes below, which are
ours (``config/paper.yaml`` sets the paper's method, the baseline: ``--method paper``). A config file (``--configfile``) sets any of them, section by section;
:func:`settings_from_config` builds every section once from the merged, schema-validated
config, and refuses a key no class knows. ``config/README.md`` lists every setting with its
default and meaning (made from these classes by ``stringcast settings --markdown``).

A stage's entry point names the settings it reads by its parameters' types (for example
``run_estimation(..., estimation: EstimationSettings, evaluation: EvaluationSettings, ...)``);
:func:`.sections.sections_read` reads them back, so the workflow reruns a stage exactly when a
section it reads changes (``workflow/rules/common.smk``).

Units are those of the key's suffix (``_mm``, ``_px``, ``_s``, ``_deg``, ``_rad_s``); the
stages convert on use, as they did when the settings were a dict.
"""
from __future__ import annotations

import typing
from dataclasses import dataclass, field
from typing import Any
from collections.abc import Mapping

from .errors import ConfigError
from .section import Section, one_of, section_schema
from .section import setting as _f

MODES = ("markerless", "markers")
"""``tracking.mode``: the string's points by arc length, or by the bands at the mass points."""
POLARITIES = ("auto", "brighter", "darker")
"""``tracking.band_polarity``: a band brighter or darker than the string, or whichever gives more."""
OPTIMIZERS = ("random_search", "cmaes", "de")
PLANNERS = ("paper", "robust")
DRAG_LAWS = ("normal", "isotropic")
"""``model.drag``: the air drag on each point's velocity normal to the string (a slender body's, ours) or on its
whole velocity (the paper's "air resistance at the mass point"); docs/string_model.md, "Air drag"."""
FIRST_K_S = ("carrying", "max")
"""``motion.first_k_s``: the least k_s that keeps the hanging strain, or Table 2's largest."""
SYNC_METHODS = ("video", "trigger")
"""``sync.method``: the arm in the video, or video.yaml's trigger time."""


PARAM_NAMES: tuple[str, ...] = (
    "k_s", "c_s", "k_h", "c_h", "k_sh", "c_sh", "C_c1", "C_c2", "k_ph", "c_ph",
)
"""The ten coefficients of the string model, in the paper's Table 2 order."""

_UR_SCHEMA = {"additionalProperties": False, "properties": {
    "joint_map": {"type": "array", "items": {"type": "integer", "minimum": 0, "maximum": 5}, "minItems": 1,
                  "maxItems": 6},
    "sign": {"type": "array", "items": {"enum": [-1, 1]}, "minItems": 1, "maxItems": 6},
    "offset_deg": {"$ref": "#/$defs/vec3"},
    "lookahead_time_s": {"type": "number", "minimum": 0.03, "maximum": 0.2},
    "gain": {"type": "number", "minimum": 100, "maximum": 2000},
    "servo_speed_rad_s": {"type": "number", "exclusiveMinimum": 0},
    "servo_acceleration_rad_s2": {"type": "number", "exclusiveMinimum": 0},
    "settle_s": {"type": "number", "minimum": 0, "maximum": 2},
    "move_to_start_speed_rad_s": {"type": "number", "exclusiveMinimum": 0, "maximum": 1},
    "move_to_start_acceleration_rad_s2": {"type": "number", "exclusiveMinimum": 0, "maximum": 2}}}
"""``executor.ur``'s keys and their bounds (the UR backend's settings)."""


@dataclass(frozen=True)
class ModelSettings(Section):
    """``model``: the string model's integration and the parameter ranges (Table 2)."""

    SECTION: typing.ClassVar[str] = "model"
    dt_s: float = _f(1.0e-4, "integration step of the string model, s", exclusiveMinimum=0, maximum=0.002)
    psi0_deg: float = _f(0.0, "the string's rest direction in the hand frame, deg")
    first_mu: float = _f(1.0, "relative masses for the first plan (Table 2 has no mass row)", exclusiveMinimum=0)
    blowup_halvings: int = _f(0, "a candidate whose run blows up is run again at half the step, up to this many "
                                 "times: a stiff string's blow-up at dt is the step's, not the string's (0: never, "
                                 "the paper's)", minimum=0, maximum=4)
    drag: str = _f("normal", "air drag (C_c1, C_c2) on each point's velocity normal to the string (normal: a slender "
                             "body's) or on its whole velocity (isotropic: the paper's)", enum=list(DRAG_LAWS))
    ranges: Mapping[str, tuple] = _f({
        "k_s": (1.0e+3, 1.0e+6), "c_s": (1.0, 10.0), "k_h": (1.0e-3, 10.0), "c_h": (1.0e-3, 10.0),
        "k_sh": (1.0e-4, 1.0), "c_sh": (1.0e-4, 1.0), "C_c1": (1.0e-6, 10.0), "C_c2": (1.0e-3, 10.0),
        "k_ph": (1.0e-3, 1.0), "c_ph": (1.0e-3, 1.0), "mu": (0.01, 100.0)},
        "[min, max] of each coefficient (Table 2; ours: k_ph, c_ph up to 1, C_c2 from 1e-3) and of the relative "
        "masses mu (ours from 0.01: a thread's point against a 10 g weight); a file may set some",
        additionalProperties=False, properties={k: {"$ref": "#/$defs/range"} for k in (*PARAM_NAMES, "mu")})

    def __post_init__(self):
        if self.dt_s <= 0:
            raise ConfigError(f"model.dt_s must be > 0, got {self.dt_s}")
        one_of("model", "drag", self.drag, DRAG_LAWS)


@dataclass(frozen=True)
class EvaluationSettings(Section):
    """``evaluation``: the evaluation value E (eqs. 4-6)."""

    SECTION: typing.ClassVar[str] = "evaluation"
    w: float = _f(1.0, "tip weighting of eq. (6): point i counts 1 + w (i - 1) times", minimum=0)


@dataclass(frozen=True)
class EstimationSettings(Section):
    """``estimation``: the parameter search (eqs. 2-3) and what params.json keeps."""

    SECTION: typing.ClassVar[str] = "estimation"
    optimizer: str = _f("cmaes", "random_search (eqs. 2-3), cmaes (CMA-ES) or de (SciPy differential evolution)", enum=list(OPTIMIZERS))
    iterations: int = _f(3000, "candidates evaluated per trial", minimum=1)
    batch: int = _f(64, "candidates simulated per numba batch", minimum=1)
    chi0: float = _f(1.0, "eq. (3): the first sampling radius in chi", exclusiveMinimum=0)
    beta: float = _f(0.998, "eq. (3): the radius shrinks by this factor per sample", exclusiveMinimum=0, maximum=1)
    seed: int = _f(0, "the search's random seed (with the trial number)", minimum=0)
    de_popsize: int = _f(8, "SciPy differential evolution population (per dimension)", minimum=1)
    top_k: int = _f(20, "params.json keeps the best K sets (the robust planner's ensemble)", minimum=1)
    near_best_tol: float = _f(0.05, "diagnostics: sets within this share of the best E show which parameters are pinned", minimum=0)
    pinned_spread: float = _f(0.2, "... pinned when they spread over less than this share of Table 2's log range", exclusiveMinimum=0, maximum=1)
    cmaes_sigma0: float = _f(0.3, "CMA-ES initial step in chi (log-parameter) space, / M", exclusiveMinimum=0)
    cmaes_popsize: int = _f(0, "CMA-ES population; 0: cma's default (4 + 3 ln D)", minimum=0)
    cmaes_runs: int = _f(2, "CMA-ES runs sharing the budget: the first from the last estimate, the others from the centre", minimum=1)
    cmaes_options: Mapping[str, Any] = _f({}, "passed on to cma.CMAOptions (e.g. {CSA_dampfac: 0.5}); an unknown name is an error")
    cmaes_first_look: int = _f(300, "CMA-ES: first evaluate this many eq. (3) samples around chi_best and start at their best (0: off)", minimum=0)
    compare_after_motion_s: float | None = _f(None, "compare frames up to this long after the arm stops, s (null: the whole joint log, as the paper)", minimum=0)
    cmaes_grasp_flip: float = _f(0.0, "CMA-ES: evaluations added, as a share of the budget after the first look, for a last run from the best set with the hand spring k_ph at the other end of its range (0: off)", minimum=0, maximum=1)
    top_grasp_basins: bool = _f(False, "params.json's top (the robust planner's ensemble): half its sets from the hand spring k_ph's other basin (chi on the other side of 0.5) when that basin's best E is within near_best_tol of the best")
    cmaes_first_start: str = _f("centre", "CMA-ES on trial 1 without a first look: from the centre of the box (centre) or from chi_best (best)", enum=["centre", "best"])
    verdict_error_share: tuple = _f((0.18, 0.25), "fit verdict: [warn, fail] when the fit's median error over the moving frames exceeds these shares of the string's length", items={"type": "number", "minimum": 0}, minItems=2, maxItems=2)
    verdict_skill: tuple = _f((0.45, 0.25), "fit verdict: [warn, fail] when the fit explains at most this share of the error of a string carried without swinging (1 - error / that error)", items={"type": "number", "minimum": 0}, minItems=2, maxItems=2)
    verdict_shift_gain: tuple = _f((0.7, 0.5), "fit verdict: [warn, fail] (clock) when shifting the frames' times by 3 or more frame periods cuts the fit's error to this share", items={"type": "number", "minimum": 0}, minItems=2, maxItems=2)
    verdict_min_valid_share: float = _f(0.5, "fit verdict: warn (tracking) when a smaller share of the string's points was tracked in the moving frames", minimum=0, maximum=1)
    verdict_rest_gap_share: float = _f(0.05, "fit verdict: warn (geometry) when a tracked rest point hangs farther from the grasp than the string up to it plus this share of its length", minimum=0)
    verdict_floor_share: float = _f(0.05, "fit verdict: skill and time shift judge only fits whose median error exceeds this share of the string's length", minimum=0)

    def __post_init__(self):
        one_of("estimation", "optimizer", self.optimizer, OPTIMIZERS)
        pairs = {"verdict_error_share": 1, "verdict_skill": -1, "verdict_shift_gain": -1}
        for name, order in pairs.items():
            pair = tuple(getattr(self, name))
            if len(pair) != 2 or not all(0 <= v for v in pair) or order * (pair[1] - pair[0]) < 0:
                raise ConfigError(f"estimation.{name}: [warn, fail], both >= 0, the fail value "
                                  f"{'above' if order > 0 else 'below'} the warn value; got {list(pair)}")


@dataclass(frozen=True)
class MotionSettings(Section):
    """``motion``: motion generation (Section V) and the planners."""

    SECTION: typing.ClassVar[str] = "motion"
    T_range_s: tuple = _f((0.2, 1.2), "[min, max] motion duration T, s", items={"type": "number", "exclusiveMinimum": 0}, minItems=2, maxItems=2)
    n_control_points: int = _f(6, "control points of eq. (1)'s Bezier velocity curves", minimum=2, maximum=30)
    alpha_max_rad_s2: float = _f(40.0, "|alpha_k| of eq. (1), rad/s^2", exclusiveMinimum=0)
    perturb_rad_s: float = _f(0.5, "later trials: control points moved by up to this, rad/s", minimum=0)
    flight_window_s: float = _f(0.5, "the tip may hit up to this long after the motion ends, s", minimum=0)
    max_candidates: int = _f(20000, "candidates searched at most per plan", minimum=1)
    extra_after_hit: int = _f(200, "keep searching this many candidates after the first hit, take the closest", minimum=0)
    aim_radius_mm: float | None = _f(None, "the first hit that starts extra_after_hit's count must pass this close under "
                                           "the planning set, mm (null: the target's radius, the paper)", exclusiveMinimum=0)
    batch: int = _f(64, "candidates simulated per numba batch", minimum=1)
    seed: int = _f(0, "the planner's random seed (with the trial number)", minimum=0)
    floor_margin_m: float = _f(0.05, "the hanging string must clear the floor by this at the start posture, m", minimum=0)
    posture_pool: int = _f(32, "random initial postures tried per batch in the first plan", minimum=1)
    start_grasp_box_mm: tuple | None = _f(((-200.0, 900.0), (-100.0, 700.0)),
                                          "start grasp inside [[x_min, x_max], [y_min, y_max]], mm: where the camera sees the hanging string", type="array", minItems=2, maxItems=2, items={"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2})
    first_max_strain: float = _f(0.05, "first plan: k_s raised so the hanging string stretches at most this", exclusiveMinimum=0)
    first_k_s: str = _f("max", "first plan's k_s: carrying (the least that keeps first_max_strain) or max (Table 2's)", enum=list(FIRST_K_S))
    planner: str = _f("robust", "paper: Section V; robust: prefer motions that hit under most of the estimate's best sets", enum=list(PLANNERS))
    robust_screen_mm: float = _f(20.0, "robust: only candidates within this of the target edge (best set) are scored on the ensemble, mm", minimum=0)
    robust_min_share: float = _f(0.0, "robust: the first hit must hit under at least this share of the sets", minimum=0, maximum=1)
    residual_correction: bool = _f(True, "aim at the target minus the model's error on the played motion's tracked tip")
    hang_clearance_mm: float = _f(60.0, "the hanging string at the start posture stays this far from the arm's centre lines, mm", minimum=0)
    replan_miss_mm: float = _f(45.0, "> 0: after a tracked miss larger than this, plan a new motion (0: always perturb, Section V.B), mm", minimum=0)
    replan_perturb_rad_s: float = _f(1.0, "> 0 (with replan_miss_mm): first try perturbing the played motion by up to this, rad/s", minimum=0)
    replan_min_share: float = _f(0.9, "that wider perturbation is kept when it hits under at least this share of the ensemble", minimum=0, maximum=1)
    replan_residual_mm: float = _f(50.0, "> 0 (with residual_correction): no perturbation when the model's tip error on the played motion exceeds this, mm", minimum=0)
    taut_chord_share: float = _f(0.0, "first and new plans: a hit whose model string is at least this taut at its closest approach (tip-to-grasp distance / the string's length) is preferred to one that is not (0: off, the paper)", minimum=0, maximum=1.5)
    slack_warn_chord_share: float = _f(0.9, "first and new plans: the planner's note warns when the model string's tip is nearer the grasp than this share of the string's length at the predicted hit (such hits rest on the bending, damping and drag the model guesses; 0: no warning)", minimum=0, maximum=1.5)

    def __post_init__(self):
        one_of("motion", "planner", self.planner, PLANNERS)
        one_of("motion", "first_k_s", self.first_k_s, FIRST_K_S)
        if self.aim_radius_mm is not None and not float(self.aim_radius_mm) > 0:
            raise ConfigError(f"motion.aim_radius_mm: > 0 mm or null; got {self.aim_radius_mm}")


@dataclass(frozen=True)
class ExecutorSettings(Section):
    """``executor``: playing a motion file (pre- and post-roll, the UR backend)."""

    SECTION: typing.ClassVar[str] = "executor"
    pre_roll_s: float = _f(0.3, "hold the start posture, filmed, before the motion, s", minimum=0)
    post_roll_s: float = _f(0.6, "hold the end posture after the motion (covers the flight window), s", minimum=0)
    start_tolerance_rad: float = _f(0.02, "ur-rtde: refuse (or --move-to-start) if the arm is further from the start, rad", exclusiveMinimum=0, maximum=0.2)
    ur: Mapping[str, Any] = _f({
        "joint_map": (1, 2, 3), "sign": (-1, -1, -1), "offset_deg": (0.0, 0.0, -90.0), "lookahead_time_s": 0.1,
        "gain": 300, "servo_speed_rad_s": 0.5, "servo_acceleration_rad_s2": 0.5, "settle_s": 0.2,
        "move_to_start_speed_rad_s": 0.3, "move_to_start_acceleration_rad_s2": 0.5},
        "ur-rtde backend: joint_map (UR joint of q1..qJ), sign and offset_deg (q_planar = sign q_ur + offset), "
        "servoJ lookahead_time_s (0.03-0.2) and gain (100-2000), settle_s, move_to_start speed and acceleration", **_UR_SCHEMA)


@dataclass(frozen=True)
class TrackingSettings(Section):
    """``tracking``: markerless (or band-marker) tracking of the string."""

    SECTION: typing.ClassVar[str] = "tracking"
    rest_frames: int = _f(40, "frames before the motion used for the rest state", minimum=1)
    background_samples: int = _f(31, "frames in the background's temporal median", minimum=0)
    threshold_low: float = _f(4.0, "hysteresis threshold, low, in units of the local noise sigma", minimum=0)
    threshold_high: float = _f(8.0, "hysteresis threshold, high, in units of the local noise sigma", minimum=0)
    smooth_px: float = _f(0.8, "Gaussian smoothing of |I - g B| before thresholding, px", minimum=0)
    roi_margin_mm: float = _f(120.0, "segment within the string's length plus this of the grasp, mm", minimum=0)
    grasp_search_mm: float = _f(60.0, "the centreline's walk starts within this of the grasp, mm", minimum=0)
    grasp_clear_mm: float = _f(15.0, "the first stretch from the grasp, hidden by the fingers, is a circular arc, mm", minimum=0)
    max_gap_px: float = _f(8.0, "gaps in the skeleton bridged up to this (bridged parts are never valid), px", minimum=0)
    end_tolerance_mm: float = _f(6.0, "a free end's length may differ from L by this, mm", minimum=0)
    arc_step_px: float = _f(4.0, "chord length of the centreline's spline, px", minimum=0)
    overlay_frames: int = _f(6, "frames drawn in tracking_overlay.png", minimum=0)
    arm_mask_margin_px: float = _f(2.0, "margin around the arm's mask, px", minimum=0)
    arm_guard_px: float = _f(3.0, "guard band around the arm's mask where the string is not trusted, px", minimum=0)
    branch_min_px: int = _f(6, "skeleton branches shorter than this are spurs, px", minimum=0)
    anchor_tol_mm: float = _f(3.0, "a free end is trusted when the length agrees with L within this, mm ...", minimum=0)
    anchor_tol_px: float = _f(2.0, "... or within this, px", minimum=0)
    end_sigma_px: float = _f(1.0, "uncertainty of a free end's position, px", minimum=0)
    scale_sigma: float = _f(0.003, "relative uncertainty of the pixel scale along the string", minimum=0)
    tip_shortfall_mm: float = _f(0.0, "the visible string ends this short of the tip (a tip that does not show), mm", minimum=0)
    end_contrast_min: float = _f(0.4, "a free end is clean when its contrast stays above this share ...", minimum=0)
    end_edge_max: float = _f(0.25, "... and not more than this share of it lies on an occluder's rim", minimum=0)
    max_missing_frac: float = _f(0.3, "a frame with more than this share of the string missing gives no points", minimum=0)
    max_stretch_share: float = _f(0.3, "a string seen longer than L by up to this share, from the grasp to a trusted free end with no ambiguity between, is taken as stretched: its points at the same shares of the seen length", minimum=0)
    stretch_hold_ms: float = _f(200.0, "a frame that does not see the string's end spreads its points by the stretch seen (from the grasp to a trusted free end) in the frames within this of it, ms (0: off)", minimum=0)
    end_touch_mm: float = _f(12.0, "a free end this close to the string's own earlier stretch is not trusted, mm", minimum=0)
    background_window_s: float | None = _f(None, "background samples only from the motion's first seconds, s (null: all)", exclusiveMinimum=0)
    background_bursts: int = _f(5, "the background samples are decoded in this many short runs", minimum=0)
    prefetch_frames: int = _f(48, "frames decoded ahead of the tracker", minimum=0)
    verdict_min_valid_share: float = _f(0.7, "warn when fewer of the string's points are tracked in the frames judged (the motion's start to the joint log's end)", minimum=0, maximum=1)
    verdict_segment_excess_mm: float = _f(3.0, "warn when consecutive points lie farther apart than L / n by more (p95), mm", minimum=0)
    verdict_rest_jitter_mm: float = _f(1.0, "warn when the hanging string's points jitter more (p95 of their deviations at rest), mm", minimum=0)
    verdict_length_share: float = _f(0.3, "warn naming the string's length_mm when the string seen from the grasp to its free end differs from L by more than this share (median over the frames judged)", exclusiveMinimum=0)
    verdict_length_spread_mm: float = _f(5.0, "warn when the string seen from the grasp to its free end varies about its median length by more (p95 of the deviation from the median over the frames that placed points by a trusted free end), mm: points placed in such frames lie off along the string by up to about as much", minimum=0)
    verdict_past_roi_share: float = _f(0.05, "warn naming the string's length_mm when the string runs past L + roi_margin_mm from the grasp in more than this share of the frames judged", minimum=0, maximum=1)
    mode: str = _f("markerless", "markerless: points by arc length from the grasp; markers: a band at each mass point", enum=list(MODES))
    band_width_mm: float = _f(8.0, "markers: the bands' length along the string, mm", exclusiveMinimum=0)
    band_contrast_min: float = _f(0.25, "markers: a band's grey differs from the string's by >= this x the string's contrast", exclusiveMinimum=0)
    band_tolerance: float = _f(0.35, "markers: a band lies within this share of the point spacing of its expected place", exclusiveMinimum=0, maximum=0.5)
    band_length_tol: float = _f(0.5, "markers: its measured length within +- this share of band_width_mm", exclusiveMinimum=0, maximum=1)
    band_polarity: str = _f("auto", "markers: brighter or darker than the string; auto: per frame, whichever gives more bands", enum=list(POLARITIES))
    band_step_px: float = _f(0.25, "markers: sampling step along the centreline, px", exclusiveMinimum=0)

    def __post_init__(self):
        one_of("tracking", "mode", self.mode, MODES)
        one_of("tracking", "band_polarity", self.band_polarity, POLARITIES)


@dataclass(frozen=True)
class SyncSettings(Section):
    """``sync``: the video's frames on the controller clock."""

    SECTION: typing.ClassVar[str] = "sync"
    method: str = _f("video", "video: the arm in the video against the forward kinematics; trigger: video.yaml's trigger time", enum=list(SYNC_METHODS))
    search_ms: float = _f(10.0, "fine search +- around the trigger time (or the coarse estimate), ms", exclusiveMinimum=0)
    step_ms: float = _f(0.25, "fine search step, ms", exclusiveMinimum=0)
    coarse_step_ms: float = _f(0.5, "coarse search step without a trigger time, ms", exclusiveMinimum=0)
    strip_samples: int = _f(8, "sample strips across each arm segment", minimum=2)
    strip_width_samples: int = _f(41, "samples across a strip", minimum=9)
    strip_margin_mm: float = _f(10.0, "a strip reaches this past the segment's outline, mm", minimum=0)
    rest_frames: int = _f(5, "frames before the motion that give the still arm's reference", minimum=1)
    smooth_px: float = _f(1.0, "Gaussian smoothing of the frames, px", minimum=0)
    board_check_warn_mm: float = _f(20.0, "sync warns when the still arm is seen farther than this from the forward kinematics, mm", exclusiveMinimum=0)
    min_frame_contrast: float = _f(0.02, "frames whose score varies less than this are left out", minimum=0)
    min_frames: int = _f(20, "fewer frames than this: no video estimate", minimum=1)
    segment_agree_ms: float = _f(3.0, "segments whose own peak is farther than this from the others' are left out, ms", exclusiveMinimum=0)
    recentre_ms: float = _f(1.0, "the fine search recentres until the peak lies within this of the centre, ms", exclusiveMinimum=0)
    evidence_k: float = _f(3.0, "the video overrules a trigger time only when the arm matches the frames worse at the trigger's offset than at the video's with this many standard errors' confidence (one-sided, frames resampled in blocks); also the margin for an ambiguous peak and the offset's uncertainty", exclusiveMinimum=0)
    match_warn_px: float = _f(1.0, "warn when the arm-match residual, or the offset's uncertainty times the arm's speed, exceeds this, px", exclusiveMinimum=0)
    still_speed_share: float = _f(0.05, "a joint log may start after the video or end before it where every joint moves slower than this share of its speed limit (the arm taken as still outside the log)", exclusiveMinimum=0, maximum=1)
    still_window_s: float = _f(0.02, "the joints' speed at each end of the log is fitted over this span, s", exclusiveMinimum=0)

    def __post_init__(self):
        one_of("sync", "method", self.method, SYNC_METHODS)


@dataclass(frozen=True)
class BoardCheckSettings(Section):
    """``board_check``: the still-arm check of the board-to-robot transform."""

    SECTION: typing.ClassVar[str] = "board_check"
    warn_mm: float = _f(5.0, "calibration warns when the still arm is seen farther than this from where the board pose puts it, mm", exclusiveMinimum=0)
    margin_mm: float = _f(30.0, "profiles across a link reach this past its outline, mm", minimum=0)
    step_mm: float = _f(0.5, "sampling step along a profile, mm", exclusiveMinimum=0)
    rows: int = _f(24, "profiles across each link", minimum=2)
    width_range: tuple = _f((0.6, 1.1), "an edge pair counts when its width is within this share of the link's width", items={"type": "number"}, minItems=2, maxItems=2)
    clear_mm: float = _f(10.0, "profiles keep this clear of the joints, mm", minimum=0)
    min_rows: int = _f(6, "a link with fewer agreeing profiles gives no offset", minimum=1)
    min_share: float = _f(0.4, "... or with fewer than this share of its profiles agreeing", minimum=0, maximum=1)
    max_spread_mm: float = _f(2.0, "profiles agree within this, mm", minimum=0)
    use_discs: bool = _f(True, "use the joint discs' rims")
    disc_rays: int = _f(48, "rays around a joint disc", minimum=8)
    disc_reach_mm: float = _f(35.0, "a disc rim is searched this far around its expected radius, mm", minimum=0)
    use_end: bool = _f(True, "use the gripper's end along its axis when the links and discs leave a direction open")
    end_reach_mm: float = _f(35.0, "the gripper's end is searched this far either side of the outline's end, mm", exclusiveMinimum=0)
    use_string: bool = _f(False, "use the hanging string below the grasp")
    string_rows_mm: tuple = _f((20.0, 140.0), "the string's rows below the grasp, [from, to], mm", items={"type": "number"}, minItems=2, maxItems=2)
    string_search_mm: float = _f(40.0, "the string is searched this far either side, mm", minimum=0)


@dataclass(frozen=True)
class SweepSettings(Section):
    """``sweep``: the swing plane's mapping and the clock refined by the arm's sweep of the trial."""

    SECTION: typing.ClassVar[str] = "sweep"
    frames: int = _f(40, "frames spread over the trial whose arm links are read (0: no sweep; the calibration and sync pass through)", minimum=0)
    min_rows: int = _f(200, "fewer agreeing link rows than this: not refined, and the verdict says so", minimum=20)
    passes: int = _f(3, "at most this many passes, each reading the links at the clock of the last (the rows' clock model is linear)", minimum=1)
    huber: float = _f(2.0, "the fit's Huber loss scale, in units of the rows' own noise (their median absolute deviation)", exclusiveMinimum=0)
    tolerance_mm: float = _f(1.0, "the mapping must be known to this over where the string can be (the tracking's median goal), mm", exclusiveMinimum=0)
    clock_tolerance_ms: float = _f(0.5, "the clock must be known to this (the sync goal), ms", exclusiveMinimum=0)
    fit_lens: bool = _f(True, "also refit k1 and the principal point (within the priors below); the mapping's uncertainty then includes how far that moves it from the homography-only fit")
    principal_point_prior: float = _f(0.02, "standard deviation of the principal point's move, as a share of the image width (real calibrations: a few per cent)", exclusiveMinimum=0)
    k1_prior: float = _f(0.02, "standard deviation of k1's move (what fx a few per cent off does to k1 at k1 ~ -0.2)", exclusiveMinimum=0)

    def __post_init__(self):
        if self.frames < 0 or self.passes < 1 or self.min_rows < 20:
            raise ConfigError(f"sweep: frames >= 0, passes >= 1 and min_rows >= 20 needed, got {self.frames}, "
                              f"{self.passes}, {self.min_rows}")
        if min(self.huber, self.tolerance_mm, self.clock_tolerance_ms, self.principal_point_prior, self.k1_prior) <= 0:
            raise ConfigError("sweep: huber, tolerance_mm, clock_tolerance_ms, principal_point_prior and k1_prior must be > 0")


@dataclass(frozen=True)
class CalibrationSettings(Section):
    """``calibration``: the intrinsics from the calib/ shots, and how they are judged."""

    SECTION: typing.ClassVar[str] = "calibration"
    max_candidate_frames: int = _f(240, "a calibration clip is sampled evenly to at most this many frames for board detection", minimum=3)
    max_views: int = _f(40, "views kept for the fit, chosen for pose diversity", minimum=3)
    coverage_grid: tuple = _f((8, 6), "columns x rows of the grid over the image in which the views' coverage is counted", items={"type": "integer", "minimum": 3}, minItems=2, maxItems=2)
    min_coverage: float = _f(0.6, "share of the grid's cells, and of each third of the image, that must hold corners", minimum=0, maximum=1)
    min_tilt_variety_deg: float = _f(10.0, "the views' rms tilt about the weaker image axis must reach this, deg", minimum=0, maximum=90)
    jackknife_groups: int = _f(10, "the intrinsics' deviations come from refits with each of this many groups of views left out", minimum=3)
    max_principal_point_sd: float = _f(0.01, "the principal point's standard deviation may reach this share of the image", exclusiveMinimum=0)
    max_fx_sd: float = _f(0.01, "fx's standard deviation may reach this share of fx", exclusiveMinimum=0)
    max_distortion_sd: float = _f(0.01, "the distortion's standard deviation at the image's corners may reach this share of the half-diagonal", exclusiveMinimum=0)
    fail_factor: float = _f(2.0, "fail when, with what can be held held, a standard deviation still exceeds its limit this many times", minimum=1)
    hold_rms_tol: float = _f(0.05, "a held principal point or k2/k3 that raises the rms by more than this share contradicts the views", exclusiveMinimum=0)
    board_view: bool = _f(True, "the trial's board (in the swing plane) checks the intrinsics and joins the fit as one more view")
    board_view_ratio: float = _f(2.0, "warn when the trial's board reprojects this many times worse than its own noise and the views'", exclusiveMinimum=1)

    def __post_init__(self):
        if self.jackknife_groups < 3:
            raise ConfigError(f"calibration.jackknife_groups must be >= 3, got {self.jackknife_groups}")
        if len(self.coverage_grid) != 2 or min(self.coverage_grid) < 3:
            raise ConfigError(f"calibration.coverage_grid must be [columns, rows], each >= 3, got {self.coverage_grid}")


SECTION_CLASSES: tuple[type, ...] = (ModelSettings, EvaluationSettings, EstimationSettings, MotionSettings,
                                     ExecutorSettings, TrackingSettings, SyncSettings, BoardCheckSettings,
                                     CalibrationSettings, SweepSettings)
"""The stages' settings classes, one per config section."""


def settings_schema() -> dict:
    """``{section: its JSON schema}`` of every stage section (:func:`section_schema`)."""
    return {c.SECTION: section_schema(c) for c in SECTION_CLASSES}
LAB_SECTIONS: tuple[str, ...] = ("arms", "cameras", "setups", "strings", "targets")
"""Sections that describe the lab; a campaign reads only its own entries (:func:`campaign_sections`)."""


@dataclass(frozen=True)
class Settings:
    """Every stage's settings, built once from the merged config (:func:`settings_from_config`)."""

    model: ModelSettings = field(default_factory=ModelSettings)
    evaluation: EvaluationSettings = field(default_factory=EvaluationSettings)
    estimation: EstimationSettings = field(default_factory=EstimationSettings)
    motion: MotionSettings = field(default_factory=MotionSettings)
    executor: ExecutorSettings = field(default_factory=ExecutorSettings)
    tracking: TrackingSettings = field(default_factory=TrackingSettings)
    sync: SyncSettings = field(default_factory=SyncSettings)
    board_check: BoardCheckSettings = field(default_factory=BoardCheckSettings)
    calibration: CalibrationSettings = field(default_factory=CalibrationSettings)
    sweep: SweepSettings = field(default_factory=SweepSettings)


def settings_from_config(config: Mapping | None) -> Settings:
    """Build every section's settings from a merged config (the sections it lacks take the defaults).

    Parameters
    ----------
    config : mapping or None
        The merged config (:func:`~stringcast.core.config.load_config`); None: every section's defaults.

    Returns
    -------
    Settings
        One settings object per stage section (``model``, ``evaluation``, ..., ``sweep``).

    Raises
    ------
    ConfigError
        An unknown key or a value out of its set (naming section and key).
    """
    config = config or {}
    return Settings(**{c.SECTION: c.from_mapping(config.get(c.SECTION)) for c in SECTION_CLASSES})
