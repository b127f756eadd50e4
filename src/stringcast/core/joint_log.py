"""Joint logs (``joints.csv``, ``motion.csv``): read, written, checked against the arm and the video.

Read with the ``csv`` module and Python's ``float`` and written with ``%.9g``, not pandas: the
stages that read nothing else tabular (sync, the sweep, plan) then never import pandas. The
floats read equal pandas' and the bytes written equal its ``to_csv`` (tests). Every error is a
:class:`~stringcast.core.files.DataError` naming the file (docs/data_contract.md).
"""
from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np

from .files import DataError, atomic_path, read_json


def _joint_columns(columns: list[str], path: Path) -> list[str]:
    cols = []
    j = 1
    while f"q{j}_rad" in columns:
        cols.append(f"q{j}_rad")
        j += 1
    if not cols:
        raise DataError(f"{path}: no joint columns q1_rad, q2_rad, ... in header {columns}")
    return cols


_MISSING = {"", "nan", "NaN", "NA", "N/A", "null"}
"""Cells read as a missing value (NaN), as ``pandas.read_csv`` reads them; refused with the NaN rows."""


def _csv_rows(path: Path, header_only: bool = False) -> list[list[str]]:
    """The non-blank rows of a CSV file as strings (``csv`` module, UTF-8 with or without a
    byte-order mark); only the first line with ``header_only``.

    Raises:
        DataError: a missing or unreadable file (named).
    """
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            return [next(csv.reader(f), [])] if header_only else [r for r in csv.reader(f) if r]
    except FileNotFoundError as exc:
        raise DataError(f"{path}: file not found") from exc
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise DataError(f"{path}: not a readable CSV file: {exc}") from exc


def _read_numeric_csv(path: Path) -> tuple[list[str], list[list[str]]]:
    """The header and the non-blank rows of a CSV file, as strings (:func:`_csv_rows`).

    Raises:
        DataError: missing, unreadable or empty file; a row with another field count than the header.
    """
    rows = _csv_rows(path)
    if not rows:
        raise DataError(f"{path}: not a readable CSV file: it is empty")
    header, body = rows[0], rows[1:]
    for i, r in enumerate(body):
        if len(r) != len(header):
            raise DataError(f"{path}: not a readable CSV file: row {i + 2} has {len(r)} fields, the header "
                            f"{len(header)}")
    return header, body


def _column_floats(path: Path, header: list[str], body: list[list[str]], columns: list[str]) -> np.ndarray:
    """(K, len(columns)) float: the named columns, parsed by Python's ``float`` (correctly rounded, as
    ``pandas.read_csv``'s default parser on the project's files); a missing cell is NaN.

    Raises:
        DataError: a cell that is not a number (its row and column named).
    """
    idx = [header.index(c) for c in columns]
    out = np.empty((len(body), len(idx)))
    for i, r in enumerate(body):
        for k, j in enumerate(idx):
            cell = r[j].strip()
            try:
                out[i, k] = np.nan if cell in _MISSING else float(cell)
            except ValueError:
                raise DataError(f"{path}: row {i + 2}, column {columns[k]}: {cell!r} is not a number") from None
    return out


def joint_header_problem(columns, n_joints: int, arm_name: str | None = None) -> str | None:
    """What is wrong with a joint log's header for an arm of ``n_joints`` joints, or None.

    The log needs ``q1_rad .. q<n_joints>_rad``; a ``q<j>_rad`` beyond them is another arm's.
    """
    want = [f"q{j}_rad" for j in range(1, n_joints + 1)]
    arm = f"the arm {arm_name}" if arm_name else "the arm"
    has = f"{arm} has {n_joints} joint{'s' if n_joints != 1 else ''}: {', '.join(want)}"
    missing = [c for c in want if c not in columns]
    if missing:
        return f"missing columns {', '.join(missing)} ({has})"
    extra = sorted((c for c in columns if re.fullmatch(r"q\d+_rad", str(c)) and c not in want),
                   key=lambda c: int(c[1:-4]))
    if extra:
        return f"joint columns {', '.join(extra)} beyond the arm's ({has})"
    return None


