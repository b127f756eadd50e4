"""Video readers: one streaming, mono interface over containers (OpenCV/FFmpeg),
frame folders, TIFF stacks and Photron files, and a decode-ahead thread.
"""
from typing import TYPE_CHECKING

from stringcast.core import lazy_exports

if TYPE_CHECKING:
    from .base import FRAME_SUFFIXES
    from .container import check_frame_count, dropped_frames, open_video, video_meta_problems
    from .decode_ahead import prefetch
    from .frame_cache import CachedVideo, open_trial_video, write_frame_cache

__getattr__, __dir__ = lazy_exports(__name__, {
    "FRAME_SUFFIXES": ".base",
    "check_frame_count": ".container",
    "dropped_frames": ".container",
    "open_video": ".container",
    "video_meta_problems": ".container",
    "prefetch": ".decode_ahead",
    "CachedVideo": ".frame_cache",
    "open_trial_video": ".frame_cache",
    "write_frame_cache": ".frame_cache",
})

__all__ = ["FRAME_SUFFIXES", "CachedVideo", "check_frame_count", "dropped_frames", "open_trial_video", "open_video",
           "prefetch", "video_meta_problems", "write_frame_cache"]
