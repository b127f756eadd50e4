"""Time sync: the video's frames on the controller clock, from the trigger time or from
the arm seen in the video matched with the forward kinematics of the joint log.
"""
from .offset import frame_times, run_sync

__all__ = ["frame_times", "run_sync"]
