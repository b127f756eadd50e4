"""A workflow job ends with its workflow (stringcast.core.lifeline), its forked workers with it, and
one run at a time holds a results folder (stringcast.core.runlock)."""
import os
import subprocess
import sys
import textwrap
import time

import pytest

from stringcast.core.lifeline import alive, process_start, workflow_stamp
from stringcast.core.runlock import RunConflict, claim_results as claim, outputs_newer_than as newer_than, release

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux: /proc and PR_SET_PDEATHSIG")


def _wait(pred, timeout_s=20.0):
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.05)
    return False


def _gone(pid: int) -> bool:
    """The process has ended (a zombie, reaped by nobody here, counts as ended)."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] == "Z"
    except OSError:
        return True


def test_a_stamp_names_one_process_not_its_pid():
    me = workflow_stamp()
    assert alive(me) and me == f"{os.getpid()}:{process_start(os.getpid())}"
    assert not alive(f"{os.getpid()}:1")                   # the same pid, started at another time: reused
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    assert not alive(workflow_stamp(p.pid) if process_start(p.pid) else str(p.pid))


JOB = textwrap.dedent("""
    import os, sys, time
    from pathlib import Path
    from stringcast.core import atomic_path, forked_map
    from stringcast.core.lifeline import start_lifeline

    out = Path(sys.argv[1])
    assert start_lifeline(sys.argv[2])

    def nap(chunk):
        (out.parent / f"worker_{os.getpid()}").touch()
        time.sleep(120)
        return chunk

    try:
        with atomic_path(out) as tmp:
            tmp.write_text("half")
            (out.parent / "job_started").touch()
            list(forked_map(nap, [1, 2], 2))
            tmp.write_text("finished")
    except KeyboardInterrupt:
        sys.exit(130)
""")


def test_a_job_and_its_workers_end_when_the_workflow_is_killed(tmp_path):
    """kill -9 of the workflow: the job is interrupted (its temporary file removed, nothing that looks
    finished), and its forked workers end with it."""
    workflow = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(300)"])
    job = subprocess.Popen([sys.executable, "-c", JOB, str(tmp_path / "out.txt"), workflow_stamp(workflow.pid)])
    try:
        assert _wait(lambda: len(list(tmp_path.glob("worker_*"))) == 2), "the workers did not start"
        workers = [int(p.name.split("_")[1]) for p in tmp_path.glob("worker_*")]
        assert job.poll() is None
        workflow.kill()
        workflow.wait()
        assert job.wait(timeout=20) in (130, 143)
        assert _wait(lambda: all(_gone(w) for w in workers), 10), "a worker outlived its job"
        assert not (tmp_path / "out.txt").exists()
        assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".out.txt")]
    finally:
        for p in (workflow, job):
            if p.poll() is None:
                p.kill()


def test_a_job_ends_when_its_shell_is_killed(tmp_path):
    """Snakemake cancels a job by killing its shell: the stage under it ends too."""
    shell = subprocess.Popen(["bash", "-c", f'"{sys.executable}" -c "$1" "$2" "$3"; echo done', "job", JOB,
                              str(tmp_path / "out.txt"), workflow_stamp()])
    try:
        assert _wait(lambda: (tmp_path / "job_started").exists())
        shell.kill()
        shell.wait()
        assert _wait(lambda: not list(tmp_path.glob(".out.txt*")), 20), "the job outlived its shell"
        assert not (tmp_path / "out.txt").exists()
    finally:
        if shell.poll() is None:
            shell.kill()


CLAIMER = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    from stringcast.core.runlock import claim_results as claim
    claim(["results/c/trial_1"], Path(sys.argv[1]))
    print("claimed", flush=True)
    time.sleep(300)
""")


def test_one_run_at_a_time_holds_a_results_folder(tmp_path):
    """A folder another process holds is refused, naming it and the process; others can be claimed; the
    kernel drops the lock when the holder dies, however it dies."""
    locks = tmp_path / "locks"
    other = subprocess.Popen([sys.executable, "-c", CLAIMER, str(locks)], stdout=subprocess.PIPE, text=True)
    try:
        assert other.stdout.readline().strip() == "claimed"
        with pytest.raises(RunConflict, match=rf"results/c/trial_1 is being made by another snakemake run "
                                              rf"\(process {other.pid}\)"):
            claim(["results/c/trial_2", "results/c/trial_1"], locks)
        assert claim(["results/c/trial_2"], locks) == ["results/c/trial_2"]    # the refused call held nothing
        other.kill()
        other.wait()
        assert claim(["results/c/trial_1"], locks) == ["results/c/trial_1"]
    finally:
        release()
        if other.poll() is None:
            other.kill()


def test_outputs_made_since_the_plan_are_named(tmp_path):
    before = time.time() - 5
    (tmp_path / "a").write_text("x")
    os.utime(tmp_path / "a", (before - 10, before - 10))
    (tmp_path / "b").write_text("x")
    assert newer_than([str(tmp_path / n) for n in ("a", "b", "c")], before) == [str(tmp_path / "b")]
