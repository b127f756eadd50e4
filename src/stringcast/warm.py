"""Warm start: the workflow's jobs forked from one process that has imported every stage.

A rule runs ``stringcast <stage> ...`` in a process of its own, and each such process paid 0.5-1.5 s
before its first useful instruction: importing NumPy, SciPy, OpenCV, pandas and numba, and numba
setting up its compiler to load the cached kernels. On a trial's chain of stages (sync, sweep,
track, estimate, plan) that was about 6 s of the 40 s a person waits at the arm for the next
motion (docs/results.md, issue 26).

A local Snakemake run therefore starts one *warm server* (the workflow's ``onstart``,
:func:`start_server`): a process that imports every stage once and then forks a child for each
job. The job's own ``stringcast`` process is only a client (:func:`run_in_server`, called first
by :func:`stringcast.cli.main`): it hands the server its arguments, working directory,
environment and standard streams (the log the rule redirects them to) and waits for the forked
child's exit status. The child runs :func:`stringcast.cli.main` as the job's process would, so
the outputs are the same byte for byte (tests/workflow/test_slurm.py compares a local run, warm,
file by file with a Slurm run, cold).

* Only the workflow's stages (``stringcast.cli.STAGES``) run warm; any other command, or any
  failure to reach the server, runs in the client's own process as before.
* SIGINT, SIGTERM and SIGHUP sent to the client (Snakemake cancelling a job) are passed on to the
  child, and a client that dies (SIGKILL) takes the child with it.
* The server ends with the Snakemake run (``onsuccess``, ``onerror``: :func:`stop_server`) or as
  soon as its parent process is gone. Its log, one line per job (appended to by every run), is
  ``.snakemake/stringcast_warm.log``.
* Linux only (``fork``, file descriptors passed over a Unix socket); the Slurm and other
  non-local executors run every job cold. ``STRINGCAST_WARM_START=0`` turns it off.
* Snakemake's ``benchmark:`` files then measure the client: their wall seconds (``s``) are the
  job's, their CPU and memory columns are not.

This module imports only the standard library: the client must cost nothing.
"""
from __future__ import annotations

import json
import os
import select
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
import traceback
from typing import Callable

