"""Reading and writing the data contract's files (docs/data_contract.md).

Every writer writes to a temporary name in the same folder and renames, so a
failed or interrupted step never leaves a half-written file that looks finished.
Every reader raises :class:`DataError` naming the file and what is wrong.
"""
from __future__ import annotations

import json
import os
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any
from collections.abc import Iterator, Mapping

import numpy as np

if TYPE_CHECKING:
    import pandas as pd
import yaml
from .config import ConfigError, load_yaml, validate


TRACK_COLUMNS = ["frame", "t_s", "point", "x_m", "y_m", "valid"]
"""Columns of ``tracks.parquet`` (point 0 = grasp, 1..n the model's points)."""


class DataError(ValueError):
    """An input file is missing or malformed; the message names the file."""


@contextmanager
def atomic_path(path: str | Path, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    On an exception the temporary file is removed and ``path`` is left untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix or path.suffix or ".tmp",
                               dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; finished files get the usual mode
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def write_text(path: str | Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        x = float(x)
        return x if np.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, Path):
        return str(x)
    return x


def write_json(path: str | Path, doc: Any) -> None:
    """Write JSON atomically (NumPy values converted; non-finite floats become null)."""
    write_text(path, json.dumps(_jsonable(doc), indent=2) + "\n")


def read_json(path: str | Path, mapping: bool = False) -> Any:
    """A JSON file's content; with ``mapping``, it must be a JSON object (a dict).

    Raises:
        DataError: the file is missing, unreadable, not JSON, or (``mapping``) not an object (named).
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError as exc:
        raise DataError(f"{path}: file not found") from exc
    except json.JSONDecodeError as exc:
        raise DataError(f"{path}: not valid JSON: {exc}") from exc
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not a text file (not UTF-8: {exc.reason} at byte {exc.start})") from exc
    except OSError as exc:
        raise DataError(f"{path}: not readable: {exc.strerror or exc}") from exc
    if mapping and not isinstance(doc, dict):
        raise DataError(f"{path}: expected a JSON object (keys and values), got a {type(doc).__name__}")
    return doc


def write_yaml(path: str | Path, doc: Any) -> None:
    write_text(path, yaml.safe_dump(_jsonable(doc), sort_keys=False))


def write_parquet(path: str | Path, df: pd.DataFrame) -> None:
    """Write a DataFrame to Parquet with pyarrow, atomically."""
    with atomic_path(path) as tmp:
        df.to_parquet(tmp, engine="pyarrow", index=False)


def read_parquet(path: str | Path, columns: list[str] | None = None) -> pd.DataFrame:
    path = Path(path)
    if not path.exists():
        raise DataError(f"{path}: file not found")
    try:
        import pandas as pd   # here, not at the top: the decode stage never loads pandas (0.2 s)

        df = pd.read_parquet(path, engine="pyarrow")
    except Exception as exc:  # pyarrow raises several types for corrupt files
        raise DataError(f"{path}: not a readable Parquet file: {exc}") from exc
    if columns:
        missing = [c for c in columns if c not in df.columns]
        if missing:
            raise DataError(f"{path}: missing columns {missing}")
    return df


def read_parquet_columns(path: str | Path, columns: list[str]) -> dict[str, np.ndarray]:
    """The named columns of a Parquet file as NumPy arrays, read by ``pyarrow.parquet`` alone (no
    pandas: the plan stage reads ``tracks.parquet`` so); the same values :func:`read_parquet` gives.

    Raises:
        DataError: a missing or unreadable file, or missing columns (named).
    """
    path = Path(path)
    if not path.exists():
        raise DataError(f"{path}: file not found")
    try:
        import pyarrow.parquet as pq

        names = pq.read_schema(path).names
        missing = [c for c in columns if c not in names]
        table = None if missing else pq.read_table(path, columns=list(columns))
    except Exception as exc:  # pyarrow raises several types for corrupt files
        raise DataError(f"{path}: not a readable Parquet file: {exc}") from exc
    if missing:
        raise DataError(f"{path}: missing columns {missing}")
    return {c: table.column(c).to_numpy() for c in columns}


def read_video_meta(path: str | Path) -> dict:
    """Read and check ``video.yaml`` (fps, frames, optional trigger_time_s)."""

    path = Path(path)
    try:
        doc = load_yaml(path)
        if not isinstance(doc, dict):
            raise DataError(f"{path}: expected a mapping with fps and frames")
        validate(doc, "video.schema.json", path)
    except ConfigError as exc:
        raise DataError(str(exc)) from exc
    return doc


BEFORE_SWEEP = {"geometry": "calibration", "clock": "sync"}
"""The sweep's outputs and the files they refine (``geometry.json`` <- ``calibration.json``, ...)."""


def trial_result(results_dir: str | Path, stage: str) -> tuple[str, Path]:
    """(the stage whose file is read, its path) for one trial's ``<stage>.json``: the sweep's
    ``geometry.json`` / ``clock.json`` where the trial has them, else (results made before the
    sweep existed) the ``calibration.json`` / ``sync.json`` they refine (:data:`BEFORE_SWEEP`)."""
    results_dir = Path(results_dir)
    if (results_dir / f"{stage}.json").exists() or stage not in BEFORE_SWEEP:
        return stage, results_dir / f"{stage}.json"
    return BEFORE_SWEEP[stage], results_dir / f"{BEFORE_SWEEP[stage]}.json"


def find_video(trial_dir: str | Path) -> Path:
    """The trial's video: ``video.<ext>`` file, a ``video/`` frame folder, or a ``.cihx``."""
    trial_dir = Path(trial_dir)
    cands = sorted(p for p in trial_dir.glob("video*") if p.name != "video.yaml")
    if not cands:
        raise DataError(f"{trial_dir}: no video (expected video.mkv/.avi/.mp4, a video/ folder of frames, or video.cihx)")
    return cands[0]


@dataclass(frozen=True)
class TrialFiles:
    """A trial's raw files, as a stage reads them (``docs/data_contract.md``).

    The workflow names each file on the stage's command line (``--video``, ``--video-meta``,
    ``--joints``); :meth:`in_folder` finds them by the data contract's names, for a person or a
    script that names the trial's folder.

    Attributes:
        video: the video: a ``video.<ext>`` container, a ``video/`` frame folder or a ``.cihx``.
        joints: ``joints.csv``, the joint log (t_s, q1_rad .. qJ_rad).
        video_meta: ``video.yaml`` (fps, trigger_time_s, ...); None for a stage that does not read it.
        played: the played motion's ``motion.json`` (its T_s and predicted closest approach); None
            for a stage that does not read it.
    """

    video: Path
    joints: Path
    video_meta: Path | None = None
    played: Path | None = None

    @classmethod
    def in_folder(cls, trial_dir: str | Path) -> TrialFiles:
        """``data/<campaign>/trial_<k>``'s files: :func:`find_video`, ``joints.csv``, ``video.yaml``,
        ``motion.json``.

        Raises:
            DataError: the folder holds no video.
        """
        d = Path(trial_dir)
        return cls(find_video(d), d / "joints.csv", d / "video.yaml", d / "motion.json")

    @classmethod
    def of(cls, trial: TrialFiles | str | Path) -> TrialFiles:
        """``trial`` itself, or the files of the trial folder it names (:meth:`in_folder`)."""
        return trial if isinstance(trial, TrialFiles) else cls.in_folder(trial)

    @property
    def name(self) -> str:
        """The trial as messages name it: the folder of its joint log (the trial's folder)."""
        return str(self.joints.parent)


@dataclass(frozen=True)
class TrialResults:
    """One trial's products that the reports read (``docs/data_contract.md``), each file named.

    Attributes:
        geometry: ``geometry.json`` (the sweep's mapping; ``calibration.json`` where it has none).
        clock: ``clock.json`` (the sweep's clock; ``sync.json`` where it has none).
        tracks: ``tracks.parquet``. tracking: ``tracking.json`` (the tracking's verdict).
        params: ``params.json`` (the estimate and the fit's verdict). fit: ``fit.parquet``.
        motion: the next motion's ``motion.csv``. motion_meta: its ``motion.json``.
        prediction: ``prediction.json``, the previous estimate's check on this trial (None: trial 1).
    """

    geometry: Path
    clock: Path
    tracks: Path
    tracking: Path
    params: Path
    fit: Path
    motion: Path
    motion_meta: Path
    prediction: Path | None = None

    @classmethod
    def in_folder(cls, results_dir: str | Path) -> TrialResults:
        """``results/<campaign>/trial_<k>``'s files by the data contract's names (:func:`trial_result` for
        the geometry and the clock)."""
        d = Path(results_dir)
        pred = d / "prediction.json"
        return cls(trial_result(d, "geometry")[1], trial_result(d, "clock")[1], d / "tracks.parquet",
                   d / "tracking.json", d / "params.json", d / "fit.parquet", d / "motion.csv", d / "motion.json",
                   pred if pred.is_file() else None)


def _numbers(column, name: str, source) -> np.ndarray:
    """A table column as float64 (N,); DataError naming ``source`` and the column where it is not numeric."""
    try:
        return np.asarray(column, dtype=float)
    except (TypeError, ValueError) as exc:
        raise DataError(f"{source}: column {name} must hold numbers ({exc})") from exc


def _whole(column, name: str, source) -> np.ndarray:
    """A table column of whole numbers as int64 (N,); DataError where a value is not one."""
    v = _numbers(column, name, source)
    if not np.all(np.isfinite(v)) or np.any(v != np.round(v)):
        raise DataError(f"{source}: column {name} must hold whole numbers")
    return v.astype(np.int64)


def tracks_arrays(tracks, n: int, source="tracks") -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Long ``tracks.parquet`` table (a DataFrame, or a mapping of column arrays as
    :func:`read_parquet_columns` gives) -> frames (F,), t (F,) s, xy (F, n+1, 2) m (NaN if
    absent), valid (F, n+1)."""
    missing = [c for c in TRACK_COLUMNS if c not in tracks]
    if missing:
        raise DataError(f"{source}: missing columns {missing}")
    if len(tracks["frame"]) == 0:
        raise DataError(f"{source}: no rows")
    pts = _whole(tracks["point"], "point", source)
    if pts.min() < 0 or pts.max() > n:
        raise DataError(f"{source}: point ids must be 0..{n} for this string (n = {n}), got {pts.min()}..{pts.max()}")
    frames, fi = np.unique(_whole(tracks["frame"], "frame", source), return_inverse=True)
    if len(np.unique(fi * (n + 1) + pts)) != len(pts):
        raise DataError(f"{source}: a (frame, point) pair appears more than once")
    t = np.full(len(frames), np.nan)
    t[fi] = _numbers(tracks["t_s"], "t_s", source)
    xy = np.full((len(frames), n + 1, 2), np.nan)
    xy[fi, pts, 0] = _numbers(tracks["x_m"], "x_m", source)
    xy[fi, pts, 1] = _numbers(tracks["y_m"], "y_m", source)
    valid = np.zeros((len(frames), n + 1), bool)
    flags = np.asarray(tracks["valid"])
    if flags.dtype != bool and not (np.issubdtype(flags.dtype, np.integer) and np.all((flags == 0) | (flags == 1))):
        raise DataError(f"{source}: column valid must hold true/false, got {flags.dtype} values such as {flags[0]!r}")
    valid[fi, pts] = flags.astype(bool)
    valid &= np.all(np.isfinite(xy), axis=-1)
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise DataError(f"{source}: frame times t_s must be finite and increase with the frame number")
    return frames, t, xy, valid


__all__ = ["BEFORE_SWEEP", "TRACK_COLUMNS", "DataError", "atomic_path", "find_video", "read_json", "read_parquet",
           "read_parquet_columns", "read_video_meta", "tracks_arrays", "trial_result", "write_json",
           "write_parquet", "write_text", "write_yaml"]


def write_by_content(text: str, folder: str | Path, stem: str, suffix: str = ".yaml") -> Path:
    """``text`` as ``<folder>/<stem>-<sha256[:12]><suffix>``, named by its content and written atomically
    where it is not there yet: a workflow's input whose time changes only when its content does, which a
    job that Slurm starts (parsing the Snakefile again) finds as written.

    Returns:
        The file's path (as ``folder`` gives it).
    """
    import hashlib

    path = Path(folder) / f"{stem}-{hashlib.sha256(text.encode()).hexdigest()[:12]}{suffix}"
    if not path.is_file():
        write_text(path, text)
    return path


def write_job_config(config: Mapping, folder: str | Path = "results/.stringcast") -> Path:
    """The config a workflow run holds (its config files merged, ``--config`` overrides included), as
    one YAML file for its jobs to read (``$STRINGCAST_CONFIG``): ``<folder>/config-<sha256[:12]>.yaml``
    (:func:`write_by_content`), so that runs with the same config share it.

    Returns:
        The file's path (as ``folder`` gives it).
    """
    return write_by_content(yaml.safe_dump(_jsonable(dict(config)), sort_keys=True), folder, "config")
