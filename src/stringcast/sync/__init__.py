"""Time sync: the video's frames on the controller clock, from the trigger time or from
the arm seen in the video matched with the forward kinematics of the joint log; then the
mapping and the clock refined together by the arm's sweep of the trial (:mod:`.sweep`).
"""
from .offset import frame_times, run_sync
from .sweep import run_sweep

__all__ = ["frame_times", "run_sweep", "run_sync"]