ENV_SOCKET = "STRINGCAST_WARM"
"""The server's socket, set by :func:`start_server` for the jobs of the run."""
ENV_SERVER_PID = "STRINGCAST_WARM_PID"
"""The server's process id, set with :data:`ENV_SOCKET`: a client that finds no socket yet waits
while that process lives (it is still importing the stages)."""
ENV_SWITCH = "STRINGCAST_WARM_START"
"""``0``: no warm server (every job cold)."""
LOG_NAME = os.path.join(".snakemake", "stringcast_warm.log")
"""The server's log, under the Snakemake run's working directory."""
FORWARDED = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""Signals the client passes on to the job."""
SERVER_ENTRY = "from stringcast.cli import warm_server; warm_server()"
"""The server's program (``python -c``, arguments SOCKET PARENT_PID): the stringcast command line's."""

_HEADER = struct.Struct("!I")   # the request's length; the three standard streams travel with it
_SERVER: tuple | None = None    # (process, directory) of the server this process started


def run_in_server(argv: list[str], wait_s: float = 0.0) -> int | None:
    """Run ``stringcast argv`` in the warm server named by ``$STRINGCAST_WARM``; its exit status.

    Returns None, having started nothing, where there is no server to reach, it declines
    (``argv`` is not a workflow stage) or a standard stream cannot be passed: the caller then
    runs the command itself. A job killed by a signal kills this process with the same signal.

    ``wait_s``: where the server is still starting (no socket yet, its process
    ``$STRINGCAST_WARM_PID`` alive), wait up to this many seconds for it rather than run cold.
    The first jobs of a run start beside the server's imports; a job that would import the same
    stages cold spends that CPU twice, taken from the jobs beside it (the video's decode).

    Raises:
        RuntimeError: the server died after the job had started (its outcome is unknown).
    """
    path = os.environ.get(ENV_SOCKET)
    if not path or not sys.platform.startswith("linux"):
        return None
    if wait_s > 0 and not os.path.exists(path):
        _wait_for_server(path, os.environ.get(ENV_SERVER_PID, ""), wait_s)
    try:
        for fd in (0, 1, 2):
            os.fstat(fd)                             # a closed standard stream cannot be passed on
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        sock.connect(path)
    except OSError:
        return None
    with sock, sock.makefile("rb") as replies:
        request = json.dumps({"argv": list(argv), "cwd": os.getcwd(), "env": dict(os.environ)}).encode()
        try:
            socket.send_fds(sock, [_HEADER.pack(len(request))], [0, 1, 2])
            sock.sendall(request)
            reply = replies.readline().decode().split()
        except OSError:
            return None
        if reply[:1] != ["pid"]:
            return None                              # declined: not a stage
        pid = int(reply[1])
        for sig in FORWARDED:
            signal.signal(sig, lambda s, _frame: _kill(pid, s))
        outcome = replies.readline().decode().split()
    if len(outcome) != 2:
        raise RuntimeError(f"stringcast: the warm server ({path}) ended while running {' '.join(argv)} "
                           f"(pid {pid}); its outcome is unknown")
    if outcome[0] == "signal":
        sig = int(outcome[1])
        signal.signal(sig, signal.SIG_DFL)
        os.kill(os.getpid(), sig)
        return 128 + sig
    return int(outcome[1])


def _wait_for_server(path: str, pid: str, wait_s: float) -> None:
    """Until the socket ``path`` exists, the server's process ``pid`` (decimal text) is gone, or
    ``wait_s`` seconds have passed."""
    end = time.monotonic() + wait_s
    while pid.isdigit() and not os.path.exists(path) and time.monotonic() < end:
        try:
            os.kill(int(pid), 0)
        except OSError:   # gone (or not ours): nothing to wait for
            return
        time.sleep(0.02)


def _kill(pid: int, sig: int) -> None:
    try:
        os.kill(pid, sig)
    except ProcessLookupError:
        pass


def serve(path: str, preload: Callable[[], None], accepts: Callable[[list], bool],
          run: Callable[[list], int], parent: int | None = None, log=None) -> None:
    """The warm server: ``preload()``, listen on the Unix socket ``path``, fork each job.

    A request whose ``accepts(argv)`` is false is declined (the client runs it itself); a job
    runs ``run(argv)`` in a fork of this process, in the client's streams, working directory
    and environment, and exits with its return value. Serves until SIGTERM or, with
    ``parent`` (a pid), until that process is gone. The socket appears only once ``preload``
    has returned (a job that starts before then runs cold).
    """
    import threadpoolctl  # noqa: F401  (each job's thread counts: _thread_counts)

    t0 = time.perf_counter()
    _note(log, f"warm server {os.getpid()} for {path}: importing the stages")
    preload()
    _note(log, f"ready in {time.perf_counter() - t0:.2f} s")
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    tmp = f"{path}.{os.getpid()}"
    srv.bind(tmp)
    srv.listen(64)
    os.replace(tmp, path)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    try:
        while parent is None or os.getppid() == parent:
            if select.select([srv], [], [], 1.0)[0]:
                conn, _ = srv.accept()
                if os.fork() == 0:
                    srv.close()
                    _handle(conn, accepts, run, log)
                    os._exit(0)
                conn.close()
            while _reap():
                pass
    finally:
        srv.close()
        if os.path.exists(path):
            os.unlink(path)


def _reap() -> bool:
    try:
        return os.waitpid(-1, os.WNOHANG)[0] > 0
    except ChildProcessError:
        return False


def _handle(conn: socket.socket, accepts, run, log) -> None:
    """In a fork of the server: read one request, fork its job, report the job's end."""
    with conn:
        head, fds, _, _ = socket.recv_fds(conn, _HEADER.size, 3)
        size = _HEADER.unpack(head + _recv_exactly(conn, _HEADER.size - len(head)))[0]
        request = json.loads(_recv_exactly(conn, size))
        argv = request["argv"]
        if not argv or len(fds) != 3 or not accepts(argv):
            conn.sendall(b"cold\n")
            return
        pid = os.fork()
        if pid == 0:
            conn.close()
            _run_job(run, argv, request["cwd"], request["env"], fds)
        for fd in fds:
            os.close(fd)
        _note(log, f"pid {pid}: stringcast {' '.join(argv)}")
        conn.sendall(f"pid {pid}\n".encode())
        status = _wait(pid, conn)
        if os.WIFSIGNALED(status):
            conn.sendall(f"signal {os.WTERMSIG(status)}\n".encode())
        else:
            conn.sendall(f"exit {os.waitstatus_to_exitcode(status)}\n".encode())


def _recv_exactly(conn: socket.socket, n: int) -> bytes:
    data = b""
    while len(data) < n:
        chunk = conn.recv(n - len(data))
        if not chunk:
            raise ConnectionError("the client closed the connection mid-request")
        data += chunk
    return data


def _wait(pid: int, conn: socket.socket) -> int:
    """The job's wait status; a client gone before the job ends (its socket at EOF) gets the job
    sent SIGTERM, then SIGKILL after 10 s."""
    try:
        ends = os.pidfd_open(pid)      # readable when the job ends (Linux 5.3)
    except OSError:
        ends = None                    # then polled
    try:
        while True:
            ready = select.select([conn] if ends is None else [ends, conn], [], [], 0.05 if ends is None else None)[0]
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                return status
            if conn in ready and not conn.recv(1, socket.MSG_PEEK):
                _kill(pid, signal.SIGTERM)
                for _ in range(200):
                    done, status = os.waitpid(pid, os.WNOHANG)
                    if done:
                        return status
                    time.sleep(0.05)
                _kill(pid, signal.SIGKILL)
                return os.waitpid(pid, 0)[1]
    finally:
        if ends is not None:
            os.close(ends)


def _run_job(run, argv: list[str], cwd: str, env: dict, fds: list[int]) -> None:
    """In the job's process: take on the client's streams, directory and environment, run the
    command, exit with its status (never returns)."""
    code = 1
    try:
        for target, fd in enumerate(fds):
            if fd != target:
                os.dup2(fd, target)
                os.close(fd)
        os.chdir(cwd)
        os.environ.clear()
        os.environ.update(env)
        os.environ.pop(ENV_SOCKET, None)       # the job itself runs here, never in a server again
        os.environ.pop(ENV_SERVER_PID, None)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGCHLD):
            signal.signal(sig, signal.SIG_DFL)
        sys.stdin, sys.stdout, sys.stderr = _std_streams()
        _thread_counts(env)
        sys.argv = ["stringcast", *argv]
        code = run(argv)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        if not isinstance(exc.code, (int, type(None))):
            print(exc.code, file=sys.stderr)
    except BaseException:  # noqa: BLE001 - reported as the job's own process would, then its status
        traceback.print_exc()
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except Exception:  # noqa: BLE001 - a closed stream: nothing more to say
                pass
        os._exit(code if isinstance(code, int) else 1)


