"""A trial's video and ``video.yaml``, checked against each other by the video's header alone.

The video is the one :func:`~stringcast.core.find_video` picks (the ``decode`` rule reads it);
opening it reads its header and first frame (:func:`~stringcast.video.open_video` with
``count_frames=False``: never a decoding pass, even where the count is known only to a few frames),
and :func:`~stringcast.video.video_meta_problems` compares it with ``video.yaml``.
"""
from __future__ import annotations

import difflib
import math
from pathlib import Path
from typing import Any
from collections.abc import Mapping

from stringcast.core import ConfigError, DataError, find_video, load_yaml
from stringcast.video import open_video, video_meta_problems
from .campaign_file import schema_findings, schema_keys
from .problem import Problem, from_error, kind_of, problem, show

VIDEO_FILES = ("video.mkv", "video.avi", "video.mp4")
"""The container names the workflow looks for (beside a ``video/`` folder and ``video.cihx``)."""
PHOTRON_HEADERS = ("video.cihx", "video.cih")
KNOWN = "video.mkv/.avi/.mp4, a video/ folder of PNG/TIFF frames, or video.cihx + video.mraw"


def _videos(trial_dir: Path) -> tuple[list[Path], list[Path]]:
    """(the trial's videos the workflow knows, the other ``video*`` names beside them), by name."""
    known, other = [], []
    for p in sorted(trial_dir.glob("video*")):
        if p.name == "video.yaml":
            continue
        if (p.name in VIDEO_FILES or p.name in PHOTRON_HEADERS) and p.is_file() or p.name == "video" and p.is_dir():
            known.append(p)
        elif p.name == "video.mraw" and any((trial_dir / h).is_file() for h in PHOTRON_HEADERS):
            continue      # the frames of video.cihx
        else:
            other.append(p)
    return known, other


def video_choice(trial_dir: Path) -> tuple[list[Problem], Path | None]:
    """Exactly one video in the trial: (problems, the video the stages read, or None).

    Two videos are an error naming the one read (:func:`~stringcast.core.find_video`: the first by
    name); a ``video*`` file the workflow does not know is an error where it is the one read, else a
    warning (not read).
    """
    known, other = _videos(trial_dir)
    try:
        chosen = find_video(trial_dir)
    except DataError as exc:
        return [from_error(exc, trial_dir, hint="copy the trial's video in")], None
    out = []
    if chosen not in known:
        why = ("its .cihx header is missing" if chosen.name == "video.mraw" else
               "the workflow does not look for this name")
        out.append(problem(chosen, f"the stages would read this as the trial's video, but {why} (expected "
                                   f"{KNOWN}): rename it or move it out"))
    if len(known) > 1:
        out.append(problem(trial_dir, f"{len(known)} videos: {', '.join(p.name for p in known)}; the workflow reads "
                                      f"{chosen.name} (the first by name): keep one, move the others out", "video"))
    for p in other:
        if p != chosen:
            out.append(problem(p, f"not read (the trial's video is {chosen.name}): a leftover, or the video under "
                                  "a name the workflow does not look for?", severity="warn"))
    return out, (chosen if chosen in known else None)


def read_meta(path: Path) -> tuple[list[Problem], dict | None]:
    """``video.yaml`` read and checked on its own (schema, fps and trigger time finite):
    (problems, the mapping where it has no error, else None)."""
    if not path.is_file():
        return [problem(path, "file not found: every trial needs one (fps, frames; docs/data_contract.md)")], None
    try:
        doc = load_yaml(path)
    except ConfigError as exc:
        return [from_error(exc, path)], None
    if not isinstance(doc, Mapping):
        return [problem(path, f"expected a mapping with fps and frames, got {kind_of(doc)}",
                        value=None if doc is None else show(doc))], None
    out = schema_findings(dict(doc), path, "video.schema.json")
    known = schema_keys("video.schema.json")
    for key in doc:
        close = [] if key in known else difflib.get_close_matches(str(key), known, n=1, cutoff=0.7)
        if close:   # other keys are the lab's own notes; one spelled like a key the stages read is a typo
            out.append(problem(path, f"not a key the stages read: a typo of {close[0]!r}? (this one is ignored)",
                               str(key), severity="warn"))
    for key in ("fps", "trigger_time_s"):
        v = doc.get(key)
        if isinstance(v, float) and not math.isfinite(v):
            out.append(problem(path, "not a finite number", key, v))
    fps = doc.get("fps")
    if any(q.field == "fps" for q in out) and isinstance(fps, (int, float)) and not isinstance(fps, bool):
        out = [problem(path, "must be > 0: the camera's frame rate in frames per second (e.g. 500)", "fps", fps)
               if q.field == "fps" and "minimum" in q.message else q for q in out]
    return out, (None if any(q.is_error for q in out) else dict(doc))


def _meta_findings(video, meta: dict, yaml_path: Path) -> list[Problem]:
    """video.yaml against the opened video (:func:`~stringcast.video.video_meta_problems`); an fps that
    differs from the file's is an error unless ``fps_note`` says why."""
    out = []
    for severity, key, value, what in video_meta_problems(video, meta):
        if key == "fps":
            if meta.get("fps_note"):
                continue
            ratio = float(value) / video.fps
            out.append(problem(yaml_path, f"the video {video.path} says {video.fps:g} fps ({ratio:.3g} x): "
                                          "fps is the time base of every frame; a typo, or another camera's rate? "
                                          "If the file stores another rate (a playback rate), say why in fps_note",
                               key, value))
        elif key == "frames":
            out.append(problem(yaml_path, f"{what}: another trial's count, or a video cut short?", key, value))
        else:
            out.append(problem(yaml_path, what, key, value, severity))
    return out


def video_findings(trial_dir: Path) -> tuple[list[Problem], dict | None]:
    """The trial's video and ``video.yaml``: (problems, ``video.yaml``'s mapping where it has no
    error, else None).

    Checks: one video (:func:`video_choice`), ``video.yaml`` (:func:`read_meta`), the video opened
    by its header, and ``frames``, ``width_px``, ``height_px``, ``fps`` (unless ``fps_note``) and
    ``bit_depth`` against it.
    """
    out, path = video_choice(trial_dir)
    meta_problems, meta = read_meta(trial_dir / "video.yaml")
    out += meta_problems
    if path is None:
        return out, meta
    fps: Any = None if meta is None else float(meta["fps"])
    try:
        video = open_video(path, fps=fps, count_frames=False)
    except DataError as exc:
        out.append(from_error(exc, path, hint="a copy cut short, or not the camera's file?"))
        return out, meta
    try:
        if meta is not None:
            out += _meta_findings(video, meta, trial_dir / "video.yaml")
    finally:
        video.close()
    return out, meta
