"""Settings of the stages, one per config section, with their defaults in one place."""
from __future__ import annotations

from .config import ConfigError

MODES = ("markerless", "markers")
"""``tracking.mode``: the string's points by arc length, or by the bands at the mass points."""
POLARITIES = ("auto", "brighter", "darker")
"""``tracking.band_polarity``: a band brighter or darker than the string, or whichever gives more."""

DEFAULTS = {
    "rest_frames": 40, "background_samples": 31, "threshold_low": 4.0, "threshold_high": 8.0,
    "smooth_px": 0.8, "roi_margin_mm": 120.0, "grasp_search_mm": 60.0, "grasp_clear_mm": 15.0,
    "max_gap_px": 8.0, "end_tolerance_mm": 6.0, "arc_step_px": 4.0, "overlay_frames": 6,
    # the arm's outline for its mask (UR5e-sized; set them for your arm and gripper)
    "arm_link_widths_mm": [120.0, 100.0, 85.0], "arm_joint_radii_mm": [70.0, 60.0, 50.0, 45.0],
    "gripper_widths_mm": [66.0, 30.0], "gripper_mask_extend_mm": 3.0, "arm_mask_margin_px": 2.0,
    "arm_guard_px": 3.0, "branch_min_px": 6, "anchor_tol_mm": 3.0, "anchor_tol_px": 2.0, "end_sigma_px": 1.0,
    "scale_sigma": 0.003, "tip_shortfall_mm": 0.0, "end_contrast_min": 0.4, "end_edge_max": 0.25, "max_missing_frac": 0.3,
    "end_touch_mm": 12.0,
    "background_window_s": None, "background_bursts": 5, "prefetch_frames": 48,
    # markers (stringcast.track.markers): a band centred at each mass point gives its position
    "mode": "markerless", "band_width_mm": 8.0, "band_contrast_min": 0.25, "band_tolerance": 0.35,
    "band_length_tol": 0.5, "band_polarity": "auto", "band_step_px": 0.25,
}


def tracking_settings(config: dict | None) -> dict:
    """Tracking settings: ``config['tracking']`` over :data:`DEFAULTS`."""
    s = dict(DEFAULTS)
    s.update((config or {}).get("tracking", {}) or {})
    if s["mode"] not in MODES or s["band_polarity"] not in POLARITIES:
        raise ConfigError(f"tracking: mode {s['mode']!r} (one of {MODES}), band_polarity {s['band_polarity']!r}")
    return s