def _std_streams():
    """New sys.stdin, stdout, stderr on file descriptors 0-2, as Python opens them at start-up:
    stdout line-buffered on a terminal only, stderr always, both written through under
    ``$PYTHONUNBUFFERED``."""
    def stream(fd, mode, buffering, errors):
        return open(fd, mode, buffering=buffering, encoding=sys.stdout.encoding, errors=errors, closefd=False)

    streams = (stream(0, "r", -1, "strict"), stream(1, "w", 1 if os.isatty(1) else -1, sys.stdout.errors),
               stream(2, "w", 1, "backslashreplace"))
    if os.environ.get("PYTHONUNBUFFERED"):
        for s in streams[1:]:
            s.reconfigure(write_through=True)
    return streams


def _thread_counts(env: dict) -> None:
    """Apply the job's thread counts to the libraries the server loaded, which read theirs from the
    server's environment when they were loaded: the BLAS (OpenBLAS's variables first) and
    OpenMP by ``threadpoolctl``, numba's configuration re-read from the job's environment (as a cold
    job reads it at import) before its thread pool starts, and its ``NUMBA_NUM_THREADS`` used. Snakemake sets ``OMP_NUM_THREADS``,
    ``OPENBLAS_NUM_THREADS``, ``NUMBA_NUM_THREADS`` and others to a rule's threads, and a BLAS on
    another number of threads sums in another order: without this a warm job's calibration differed
    from a cold one's in the 7th digit. A numba pool started on the server's count refused every
    later compile in the job (numba re-reads the environment then: "Cannot set NUMBA_NUM_THREADS to a
    different value once the threads have been launched"), wherever a rule's threads were not the
    machine's CPUs and a kernel was not yet in numba's cache (a fresh clone)."""
    from threadpoolctl import threadpool_limits

    def count(*names):
        for name in names:
            if env.get(name, "").isdigit() and int(env[name]) > 0:
                return int(env[name])
        return None

    limits = {"blas": count("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS"),
              "openmp": count("OMP_NUM_THREADS")}
    limits = {api: n for api, n in limits.items() if n is not None}
    if limits:
        threadpool_limits(limits=limits)
    if "numba" in sys.modules:
        import numba

        numba.config.reload_config()   # the job's NUMBA_* (the server started no thread pool)
        if count("NUMBA_NUM_THREADS"):     # the pool is the server's size: the job uses its own count of it
            numba.set_num_threads(min(count("NUMBA_NUM_THREADS"), numba.config.NUMBA_NUM_THREADS))


