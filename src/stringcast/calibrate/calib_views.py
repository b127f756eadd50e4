"""A campaign's calibration views, found once: ``results/<campaign>/calib_views.npz``.

Every trial of a campaign calibrates with the same ``data/<campaign>/calib/`` clip. Finding the
ChArUco board in its frames (decoding the clip, ``cv2.aruco.CharucoDetector`` on each candidate
frame, choosing the views) took a third of each trial's calibration, on the trial's critical
path beside its decode. The workflow's ``calib_views`` rule now does it once per campaign, and
each trial's ``calibrate`` reads the views back: the same :class:`~stringcast.calibrate.charuco.Views`
(float32 corners stored as they were found), so the same intrinsics.

The file is NumPy's ``.npz`` (``np.load`` opens it anywhere): per view ``object_points_<k>``
(N_k, 1, 3) float32 m and ``image_points_<k>`` (N_k, 1, 2) float32 px, and ``meta`` (a JSON
string: image_size, found, names, source).
"""
from __future__ import annotations

import json
import math
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np

from stringcast.core import CalibrationSettings, DataError, atomic_path
from stringcast.video import FRAME_SUFFIXES, open_video
from .charuco import Views, select_calibration_views

_VIDEO_SUFFIXES = (".mkv", ".avi", ".mp4", ".mov")


def _calib_reader(calib_dir: Path):
    """The calibration views: the folder's images, or the one video inside it."""
    if any(p.suffix.lower() in FRAME_SUFFIXES for p in calib_dir.iterdir()):
        return open_video(calib_dir)
    vids = sorted(p for p in calib_dir.iterdir() if p.is_file() and p.suffix.lower() in _VIDEO_SUFFIXES)
    if not vids:
        raise DataError(f"{calib_dir}: no PNG/TIFF images or video of the calibration board")
    return open_video(vids[0])


@contextmanager
def single_threaded_opencv():
    """Run OpenCV on one thread inside the block (``cv2.setNumThreads``), then restore.

    With its worker threads, calibration on the same views gave intrinsics that differed run
    to run in the 9th significant digit (the threads' partial sums add up in varying order);
    the estimation's search amplifies such a difference into another estimate, so a
    reprocessed trial would not reproduce its results. One thread costs this stage ~1 s.
    """
    n = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        yield
    finally:
        cv2.setNumThreads(n)


def find_calib_views(calib_dir: str | Path, board, st: CalibrationSettings) -> tuple[Views, str]:
    """The board's views in ``calib_dir`` (:func:`~stringcast.calibrate.charuco.select_calibration_views`
    on every ``ceil(frames / max_candidate_frames)``-th frame, at most ``max_views`` kept) and the
    source's name for messages.

    Raises:
        DataError: no images or video in the folder, or too few views of the board (named).
    """
    reader = _calib_reader(Path(calib_dir))
    stride = max(1, math.ceil(reader.n_frames / st.max_candidate_frames))
    views = select_calibration_views((f for i, f in reader if i % stride == 0), board, str(reader.path),
                                     max_views=st.max_views)
    return views, str(reader.path)


def write_calib_views(calib_dir: str | Path, campaign, out: str | Path, *,
                      calibration: CalibrationSettings = CalibrationSettings()) -> Views:
    """Find the campaign's calibration views (:func:`find_calib_views`, board from ``campaign.setup``)
    and write them to ``out`` (``.npz``, atomically). Returns the views.

    Raises:
        DataError: as :func:`find_calib_views`.
    """
    with single_threaded_opencv():   # as a trial's calibration detects
        views, source = find_calib_views(calib_dir, campaign.setup.board.make(), calibration)
    arrays = {f"object_points_{k}": np.asarray(o, np.float32) for k, o in enumerate(views.object_points)}
    arrays.update({f"image_points_{k}": np.asarray(i, np.float32) for k, i in enumerate(views.image_points)})
    meta = {"image_size": [int(x) for x in views.image_size], "found": int(views.found),
            "names": list(views.names), "source": source, "views": len(views)}
    with atomic_path(out, ".npz") as tmp:
        np.savez(tmp, meta=np.array(json.dumps(meta)), **arrays)
    return views


def read_calib_views(path: str | Path) -> tuple[Views, str]:
    """The views :func:`write_calib_views` wrote, and their source's name.

    Raises:
        DataError: not a readable views file (the file is named).
    """
    try:
        with np.load(path) as z:
            meta = json.loads(str(z["meta"]))
            n = int(meta["views"])
            views = Views(tuple(z[f"object_points_{k}"] for k in range(n)), tuple(z[f"image_points_{k}"] for k in range(n)),
                          tuple(meta["image_size"]), int(meta["found"]), tuple(meta["names"]))
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise DataError(f"{path}: not a calibration views file ({exc}); delete it to find the views again") from exc
    return views, str(meta["source"])
