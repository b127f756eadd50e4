"""Video readers: one streaming, mono interface over containers (OpenCV/FFmpeg),
frame folders, TIFF stacks and Photron files, and a decode-ahead thread.
"""
from .base import FRAME_SUFFIXES
from .container import check_frame_count, dropped_frames, open_video
from .decode_ahead import prefetch
from .frame_cache import CachedVideo, open_trial_video, write_frame_cache

__all__ = ["FRAME_SUFFIXES", "CachedVideo", "check_frame_count", "dropped_frames", "open_trial_video", "open_video",
           "prefetch", "write_frame_cache"]
