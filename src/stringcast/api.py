"""The face of stringcast for scripts and notebooks: one name per stage, in memory or from files.

Import what you need from here, not from the stage modules (``from stringcast.api import fit_tracks``);
each name loads its stage when first used, as the stage packages do (:mod:`stringcast.core.lazy`).
trackpy's ``api.py`` is the model: the stages' modules may move, these names stay.

============  ========================================================  ==========================================
stage         in memory (arrays, records)                               from and to the trial's files (the rules')
============  ========================================================  ==========================================
config        :func:`load_config`, :func:`settings_from_config`,        ``stringcast settings``
              :func:`load_campaign`, :func:`default_settings`
video         :func:`open_video` -> reader of (H, W) grey frames        :func:`write_frame_cache` (frames.npy)
calibrate     :class:`Calibration` (``pixel_to_robot``, ...)            :func:`run_calibration`
sync          :func:`frame_times` (frames on the controller clock)      :func:`run_sync`, :func:`run_sweep`
track         :func:`track_video` -> :class:`TrackedVideo`              :func:`run_tracking`
model         :func:`simulate`, :func:`simulate_batch`,
              :func:`closest_approach_batch`, :func:`hanging_equilibrium`
estimate      :func:`fit_tracks` -> :class:`Fit`; :func:`build_problem`,  :func:`run_estimation`, :func:`run_prediction`
              :func:`make_objective`, :func:`simulate_fit`;
              :func:`string_response` (does the string feel its grasp?)
plan          :func:`plan_next` -> :class:`NextMotion`                  :func:`run_first_plan`, :func:`run_plan`
execute                                                                 :func:`execute` (a motion file on an arm)
report                                                                  :func:`write_trial_report`,
                                                                        :func:`write_campaign_report`
============  ========================================================  ==========================================

Units everywhere: m, s, rad, kg per the paper's Table 2; arrays are numpy, tables pandas. The
in-memory functions take the stage's settings objects by keyword (``tracking=``, ``model=``, ...;
:func:`default_settings` gives the project's defaults); each one's docstring has its shapes.

Example, a trial's fit from its files::

    from stringcast.api import default_settings, fit_tracks, load_campaign, load_config, read_joint_table
    import pandas as pd
    config = load_config()
    s = default_settings(config)
    campaign = load_campaign("data/demo/campaign.yaml", config)
    t_j, q_j = read_joint_table("data/demo/trial_1/joints.csv")
    fit = fit_tracks(pd.read_parquet("results/demo/trial_1/tracks.parquet"), t_j, q_j, campaign,
                     model=s.model, evaluation=s.evaluation, estimation=s.estimation, motion=s.motion,
                     tracking=s.tracking)
    print(fit.estimate.verdict, fit.fit_check["skill"])
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from stringcast.core import lazy_exports, load_config, settings_from_config

if TYPE_CHECKING:
    from stringcast.calibrate import Calibration, run_calibration
    from stringcast.core import load_campaign, read_joint_table
    from stringcast.estimate import (Fit, build_problem, fit_tracks, make_objective, run_estimation, run_prediction,
                                     simulate_fit, string_response)
    from stringcast.execute import execute
    from stringcast.model import closest_approach_batch, hanging_equilibrium, simulate, simulate_batch
    from stringcast.plan import NextMotion, plan_next, run_first_plan, run_plan
    from stringcast.report import write_campaign_report, write_trial_report
    from stringcast.sync import frame_times, run_sweep, run_sync
    from stringcast.track import TrackedVideo, run_tracking, track_video
    from stringcast.video import open_video, write_frame_cache

_FACE = {
    "load_campaign": "stringcast.core", "read_joint_table": "stringcast.core",
    "open_video": "stringcast.video", "write_frame_cache": "stringcast.video",
    "Calibration": "stringcast.calibrate", "run_calibration": "stringcast.calibrate",
    "frame_times": "stringcast.sync", "run_sync": "stringcast.sync", "run_sweep": "stringcast.sync",
    "track_video": "stringcast.track", "TrackedVideo": "stringcast.track", "run_tracking": "stringcast.track",
    "simulate": "stringcast.model", "simulate_batch": "stringcast.model",
    "closest_approach_batch": "stringcast.model", "hanging_equilibrium": "stringcast.model",
    **{name: "stringcast.estimate" for name in ("fit_tracks", "Fit", "run_estimation", "run_prediction", "build_problem",
                                                 "make_objective", "simulate_fit", "string_response")},
    "plan_next": "stringcast.plan", "NextMotion": "stringcast.plan", "run_first_plan": "stringcast.plan",
    "run_plan": "stringcast.plan",
    "execute": "stringcast.execute",
    "write_trial_report": "stringcast.report", "write_campaign_report": "stringcast.report",
}
"""Each name of the face and the module that defines or exports it."""

_lazy_getattr, _lazy_dir = lazy_exports(__name__, _FACE)


def __getattr__(name: str):
    return _lazy_getattr(name)


def __dir__() -> list:
    return _lazy_dir()


def default_settings(config: dict | None = None):
    """Every stage's settings from a config.

    Parameters
    ----------
    config : dict, optional
        A merged config (:func:`load_config`); default the project's ``config/config.yaml`` over the
        settings' defaults.

    Returns
    -------
    Settings
        :class:`~stringcast.core.Settings`: one frozen settings object per stage (``s.tracking``,
        ``s.estimation``, ...).

    Raises
    ------
    ConfigError
        An invalid config (named).
    """
    return settings_from_config(config if config is not None else load_config())


__all__ = ["Calibration", "Fit", "NextMotion", "TrackedVideo", "build_problem", "closest_approach_batch",
           "default_settings", "execute", "fit_tracks", "frame_times", "hanging_equilibrium",
           "load_campaign", "load_config", "make_objective", "open_video", "plan_next", "read_joint_table",
           "run_calibration", "run_estimation", "run_first_plan", "run_plan", "run_prediction", "run_sweep",
           "run_sync", "run_tracking", "settings_from_config", "simulate", "simulate_batch", "simulate_fit",
           "string_response", "track_video", "write_campaign_report", "write_frame_cache",
           "write_trial_report"]
