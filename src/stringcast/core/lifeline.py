"""A workflow job ends with its workflow: a ``stringcast`` stage whose Snakemake run is gone stops.

Snakemake runs each local job as ``bash -c "... stringcast <stage> ..."``, a child of its own
process. Killed hard (``kill -9``, an out-of-memory kill, a closed terminal), Snakemake takes
none of them along: the shells and the stages go on writing for seconds or minutes, into a
results folder that the next run then works in beside them. So the workflow names its process
in ``$STRINGCAST_WORKFLOW_PID`` for its jobs (``workflow/rules/common.smk``), and a stage started
with it runs a *lifeline*: a daemon thread that checks, every :data:`POLL_S`, that this process
(identified by its pid and start time, so that a reused pid does not count) and the job's own
parent (the shell) still live. When either is gone the stage is interrupted as by Ctrl-C (a
SIGINT to the main thread: ``KeyboardInterrupt``, and the writers' ``finally`` remove their
temporary files, so nothing is left that looks finished), and after :data:`GRACE_S` without an exit (the
main thread inside a long native call) it ends at once with status 143. The stage's worker
processes (:func:`~stringcast.core.forked.forked_map`) end with it: each asks the kernel
(``PR_SET_PDEATHSIG``, Linux) to be killed when its parent dies.

Linux reads a process's start time from ``/proc``; elsewhere a pid that answers counts as alive.
"""
from __future__ import annotations

import os
import signal
import sys
import threading
import time

ENV_PID = "STRINGCAST_WORKFLOW_PID"
"""The environment variable naming the workflow's process: ``<pid>`` or ``<pid>:<start time>``."""
POLL_S = 0.5
"""How often the lifeline looks, s."""
GRACE_S = 3.0
"""How long an interrupted stage has to end by itself before it is ended, s."""


def process_start(pid: int) -> str | None:
    """The start time of process ``pid`` (clock ticks since boot, ``/proc/<pid>/stat`` field 22) as
    text; None where there is no such process or no ``/proc``."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            stat = fh.read()
    except OSError:
        return None
    return stat[stat.rindex(")") + 2:].split()[19]   # fields after the command's name, which may hold spaces


def workflow_stamp(pid: int | None = None) -> str:
    """``<pid>:<start time>`` of process ``pid`` (default: this one), the value of :data:`ENV_PID`."""
    pid = os.getpid() if pid is None else int(pid)
    start = process_start(pid)
    return f"{pid}" if start is None else f"{pid}:{start}"


def alive(stamp: str) -> bool:
    """Whether the process a :func:`workflow_stamp` names is still the one running (a pid reused by
    another process is not)."""
    pid, _, start = stamp.partition(":")
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass                       # someone else's process holds the pid: it lives, whether or not ours
    except ValueError:
        return True                # not a stamp: nothing to watch
    return not start or process_start(int(pid)) in (start, None)


def start_lifeline(stamp: str | None = None, poll_s: float = POLL_S, grace_s: float = GRACE_S) -> bool:
    """Watch the workflow named by ``stamp`` (default ``$STRINGCAST_WORKFLOW_PID``) and this process's
    parent from a daemon thread; end this process when either is gone (module docstring).

    Returns:
        Whether a lifeline was started (False without a stamp: a stage run by hand).
    """
    stamp = os.environ.get(ENV_PID, "") if stamp is None else stamp
    if not stamp:
        return False
    parent = os.getppid()

    def watch():
        while alive(stamp) and os.getppid() == parent:
            time.sleep(poll_s)
        print(f"stringcast: the workflow run (process {stamp.partition(':')[0]}) is gone; stopping",
              file=sys.stderr, flush=True)
        signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)   # wakes a blocking wait, unlike
        time.sleep(grace_s)                                                 # _thread.interrupt_main
        os._exit(128 + signal.SIGTERM)

    threading.Thread(target=watch, name="stringcast-lifeline", daemon=True).start()
    return True


def die_with_parent() -> None:
    """Ask the kernel to kill this process when its parent dies (Linux ``prctl(PR_SET_PDEATHSIG,
    SIGKILL)``; nothing elsewhere): a forked worker does not outlive its stage."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)   # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