def check_joint_header(path: str | Path, n_joints: int, arm_name: str | None = None) -> None:
    """Check a joint log's header (its first line only) against the arm's joint count.

    Raises:
        DataError: the file is missing, or lacks (or has more than) the arm's joint columns (named).
    """
    path = Path(path)
    problem = joint_header_problem(_csv_rows(path, header_only=True)[0], n_joints, arm_name)
    if problem:
        raise DataError(f"{path}: {problem}")


def read_joint_table(path: str | Path, kind: str = "joints.csv", *, n_joints: int | None = None,
                     arm_name: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Read ``joints.csv`` or ``motion.csv``: the time and joint columns, other columns ignored.

    Read with the ``csv`` module and Python's ``float`` rather than pandas: the stages that read
    nothing else tabular (sync, the sweep, plan) then never import pandas, a large part of their start-up.

    Parameters
    ----------
    path : str or Path
        The CSV file: ``t_s`` and ``q1_rad``, ``q2_rad``, ... columns.
    kind : str
        Which file it is, ``"joints.csv"`` or ``"motion.csv"`` (the reading is the same for both).
    n_joints : int, optional
        The arm's joint count (``campaign.arm.n_joints``): the file must have exactly
        ``q1_rad .. q<n_joints>_rad``; None takes whatever ``q<j>_rad`` columns it has.
    arm_name : str, optional
        The arm, named in the error.

    Returns
    -------
    t : ndarray, (K,)
        Seconds on the controller clock, strictly increasing.
    q : ndarray, (K, J)
        Joint angles, rad.

    Raises
    ------
    DataError
        Missing or unreadable file, a row with another field count than the header,
        missing columns (the arm's joint columns named), a cell that is not a number, NaN or
        infinite values (an empty cell is NaN), fewer than two rows, or ``t_s`` not strictly increasing.
    """
    path = Path(path)
    header, body = _read_numeric_csv(path)
    if "t_s" not in header:
        raise DataError(f"{path}: no 't_s' column in header {header}")
    if n_joints is not None:
        problem = joint_header_problem(header, n_joints, arm_name)
        if problem:
            raise DataError(f"{path}: {problem}")
    data = _column_floats(path, header, body, ["t_s"] + _joint_columns(header, path))
    if len(data) < 2:
        raise DataError(f"{path}: fewer than two rows")
    bad = ~np.isfinite(data).all(axis=1)
    if bad.any():
        raise DataError(f"{path}: NaN or infinite values in {int(bad.sum())} rows (first at row {int(np.argmax(bad)) + 2})")
    t = data[:, 0]
    dt = np.diff(t)
    if np.any(dt <= 0):
        i = int(np.argmax(dt <= 0))
        raise DataError(f"{path}: t_s is not strictly increasing at row {i + 3} ({t[i]} then {t[i + 1]})")
    return t, data[:, 1:]


def check_motion_timing(t: np.ndarray, rate: float, source: str | Path) -> None:
    """Check a motion file's clock: ``t`` (K,) s starts at 0 and steps by the controller period
    1 / ``rate`` (Hz) within 1 us, as the executor plays it.

    Raises:
        DataError: naming ``source``, the start or the largest deviation from the period.
    """
    period = 1.0 / rate
    if abs(t[0]) > 1e-9:
        raise DataError(f"{source}: a motion file starts at t_s = 0, got {t[0]:.6g} s")
    dev = np.max(np.abs(np.diff(t) - period))
    if dev > 1e-6:
        raise DataError(f"{source}: t_s must step by the controller period {period * 1000:.3f} ms "
                        f"({rate:g} Hz); deviates by up to {dev * 1000:.3f} ms")


def read_motion_sidecar(path: str | Path, n_joints: int) -> tuple[np.ndarray, float, np.ndarray]:
    """Read a ``motion.json`` sidecar's motion (docs/data_contract.md): what the plan rule rebuilds the
    played motion from.

    Returns:
        q0: (J,) rad, the initial posture; T: s, the motion time; control_points: (J, N) rad/s,
        the Bezier heights V_1..V_N (eq. 1).

    Raises:
        DataError: a missing or unreadable file, a missing key, or values of the wrong shape for
            an arm of ``n_joints`` joints (the file named).
    """
    path = Path(path)
    doc = read_json(path, mapping=True)
    try:
        q0 = np.asarray(doc["q0_rad"], float)
        T = float(doc["T_s"])
        cp = np.asarray(doc["control_points_rad_s"], float)
    except (KeyError, TypeError, ValueError) as exc:
        raise DataError(f"{path}: needs q0_rad, T_s and control_points_rad_s ({exc})") from exc
    if (q0.shape != (n_joints,) or cp.ndim != 2 or cp.shape[0] != n_joints or cp.shape[1] < 1
            or not 0 < T <= MAX_MOTION_S or not (np.all(np.isfinite(q0)) and np.all(np.isfinite(cp)))):
        raise DataError(f"{path}: q0_rad must have {n_joints} values, control_points_rad_s be {n_joints} x N "
                        f"(N >= 1), all finite, and 0 < T_s <= {MAX_MOTION_S:g} s")
    return q0, T, cp


MAX_MOTION_S = 600.0
"""The longest motion a motion.json may describe, s (a cast takes seconds; more is a corrupt file)."""


def end_speed_shares(t_joints: np.ndarray, q_joints: np.ndarray, qd_max: np.ndarray,
                     window_s: float) -> tuple[float, float]:
    """How fast the arm moves at a joint log's first and at its last sample, as a share of its speed limits.

    Each joint's velocity at an end is the slope, at that end, of a quadratic fitted by least
    squares to the samples within ``window_s`` of it (at least 3): a quadratic, so that a log
    that starts where the arm starts to accelerate reads as still there (a line's slope would
    average the acceleration in).

    Args:
        t_joints: (K,) s, increasing; q_joints: (K, J) rad; qd_max: (J,) rad/s, the speed limits.
        window_s: the span fitted at each end, s.

    Returns:
        (first, last): max over joints of |velocity| / qd_max at the log's first and last sample.
    """
    t, q = np.asarray(t_joints, float), np.asarray(q_joints, float)
    lim = np.asarray(qd_max, float)

    def share(tt: np.ndarray, qq: np.ndarray) -> float:
        n = max(3, int(np.sum(np.abs(tt - tt[0]) <= window_s)))
        x = tt[:n] - tt[0]
        coef, *_ = np.linalg.lstsq(np.column_stack([np.ones(n), x, x * x]), qq[:n], rcond=None)
        return float(np.max(np.abs(coef[1]) / lim))

    if len(t) < 3:
        return float("inf"), float("inf")
    return share(t, q), share(t[::-1], q[::-1])


def check_joint_coverage(t_joints: np.ndarray, t_frames: np.ndarray, joints_path: str | Path,
                         tol_s: float | None = None, *, q_joints: np.ndarray | None = None,
                         qd_max: np.ndarray | None = None, still_share: float = 0.05,
                         still_window_s: float = 0.02) -> dict:
    """Check that the joint log covers every video frame's time, or that the arm was still where it does not.

    A log may start after the first frame (at the motion's start) or end before the last one
    when the arm is still at that end of the log (:func:`end_speed_shares` at most
    ``still_share``): the arm is then taken as still, in the log's first (last) posture, over
    the frames outside it (``np.interp`` holds the ends). A log that ends with the arm moving
    misses part of the motion and is refused. Without ``q_joints`` and ``qd_max`` every frame must
    lie in the log.

    Args:
        t_joints: (K,) joint-log times, s, controller clock (increasing).
        t_frames: (F,) frame times, s, on the same clock (after sync).
        joints_path: the joint log, named in the error.
        tol_s: slack at each end, s; default one median joint-log period.
        q_joints: (K, J) rad, the log's joints; qd_max: (J,) rad/s, the arm's speed limits.
        still_share, still_window_s: see :func:`end_speed_shares`.

    Returns:
        ``{"starts_after_video_s", "ends_before_video_s", "extended",
        "first_speed_share", "last_speed_share"}``: how long the frames run before the log's
        start and after its end (0 when covered), whether the arm is taken as still outside
        the log, and the end speeds (None without q_joints).

    Raises:
        DataError: frames outside the log at an end where the arm moves, or without q_joints
            at all (both spans in the message).
    """
    t_joints = np.asarray(t_joints, float)
    t_frames = np.asarray(t_frames, float)
    if t_joints.size < 2 or t_frames.size < 1:
        raise DataError(f"{joints_path}: cannot check coverage of {t_frames.size} frames by {t_joints.size} joint samples")
    tol = float(np.median(np.diff(t_joints))) if tol_s is None else float(tol_s)
    j0, j1, f0, f1 = t_joints[0], t_joints[-1], float(np.min(t_frames)), float(np.max(t_frames))
    before, after = j0 - f0, f1 - j1
    shares = (None, None)
    if q_joints is not None and qd_max is not None:
        shares = end_speed_shares(t_joints, q_joints, qd_max, still_window_s)
    moving = [s is None or s > still_share for s in shares]
    bad = (before > tol and moving[0], after > tol and moving[1])
    if any(bad):
        gaps = [f"{before:.4f} s before it" if bad[0] else "", f"{after:.4f} s after it" if bad[1] else ""]
        why = "" if shares[0] is None else (
            "; the log {} with the arm moving ({:.0%} of its speed limit, more than {:.0%}): it misses part of the "
            "motion".format(" and ".join(w for w, b in zip(("starts", "ends"), bad) if b),
                            max(s for s, b in zip(shares, bad) if b), still_share))
        raise DataError(f"{joints_path}: the joint log spans {j0:.4f} .. {j1:.4f} s but the video frames span "
                        f"{f0:.4f} .. {f1:.4f} s (controller clock); frames "
                        f"{' and '.join(g for g in gaps if g)} have no joint data{why}")
    return {"starts_after_video_s": max(0.0, float(before)), "ends_before_video_s": max(0.0, float(after)),
            "extended": bool(before > tol or after > tol),
            "first_speed_share": shares[0], "last_speed_share": shares[1]}


def joint_log_span(t_joints: np.ndarray, joint_log: dict | None) -> tuple[float, float]:
    """Controller times (s) between which a frame's arm posture is known: the joint log's own span, or
    every time when ``sync.json``'s ``joint_log`` (:func:`check_joint_coverage`) says the log was
    extended (the arm still, in its first or last logged posture, outside it; ``np.interp`` holds the
    ends). t_joints: (K,) s. For the stages that take frames outside the log as unknown."""
    if joint_log and joint_log.get("extended"):
        return -np.inf, np.inf
    return float(t_joints[0]), float(t_joints[-1])


def write_joint_table(path: str | Path, t: np.ndarray, q: np.ndarray,
                      extra: dict[str, np.ndarray] | None = None) -> None:
    """Write ``joints.csv``/``motion.csv``: ``t_s, q1_rad..qJ_rad`` (+ extra columns), atomically.

    Each value as ``%.9g`` (NaN as an empty cell): the bytes pandas' ``to_csv(float_format="%.9g")``
    wrote, without importing pandas in the stages that write nothing else tabular (plan).

    Args:
        t: (K,) s; q: (K, J) rad; extra: more (K,) float columns by name.

    Raises:
        ValueError: columns of another length than ``t``.
    """
    cols = {"t_s": np.asarray(t, float)}
    q = np.asarray(q, float)
    cols.update({f"q{j + 1}_rad": q[:, j] for j in range(q.shape[1])})
    cols.update({k: np.asarray(v, float) for k, v in (extra or {}).items()})
    K = len(cols["t_s"])
    bad = [k for k, v in cols.items() if v.shape != (K,)]
    if bad:
        raise ValueError(f"write_joint_table({path}): columns {bad} are not ({K},) like t_s")
    cells = [["" if np.isnan(x) else f"{x:.9g}" for x in v.tolist()] for v in cols.values()]
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as f:
            f.write(",".join(cols) + "\n")
            f.writelines(",".join(row) + "\n" for row in zip(*cells))
