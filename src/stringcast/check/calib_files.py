"""A campaign's optional ``calib/``: the board's views as PNG/TIFF images, or one video.

The ``calib_views`` rule reads the images as one sequence (every one readable, all of one size) or,
where there are none, the first video by name. Each image is checked by its header (its size) and, a
PNG, by its end (a file cut short); the video by its header. The pixels are not decoded.
"""
from __future__ import annotations

from pathlib import Path

from stringcast.core import DataError
from stringcast.video import FRAME_SUFFIXES, open_video
from .problem import Problem, from_error, problem, show

CALIB_VIDEO_SUFFIXES = (".mkv", ".avi", ".mp4", ".mov")
"""The videos the ``calib_views`` rule reads in ``calib/`` (where it holds no images)."""


_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_END = b"\x00\x00\x00\x00IEND\xaeB`\x82"   # the empty IEND chunk that closes every PNG


def _png_size(path: Path) -> tuple[int, int] | str:
    """(height, width) from a PNG's IHDR chunk, or what is wrong: not a PNG, or cut short (no IEND
    chunk at its end). Reads 33 bytes and the last 12, not the pixels."""
    with open(path, "rb") as f:
        head = f.read(33)
        f.seek(0, 2)
        size = f.tell()
        f.seek(max(0, size - len(_PNG_END)))
        tail = f.read()
    if len(head) < 33 or not head.startswith(_PNG_SIGNATURE) or head[12:16] != b"IHDR":
        return "not a PNG image (empty, or another format under a .png name)"
    if tail != _PNG_END:
        return "a PNG cut short (it does not end with its IEND chunk): copied incompletely?"
    return int.from_bytes(head[20:24], "big"), int.from_bytes(head[16:20], "big")


def _tiff_size(path: Path) -> tuple[int, int] | str:
    """(height, width) of a TIFF's first page from its header, or what is wrong: unreadable, or its
    pixel data reaching past the end of the file (cut short)."""
    import tifffile

    try:
        with tifffile.TiffFile(path) as tif:
            page = tif.pages[0]
            shape = page.shape
            ends = [o + n for o, n in zip(page.dataoffsets, page.databytecounts)]
            size = tif.filehandle.size
    except Exception as exc:  # noqa: BLE001 -- tifffile raises many types for a damaged file
        return f"not a readable TIFF image ({type(exc).__name__}: {show(exc, 120)})"
    if ends and max(ends) > size:
        return f"a TIFF cut short (its pixels reach byte {max(ends)} of {size}): copied incompletely?"
    return tuple(shape[:2]) if len(shape) >= 2 else "a TIFF without an image"


def _image_size(path: Path) -> tuple[int, int] | str:
    """(height, width) of a PNG/TIFF image by its header (and a PNG's end), or what is wrong with it."""
    try:
        return _tiff_size(path) if path.suffix.lower() in (".tif", ".tiff") else _png_size(path)
    except OSError as exc:
        return f"not readable ({exc.strerror or exc})"


def calib_findings(calib_dir: Path) -> list[Problem]:
    """``calib/`` where there is one: images each readable and of one size, or one readable video
    (by its header); files the rule does not read are warned about. No ``calib/``: nothing."""
    if not calib_dir.exists():
        return []
    if not calib_dir.is_dir():
        return [problem(calib_dir, "not a folder: calib/ holds the board's views (PNG/TIFF images or one video)")]
    files = sorted(p for p in calib_dir.iterdir() if not p.name.startswith("."))
    images = [p for p in files if p.suffix.lower() in FRAME_SUFFIXES and p.is_file()]
    videos = [p for p in files if p.suffix.lower() in CALIB_VIDEO_SUFFIXES and p.is_file()]
    out = []
    if images:
        sizes: dict[tuple, list[Path]] = {}
        for p in images:
            size = _image_size(p)
            if isinstance(size, str):
                out.append(problem(p, f"{size}; the calibration reads every image in calib/: replace or remove it"))
            else:
                sizes.setdefault(size, []).append(p)
        if len(sizes) > 1:
            common = max(sizes, key=lambda s: len(sizes[s]))
            for size, ps in sizes.items():
                if size != common:
                    for p in ps:
                        out.append(problem(p, f"{size[1]}x{size[0]} px, the other views {common[1]}x{common[0]} px: "
                                              "every view must come from the trials' camera at its size"))
        read = images
    elif videos:
        read = videos[:1]
        try:
            open_video(videos[0], count_frames=False).close()
        except DataError as exc:
            out.append(from_error(exc, videos[0]))
        for p in videos[1:]:
            out.append(problem(p, f"not read: the calibration reads one video, {videos[0].name} (the first by name)",
                               severity="warn"))
    else:
        return [problem(calib_dir, "no PNG/TIFF images or video of the calibration board (a JPEG? convert it to "
                                   "PNG; or remove the empty folder)")]
    said = set(videos[1:]) if not images else set()
    for p in files:
        if p not in read and p not in said:
            what = "PNG/TIFF images" if images else "one video"
            out.append(problem(p, f"not read by the calibration (it reads {what} in calib/)", severity="warn"))
    return out
