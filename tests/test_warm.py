"""Warm start (stringcast.warm): a stage run through the warm server is the stage run cold, in the
client's streams, directory and environment, with its exit status; signals reach the job; anything
else (another command, no server) runs cold."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from stringcast import cli, warm

from conftest import random_frames, write_ffv1

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="warm start is Linux only")


def _nap(argv):
    """The job ``nap SECONDS CODE`` of the protocol tests' server."""
    from threadpoolctl import threadpool_info

    seconds, code = float(argv[1]), argv[2]
    blas = min(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")
    Path("job.txt").write_text(f"{os.getpid()} {blas} {os.getcwd()} {os.environ.get('WARM_TEST', '')}")
    print("out from the job")
    print("err from the job", file=sys.stderr)
    time.sleep(seconds)
    if code == "raise":
        raise ValueError("the job failed")
    return int(code)


def _wait_for(cond, timeout=10.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.02)
    return False


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:   # a zombie is gone for our purpose
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def _fork_server(path: Path, log: Path, stages: bool = False) -> int:
    """A server forked from this test process; its pid. It serves ``nap``, or with ``stages`` the
    workflow's stages as the command line's server does."""
    if stages:
        args = (cli.preload_stages, lambda a: a[0] in cli.STAGES, cli.main)
    else:
        args = (lambda: None, lambda a: a[0] == "nap", _nap)
    pid = os.fork()
    if pid == 0:
        try:
            with open(log, "w") as fh:
                warm.serve(str(path), *args, parent=os.getppid(), log=fh)
        finally:
            os._exit(0)
    assert _wait_for(path.exists, 60), "the warm server never opened its socket"
    return pid


@pytest.fixture
def server(tmp_path):
    path, log = tmp_path / "warm.sock", tmp_path / "warm.log"
    pid = _fork_server(path, log)
    yield path, log
    os.kill(pid, signal.SIGTERM)
    os.waitpid(pid, 0)


def _client(args, sock, cwd, env_extra=None, **kw):
    env = {**os.environ, warm.ENV_SOCKET: str(sock), "WARM_TEST": "from the client", "OPENBLAS_NUM_THREADS": "1",
           **(env_extra or {})}
    return subprocess.Popen([sys.executable, "-c", "import sys; from stringcast.cli import main; sys.exit(main())",
                             *args], cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def test_a_stage_runs_in_the_server_with_the_clients_streams_directory_and_environment(server, tmp_path):
    sock, log = server
    work = tmp_path / "work"
    work.mkdir()
    proc = _client(["nap", "0", "3"], sock, work)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 3
    assert out == "out from the job\n" and err == "err from the job\n"
    job_pid, blas, cwd, env = (work / "job.txt").read_text().split(" ", 3)
    assert int(job_pid) != proc.pid and cwd == str(work) and env == "from the client"
    assert blas == "1"    # the client's BLAS threads (Snakemake sets them to a rule's), not the server's
    assert f"pid {job_pid}: stringcast nap 0 3" in log.read_text()


def test_a_job_that_raises_prints_its_traceback_and_exits_1(server, tmp_path):
    proc = _client(["nap", "0", "raise"], server[0], tmp_path)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 1
    assert "Traceback" in err and "ValueError: the job failed" in err


def test_sigterm_to_the_client_ends_the_job_and_the_client(server, tmp_path):
    proc = _client(["nap", "60", "0"], server[0], tmp_path)
    assert _wait_for((tmp_path / "job.txt").exists)
    job = int((tmp_path / "job.txt").read_text().split()[0])
    proc.send_signal(signal.SIGTERM)
    proc.communicate(timeout=30)
    assert proc.returncode == -signal.SIGTERM
    assert _wait_for(lambda: not _alive(job)), "the job outlived its cancelled client"


def test_a_killed_client_takes_its_job_with_it(server, tmp_path):
    proc = _client(["nap", "60", "0"], server[0], tmp_path)
    assert _wait_for((tmp_path / "job.txt").exists)
    job = int((tmp_path / "job.txt").read_text().split()[0])
    proc.kill()
    proc.communicate(timeout=30)
    assert _wait_for(lambda: not _alive(job)), "the job outlived its killed client"


def test_other_commands_and_an_absent_server_run_cold(server, tmp_path):
    cold = subprocess.run([sys.executable, "-m", "stringcast.cli", "settings"], capture_output=True, text=True)
    assert cold.returncode == 0 and "evaluation:" in cold.stdout
    for sock in (server[0], tmp_path / "no_such.sock"):
        proc = _client(["settings"], sock, tmp_path)
        out, _ = proc.communicate(timeout=60)
        assert proc.returncode == 0 and out == cold.stdout
    assert "settings" not in server[1].read_text()


def test_the_server_ends_with_its_parent(tmp_path):
    path = tmp_path / "warm.sock"
    middle = os.fork()
    if middle == 0:   # a parent for the server, which then exits
        try:
            _fork_server(path, tmp_path / "warm.log")
        finally:
            os._exit(0)
    os.waitpid(middle, 0)
    assert path.exists()
    assert _wait_for(lambda: not path.exists()), "the server outlived its parent"


def test_a_real_stage_warm_writes_what_it_writes_cold(tmp_path):
    """decode through the command line's server (every stage preloaded): the same files and messages
    as cold, and a bad input the same one-line error and status 2."""
    path, log = tmp_path / "warm.sock", tmp_path / "warm.log"
    pid = _fork_server(path, log, stages=True)
    try:
        trial = tmp_path / "trial_1"
        trial.mkdir()
        write_ffv1(trial / "video.mkv", random_frames(6, 24, 32))
        runs = {}
        for how, sock in (("warm", path), ("cold", tmp_path / "none.sock")):
            proc = _client(["decode", "--trial-dir", "trial_1", "--out", f"{how}/frames.npy"], sock, tmp_path)
            runs[how] = (proc.communicate(timeout=120), proc.returncode)
            bad = _client(["decode", "--trial-dir", "no_trial", "--out", f"{how}/x.npy"], sock, tmp_path)
            runs[how + " bad"] = (bad.communicate(timeout=120), bad.returncode)
        assert runs["warm"][1] == 0 and runs["warm"][0][0].replace("warm", "cold") == runs["cold"][0][0]
        assert np.array_equal(np.load(tmp_path / "warm" / "frames.npy"), np.load(tmp_path / "cold" / "frames.npy"))
        assert runs["warm bad"][1] == runs["cold bad"][1] == 2
        assert runs["warm bad"][0][1].replace("warm", "cold") == runs["cold bad"][0][1] != ""
        assert "stringcast decode --trial-dir trial_1" in log.read_text()
    finally:
        os.kill(pid, signal.SIGTERM)
        os.waitpid(pid, 0)


def test_start_server_only_for_local_runs_and_not_when_switched_off(tmp_path, monkeypatch):
    monkeypatch.delenv(warm.ENV_SOCKET, raising=False)
    assert warm.start_server(False, str(tmp_path)) is None
    monkeypatch.setenv(warm.ENV_SWITCH, "0")
    assert warm.start_server(True, str(tmp_path)) is None and warm.ENV_SOCKET not in os.environ
    monkeypatch.delenv(warm.ENV_SWITCH)
    path = warm.start_server(True, str(tmp_path))
    try:
        assert os.environ[warm.ENV_SOCKET] == path
        assert _wait_for(lambda: os.path.exists(path), 60), (tmp_path / warm.LOG_NAME).read_text()
    finally:
        warm.stop_server()
    assert warm.ENV_SOCKET not in os.environ and not os.path.exists(path)


def test_a_stage_waits_for_a_starting_server_but_not_for_a_gone_one(tmp_path, monkeypatch):
    path, log = tmp_path / "warm.sock", tmp_path / "warm.log"
    pid = os.fork()
    if pid == 0:   # a server still importing for a second when the clients start
        try:
            with open(log, "w") as fh:
                warm.serve(str(path), lambda: time.sleep(1.0), lambda a: a[0] == "nap", _nap,
                           parent=os.getppid(), log=fh)
        finally:
            os._exit(0)
    try:
        monkeypatch.setenv(warm.ENV_SOCKET, str(path))
        monkeypatch.setenv(warm.ENV_SERVER_PID, str(pid))
        t0 = time.monotonic()
        assert warm.run_in_server(["nap", "0", "0"], wait_s=0.0) is None   # decode's way: cold at once
        assert time.monotonic() - t0 < 0.5 and not path.exists()
        proc = _client(["nap", "0", "4"], path, tmp_path, env_extra={warm.ENV_SERVER_PID: str(pid)})
        out, _ = proc.communicate(timeout=60)
        assert proc.returncode == 4 and out == "out from the job\n"
        job_pid = int((tmp_path / "job.txt").read_text().split()[0])
        assert job_pid != proc.pid and f"pid {job_pid}: stringcast nap 0 4" in log.read_text()
    finally:
        os.kill(pid, signal.SIGTERM)
        os.waitpid(pid, 0)
    monkeypatch.setenv(warm.ENV_SOCKET, str(tmp_path / "never.sock"))
    t0 = time.monotonic()
    assert warm.run_in_server(["nap", "0", "0"], wait_s=30.0) is None   # its server is gone: no wait
    assert time.monotonic() - t0 < 1.0


_NUMBA_SERVER = '''
import sys
from stringcast import warm


def run(argv):
    import numba
    from numba import njit, prange

    @njit(parallel=True)                 # compiled in the job: numba re-reads the environment
    def total(n):
        s = 0.0
        for i in prange(n):
            s += i
        return s

    print(total(10), numba.get_num_threads(), numba.config.NUMBA_NUM_THREADS)
    return 0


warm.serve(sys.argv[1], lambda: __import__("numba"), lambda a: a[0] == "numba", run, parent=int(sys.argv[2]))
'''


def test_a_job_compiles_numba_kernels_on_its_own_thread_count(tmp_path):
    """A job whose NUMBA_NUM_THREADS is not the server's compiles a parallel kernel and runs it on its own
    count, as it would cold (a pool started on the server's count refused every later compile)."""
    script, sock = tmp_path / "server.py", tmp_path / "warm.sock"
    script.write_text(_NUMBA_SERVER)
    server = subprocess.Popen([sys.executable, str(script), str(sock), str(os.getpid())],
                              env={**os.environ, "NUMBA_NUM_THREADS": "2"})
    try:
        assert _wait_for(sock.exists, 60), "the warm server never opened its socket"
        proc = _client(["numba"], sock, tmp_path, env_extra={"NUMBA_NUM_THREADS": "1"})
        out, err = proc.communicate(timeout=120)
        assert proc.returncode == 0, err
        assert out.split() == ["45.0", "1", "1"]
    finally:
        server.terminate()
        server.wait(timeout=30)
