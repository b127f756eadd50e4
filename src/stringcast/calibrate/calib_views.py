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

The views' own intrinsics (:func:`~stringcast.calibrate.intrinsics.judged_intrinsics`, the
fit a trial's board view is checked against before it joins the views) are the same for every
trial too: :func:`write_campaign_intrinsics` fits them once, to ``results/<campaign>/intrinsics.json``
(K, distortion, their measures and verdict), and each trial's calibration reads them back
(:func:`read_campaign_intrinsics`) rather than refit them beside its decode.
"""
from __future__ import annotations

import hashlib
import json
import math
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np

from stringcast.core import CalibrationSettings, DataError, Verdict, atomic_path, write_json
from stringcast.video import FRAME_SUFFIXES, open_video
from .charuco import Intrinsics, Views, select_calibration_views
from .intrinsics import judged_intrinsics

_VIDEO_SUFFIXES = (".mkv", ".avi", ".mp4", ".mov")


def _calib_reader(calib_dir: Path):
    """The calibration views: the folder's images, or the one video inside it.

    Raises:
        DataError: no such folder, an unreadable one, or none of either in it (named)."""
    try:
        entries = sorted(calib_dir.iterdir())
    except OSError as exc:
        raise DataError(f"{calib_dir}: not a readable folder of calibration views (PNG/TIFF images or one video "
                        f"of the ChArUco board): {exc.strerror or exc}") from exc
    if any(p.suffix.lower() in FRAME_SUFFIXES for p in entries):
        return open_video(calib_dir)
    vids = [p for p in entries if p.is_file() and p.suffix.lower() in _VIDEO_SUFFIXES]
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


def find_calib_views(calib_dir: str | Path, board, st: CalibrationSettings, campaign=None) -> tuple[Views, str]:
    """The board's views in ``calib_dir`` (:func:`~stringcast.calibrate.charuco.select_calibration_views`
    on every ``ceil(frames / max_candidate_frames)``-th frame, at most ``max_views`` kept) and the
    source's name for messages. ``campaign``: names the board's settings in the hint where too few views
    are found (:func:`~stringcast.calibrate.board_hint.board_hint`).

    Raises:
        DataError: no images or video in the folder, or too few views of the board (named).
    """
    reader = _calib_reader(Path(calib_dir))
    stride = max(1, math.ceil(reader.n_frames / st.max_candidate_frames))
    named = {} if campaign is None else {"dictionary": campaign.setup.board.dictionary,
                                         "setting": lambda key: campaign.setup_setting(f"board.{key}")}
    views = select_calibration_views((f for i, f in reader if i % stride == 0), board, str(reader.path),
                                     max_views=st.max_views, **named)
    return views, str(reader.path)


def write_calib_views(calib_dir: str | Path, campaign, out: str | Path, *,
                      calibration: CalibrationSettings = CalibrationSettings()) -> Views:
    """Find the campaign's calibration views (:func:`find_calib_views`, board from ``campaign.setup``)
    and write them to ``out`` (``.npz``, atomically). Returns the views.

    Raises:
        DataError: as :func:`find_calib_views`.
    """
    with single_threaded_opencv():   # as a trial's calibration detects
        views, source = find_calib_views(calib_dir, campaign.setup.board.make(), calibration, campaign)
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


def camera_flags(campaign) -> int:
    """The ``cv2.calibrateCamera`` flags the campaign's camera entry asks for (``fix_k3``: ``CALIB_FIX_K3``)."""
    return cv2.CALIB_FIX_K3 if campaign.setup.camera.get("fix_k3") else 0


def _views_digest(views: Views) -> str:
    """SHA-256 of the views' corners, image size and names: which views intrinsics were fitted to."""
    h = hashlib.sha256(json.dumps([list(views.image_size), list(views.names)]).encode())
    for o, i in zip(views.object_points, views.image_points):
        h.update(np.ascontiguousarray(o, np.float32).tobytes())
        h.update(np.ascontiguousarray(i, np.float32).tobytes())
    return h.hexdigest()


def write_campaign_intrinsics(views_npz: str | Path, campaign, out: str | Path, *,
                              calibration: CalibrationSettings = CalibrationSettings()) -> Intrinsics:
    """Fit and judge the views of ``views_npz`` (:func:`write_calib_views`) once for the campaign
    (:func:`~stringcast.calibrate.intrinsics.judged_intrinsics`, on one OpenCV thread as a trial's
    calibration fits) and write them to ``out`` (JSON, atomically). Returns the intrinsics.

    The file holds K (3, 3) px, dist (5,) (k1, k2, p1, p2, k3), rms_px, per_view_rms_px, the
    views' counts, the fit's flags, ``quality`` and ``verdict`` (as ``calibration.json``), and
    what they were made from: the views' digest, the flags and the ``calibration`` settings.

    Raises:
        DataError: as :func:`read_calib_views`; too few views to fit.
    """
    views, source = read_calib_views(views_npz)
    flags = camera_flags(campaign)
    with single_threaded_opencv():
        intr, quality, verdict = judged_intrinsics(views, flags, calibration)
    write_json(out, {"source": source, "views_digest": _views_digest(views), "camera_flags": flags,
                     "settings": calibration.as_dict(), "K": intr.K, "dist": intr.dist, "rms_px": intr.rms_px,
                     "n_views": intr.n_views, "image_size": list(intr.image_size),
                     "views_rejected": intr.views_rejected, "views_found": intr.views_found, "std": intr.std,
                     "per_view_rms_px": list(intr.per_view_rms_px), "flags": intr.flags,
                     "quality": quality, "verdict": verdict.as_dict()})
    return intr


def read_campaign_intrinsics(path: str | Path, views: Views, campaign, calibration: CalibrationSettings
                             ) -> tuple[Intrinsics, dict, Verdict]:
    """The intrinsics :func:`write_campaign_intrinsics` wrote: (intrinsics (no views or poses), their
    quality measures, their verdict), as ``judged_intrinsics`` returned them.

    Raises:
        DataError: not a readable intrinsics file, or made from other views, camera flags or
            ``calibration`` settings than these (the file is named; delete it to refit).
    """
    try:
        doc = json.loads(Path(path).read_text())
        intr = Intrinsics(np.asarray(doc["K"], float), np.asarray(doc["dist"], float), float(doc["rms_px"]),
                          int(doc["n_views"]), tuple(doc["image_size"]), int(doc["views_rejected"]),
                          int(doc["views_found"]), None if doc["std"] is None else np.asarray(doc["std"], float),
                          tuple(float(e) for e in doc["per_view_rms_px"]), flags=int(doc["flags"]))
        made = (doc["views_digest"], int(doc["camera_flags"]), doc["settings"])
        quality, verdict = doc["quality"], Verdict.from_dict(doc["verdict"])
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise DataError(f"{path}: not a campaign intrinsics file ({exc}); delete it to fit the views again") from exc
    now = (_views_digest(views), camera_flags(campaign), json.loads(json.dumps(calibration.as_dict())))
    for what, then, current in zip(("calibration views", "camera's fix_k3", "calibration settings"), made, now):
        if then != current:
            raise DataError(f"{path}: fitted to other {what} than this trial's; delete it to fit the views again")
    return intr, quality, verdict
