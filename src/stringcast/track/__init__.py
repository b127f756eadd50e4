"""Markerless (or band-marker) tracking of the string: background, segmentation,
centreline from the grasp, mass points by arc length in the robot frame.
"""
from .tracking import run_tracking

__all__ = ["run_tracking"]
