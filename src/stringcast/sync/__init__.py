"""Time sync: the video's frames on the controller clock, from the trigger time or from
the arm seen in the video matched with the forward kinematics of the joint log; then the
mapping and the clock refined together by the arm's sweep of the trial (:mod:`.sweep`).
"""
from typing import TYPE_CHECKING

from stringcast.core import lazy_exports

if TYPE_CHECKING:
    from .clock import frame_times
    from .offset import run_sync
    from .sweep import run_sweep

__getattr__, __dir__ = lazy_exports(__name__, {
    "frame_times": ".clock",
    "run_sync": ".offset",
    "run_sweep": ".sweep",
})

__all__ = ["frame_times", "run_sweep", "run_sync"]
