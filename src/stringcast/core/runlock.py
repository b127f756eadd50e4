"""One workflow run at a time on each results folder: a finished output is never remade beside it.

Snakemake refuses a second run whose outputs overlap a running one's, by lock files under
``.snakemake/locks``; but a run that ends removes that whole folder, other runs' locks included
(Snakemake 9's ``persistence._delete_locks``). A third run is then let in beside the first, and
both remake the same outputs: Snakemake deletes a job's outputs before it starts and after it
fails, so one run can delete what the other has just reported finished.

So each run also claims, before its first job, the results folders its jobs write
(``results/<campaign>/trial_<k>/``, ``results/<campaign>/first_motion/``, ``results/<campaign>/``)
with an exclusive ``flock`` on one file per folder under ``.snakemake/stringcast/locks/``. The
kernel holds the lock while the run's process lives and drops it when the process ends however
it ends (no stale lock to remove after a ``kill -9``). A run that finds a folder claimed stops
before any job with a message naming the folder and the run that holds it; a run that planned
while another finished part of its work (an output newer than the plan) stops as well, rather
than remake it. POSIX only (``fcntl``); elsewhere nothing is claimed.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path
from collections.abc import Iterable

LOCK_DIR = Path(".snakemake", "stringcast", "locks")
"""Where the lock files are, under the workflow's working directory."""

_HELD: dict[str, int] = {}   # folder -> the open file descriptor that holds its lock, for the process's life


class RunConflict(RuntimeError):
    """Another workflow run holds a results folder this run would write, or finished part of its work."""


def _lock_file(folder: str, lock_dir: Path) -> Path:
    digest = hashlib.sha1(folder.encode()).hexdigest()[:12]
    name = folder.strip("/").replace("/", "__")[-80:]
    return lock_dir / f"{name}.{digest}.lock"


def claim_results(folders: Iterable[str], lock_dir: Path = LOCK_DIR) -> list[str]:
    """Hold an exclusive lock on each of ``folders`` (paths relative to the working directory) for
    the rest of this process's life; the folders newly claimed, sorted.

    Raises:
        RunConflict: a folder is held by another process (named by the pid it wrote into the lock
            file); the folders this call claimed are released again.
    """
    try:
        import fcntl
    except ImportError:   # not POSIX
        return []
    lock_dir.mkdir(parents=True, exist_ok=True)
    new = []
    for folder in sorted(set(folders) - set(_HELD)):
        path = _lock_file(folder, lock_dir)
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            release(new)
            raise RunConflict(f"{folder} is being made by another snakemake run (process {holder}); wait for it "
                              "to finish, then run again (or run a target of another trial)") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
        _HELD[folder] = fd
        new.append(folder)
    return new


def release(folders: Iterable[str] | None = None) -> None:
    """Give up the locks on ``folders`` (default: all this process holds)."""
    for folder in list(_HELD if folders is None else folders):
        fd = _HELD.pop(folder, None)
        if fd is not None:
            os.close(fd)


def outputs_newer_than(paths: Iterable[str], since: float) -> list[str]:
    """Those of ``paths`` that exist and were modified after ``since`` (a ``time.time()``), sorted."""
    out = []
    for p in paths:
        try:
            if os.stat(p).st_mtime > since:
                out.append(str(p))
        except OSError:
            pass
    return sorted(out)
