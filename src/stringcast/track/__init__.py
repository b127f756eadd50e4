"""Markerless (or band-marker) tracking of the string: background, segmentation,
centreline from the grasp, mass points by arc length in the robot frame.
"""
from .tracking import TrackedVideo, run_tracking, track_video

__all__ = ["TrackedVideo", "run_tracking", "track_video"]