def _note(log, text: str) -> None:
    if log is not None:
        log.write(f"{time.strftime('%H:%M:%S')} {text}\n")
        log.flush()


def start_server(local: bool, workdir: str = ".") -> str | None:
    """Start a warm server for this Snakemake run's jobs (the workflow's ``onstart``); its socket.

    ``local``: Snakemake runs the jobs on this machine (``workflow.local_exec``); otherwise, off
    Linux or with ``$STRINGCAST_WARM_START`` = 0, nothing is started and None returned. Sets
    ``$STRINGCAST_WARM`` for the jobs. Never raises: a server that cannot start leaves the jobs cold.
    """
    global _SERVER
    if not local or os.environ.get(ENV_SWITCH, "1") == "0" or not sys.platform.startswith("linux"):
        return None
    stop_server()
    directory = tempfile.mkdtemp(prefix="stringcast-warm-")   # mode 0700: the socket is this user's
    path = os.path.join(directory, "socket")
    try:
        log_path = os.path.join(workdir, LOG_NAME)
        os.makedirs(os.path.dirname(log_path), exist_ok=True)
        with open(log_path, "a") as log:
            proc = subprocess.Popen([sys.executable, "-c", SERVER_ENTRY, path, str(os.getpid())],
                                    stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                    start_new_session=True)   # a Ctrl-C reaches the jobs, not the server
    except OSError:
        shutil.rmtree(directory, ignore_errors=True)
        return None
    _SERVER = (proc, directory)
    os.environ[ENV_SOCKET] = path
    os.environ[ENV_SERVER_PID] = str(proc.pid)
    return path


def stop_server() -> None:
    """Stop the server :func:`start_server` started (the workflow's ``onsuccess`` and ``onerror``)."""
    global _SERVER
    os.environ.pop(ENV_SOCKET, None)
    os.environ.pop(ENV_SERVER_PID, None)
    if _SERVER is None:
        return
    proc, directory = _SERVER
    _SERVER = None
    proc.terminate()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    shutil.rmtree(directory, ignore_errors=True)
