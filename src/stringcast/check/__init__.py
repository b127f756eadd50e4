"""The check before any decode: every raw file of a campaign validated in seconds, each problem one
line naming the file, the field, the value and the likely mistake (``stringcast check data/<c>``).

It reads headers only, writes nothing, raises nothing, and stands on :mod:`stringcast.core` and
:mod:`stringcast.video`'s readers (never the virtual lab), so the workflow can run it while it
builds its jobs.
"""
from .campaign_check import check_campaign, check_trial, trial_dirs
from .problem import Problem

__all__ = ["Problem", "check_campaign", "check_trial", "trial_dirs"]
