"""The whole loop end to end on a small virtual lab, through Snakemake (slow: run once in CI).

A tmp project root links the repo's Snakefile and workflow/ and holds its own
config: a 512 x 512 camera at 250 fps with a larger ChArUco board, and small
search budgets, so that two executions finish in a few minutes on 2 cores. After the
campaign it checks the workflow's bookkeeping: nothing to redo, a deleted product reruns
only what depends on it, a run killed hard mid-trial and restarted gives the same
results, and data/ is never written.
"""
import contextlib
import copy
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
import yaml

import browser
from lab_project import make_project
from stringcast_lab.campaign import run_campaign, tracking_error_mm, tracking_errors
from stringcast.core.files import DataError
from stringcast.video import open_video

ROOT = Path(__file__).resolve().parents[2]


def snakemake(root: Path, *args: str) -> str:
    proc = subprocess.run([sys.executable, "-m", "snakemake", *args, "--cores", "2", "--directory", str(root)],
                          cwd=root, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout + proc.stderr


def snapshot(folder: Path) -> dict:
    """Every file under ``folder``: (size, mtime, SHA-256)."""
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns, hashlib.sha256(p.read_bytes()).hexdigest())
            for p in sorted(folder.rglob("*")) if p.is_file()}


def planned_rules(dry_run_output: str) -> set[str]:
    """The rules a dry run would run (the target rule ``all`` left out)."""
    return set(re.findall(r"^rule (\w+):", dry_run_output, flags=re.M)) - {"all"}


def test_tracking_error_against_truth(tmp_path):
    """Only valid tracked points 1..n count (the grasp, point 0, is forward kinematics), matched by
    frame and point: errors 3, 4 and 0 mm, 3 of the 4 tracked points valid."""
    tracks = pd.DataFrame({"frame": [0, 0, 0, 1, 1], "point": [0, 1, 2, 1, 2], "x_m": [0.9, 0.003, 0.5, 0.0, 0.1],
                           "y_m": [0.0, 0.0, 0.5, 0.004, 0.2], "valid": [True, True, False, True, True]})
    truth = pd.DataFrame({"frame": [0, 0, 0, 1, 1], "point": [0, 1, 2, 1, 2], "x_m": [0.0, 0.0, 0.0, 0.0, 0.1],
                          "y_m": [0.0, 0.0, 0.0, 0.0, 0.2]})
    e, share = tracking_errors(tracks, truth)
    np.testing.assert_allclose(e, [3.0, 4.0, 0.0], atol=1e-9)
    assert share == pytest.approx(0.75)
    tracks.to_parquet(tmp_path / "tracks.parquet")
    truth.to_parquet(tmp_path / "truth.parquet")
    med, p95 = tracking_error_mm(tmp_path / "tracks.parquet", tmp_path / "truth.parquet")
    assert med == pytest.approx(3.0) and p95 == pytest.approx(np.percentile([3.0, 4.0, 0.0], 95))
    truth.drop(columns="y_m").to_parquet(tmp_path / "bad.parquet")
    with pytest.raises(DataError, match=r"bad\.parquet.*y_m"):
        tracking_error_mm(tmp_path / "tracks.parquet", tmp_path / "bad.parquet")


@pytest.fixture(scope="module")
def finished(tmp_path_factory, config):
    """A campaign run to its end (at most 2 executions) in a tmp project: (root, summary)."""
    root = make_project(tmp_path_factory.mktemp("e2e") / "project", config)
    summary = run_campaign("e2e", "1", "1", config_path=str(root / "config" / "config.yaml"),
                           max_executions=2, cores=2, seed=3, root=root)
    return root, summary


@pytest.mark.slow
def test_campaign_end_to_end(tmp_path, finished):
    root, summary = finished
    k = summary["executions"]
    assert 1 <= k <= 2
    res = root / "results" / "e2e"
    for name in ("calibration.json", "sync.json", "geometry.json", "clock.json", "tracks.parquet", "params.json",
                 "fit.parquet", "motion.csv", "motion.json", "report.html"):
        assert (res / "trial_1" / name).stat().st_size > 0, name
    # the video decoded once, kept (keep_frames): exactly the video's frames
    frames = np.load(res / "trial_1" / "frames.npy", mmap_mode="r")
    with open_video(root / "data" / "e2e" / "trial_1" / "video.mkv") as video:
        assert frames.shape == (video.n_frames, video.height, video.width)
        assert np.array_equal(frames[video.n_frames // 2], video.read(video.n_frames // 2))
    tracks = pd.read_parquet(res / "trial_1" / "tracks.parquet")
    assert list(tracks.columns) == ["frame", "t_s", "point", "x_m", "y_m", "valid"]
    assert tracks["valid"].mean() > 0.5
    params = json.loads((res / "trial_1" / "params.json").read_text())
    assert params["E_mm"] is not None and params["E_mm"] > 0
    html = (res / "report.html").read_text()
    assert "trial_1/report.html" in html and "<table" in html
    # each execution's fit verdict, with its cause where not ok, in the campaign's table
    v = params["verdict"]
    assert f'class="l verdict-fit"><span class="badge {v["status"]}"' in html
    assert (f"(likely cause: {v['likely_cause']})" in html) == (v["status"] != "ok")
    trial_html = (res / "trial_1" / "report.html").read_text()
    assert 'id="fig-valid"' in trial_html and "ground truth" not in trial_html.lower()
    # the lab's truth is the driver's (the experimenter's), not the workflow's: summary, not report
    row = summary["trials"][0]
    assert 0 < row["tracking_error_median_mm"] < row["tracking_error_p95_mm"] < 30
    # the pages as a person sees them: every figure decodes in Chromium, and the page is drawn
    if browser.chromium():
        for page in (res / "trial_1" / "report.html", res / "report.html"):
            loaded, n_img = browser.figures_loaded(page, tmp_path)
            assert n_img == page.read_text().count("<img") and loaded == n_img, (page, loaded, n_img)
        assert n_img >= 1 and browser.figures_loaded(res / "trial_1" / "report.html", tmp_path)[1] >= 8
        shot = cv2.imread(str(browser.screenshot(res / "trial_1" / "report.html", tmp_path / "trial.png")))
        assert shot is not None and shot.shape[1] == 1280 and len(np.unique(shot.reshape(-1, 3), axis=0)) > 50
    elif os.environ.get("CI"):
        pytest.fail("CI must have headless Chromium (make browser) to check the reports")
    # the raw data are untouched by the workflow: only the lab/executor wrote there
    assert not list((root / "data" / "e2e").rglob("*.parquet.*"))

    # Snakemake's own report gathers the trial pages and overlays with their captions
    snakemake(root, "--report", str(tmp_path / "snakemake_report.html"))
    assert (tmp_path / "snakemake_report.html").stat().st_size > 10_000

    # a finished campaign: nothing to do
    t_done = time.time()
    out = snakemake(root, "-n")
    assert "Nothing to be done" in out or not planned_rules(out), out
    # deleting the last trial's tracks (it has the fewest outputs downstream) reruns what depends on
    # them, not calibration or sync
    before_data = snapshot(root / "data")
    last = res / f"trial_{k}"
    tracks, params = pd.read_parquet(last / "tracks.parquet"), json.loads((last / "params.json").read_text())
    (last / "tracks.parquet").unlink()
    rules = planned_rules(snakemake(root, "-n"))
    assert {"track", "estimate", "plan", "report_trial", "report_campaign"} <= rules
    assert not rules & {"calibrate", "sync", "sweep", "plan_first"}

    # a run killed hard in the middle of tracking, then started again, ends with the same results
    proc = subprocess.Popen([sys.executable, "-m", "snakemake", "--cores", "2", "--directory", str(root)],
                            cwd=root, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    log = res / "logs" / f"track_{k}.log"

    def tracking_started():    # Snakemake removes a job's old log as the job starts: it may go between looks
        try:
            return log.stat().st_mtime > t_done
        except FileNotFoundError:
            return False

    deadline = time.monotonic() + 120
    while not tracking_started() and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(1.0)
    os.killpg(proc.pid, signal.SIGKILL)   # snakemake and its job, as a power cut would
    proc.wait()
    assert not (last / "tracks.parquet").exists()   # nothing half-written under the real name
    snakemake(root, "--unlock")
    snakemake(root, "--rerun-incomplete")
    pd.testing.assert_frame_equal(pd.read_parquet(last / "tracks.parquet"), tracks)
    again = json.loads((last / "params.json").read_text())
    assert again["E_mm"] == pytest.approx(params["E_mm"], rel=1e-9)
    # raw data under data/ were never written by the workflow
    assert snapshot(root / "data") == before_data


@pytest.mark.slow
def test_next_writes_what_the_workflow_writes(tmp_path, finished):
    """``stringcast next data/<c>/trial_1`` in another project holding the same raw files writes the
    workflow's files (the same names, logs included) with the same content, in one process."""
    from stringcast.cli import main

    root, _ = finished
    other = make_project(tmp_path / "project", yaml.safe_load((root / "config" / "config.yaml").read_text()))
    src, dst = root / "data" / "e2e", other / "data" / "e2e"
    dst.mkdir(parents=True)
    for name in ("campaign.yaml", "calib", "trial_1"):
        (shutil.copytree if (src / name).is_dir() else shutil.copyfile)(src / name, dst / name)
    assert main(["next", str(dst / "trial_1")]) == 0
    res, res2 = root / "results" / "e2e", other / "results" / "e2e"
    names = {p.name for p in (res / "trial_1").iterdir()}
    assert names == {p.name for p in (res2 / "trial_1").iterdir()} and "motion.csv" in names
    logs = {p.name for p in (res2 / "logs").iterdir()}
    assert logs <= {p.name for p in (res / "logs").iterdir()} and {"track_1.log", "plan_1.log"} <= logs
    assert (res2 / "report.html").is_file() and "trial_1/report.html" in (res2 / "report.html").read_text()
    pd.testing.assert_frame_equal(pd.read_parquet(res2 / "trial_1" / "tracks.parquet"),
                                  pd.read_parquet(res / "trial_1" / "tracks.parquet"))
    for name, key in (("geometry.json", "H_pixel_to_robot"), ("clock.json", "offset_s"), ("params.json", "E_mm"),
                      ("params.json", "chi")):
        a, b = (json.loads((r / "trial_1" / name).read_text()) for r in (res, res2))
        np.testing.assert_allclose(np.asarray(b[key], float), np.asarray(a[key], float), rtol=1e-9, err_msg=name)
    assert (res2 / "trial_1" / "motion.csv").read_text() == (res / "trial_1" / "motion.csv").read_text()


def _edit_config(root: Path, section: str, key: str, value) -> dict:
    """Set ``section.key`` in the project's config/config.yaml; returns the file's old content."""
    path = root / "config" / "config.yaml"
    old = yaml.safe_load(path.read_text())
    new = copy.deepcopy(old)
    new.setdefault(section, {})[key] = value
    path.write_text(yaml.safe_dump(new))
    return old


@pytest.mark.slow
@pytest.mark.parametrize("section, key, value, reruns, spared", [
    ("evaluation", "w", 0.5, {"estimate", "plan", "report_trial", "report_campaign"},
     {"calibrate", "sync", "sweep", "track", "plan_first"}),
    ("tracking", "rest_frames", 30, {"track", "estimate", "plan", "report_trial", "report_campaign"},
     {"calibrate", "sync", "sweep", "plan_first"}),
    ("sweep", "tolerance_mm", 2.0, {"sweep", "track", "estimate", "plan", "report_trial", "report_campaign"},
     {"calibrate", "sync", "plan_first"}),
])
def test_a_changed_setting_reruns_exactly_what_reads_it(finished, section, key, value, reruns, spared):
    """Snakemake compares the settings each stage reads (its rule's params): a changed setting
    reruns the stages that read it and what follows them, and nothing upstream."""
    root, _ = finished
    assert "Nothing to be done" in snakemake(root, "-n")
    if (root / "data" / "e2e" / "trial_2").exists():   # trial 1's estimate predicting trial 2 follows it
        reruns = reruns | {"predict"}
    old = _edit_config(root, section, key, value)
    try:
        out = snakemake(root, "-n")
        assert planned_rules(out) == reruns, out
        assert not planned_rules(out) & spared
        assert "params" in out.lower()   # the reason Snakemake gives is the changed params
    finally:
        (root / "config" / "config.yaml").write_text(yaml.safe_dump(old))
    assert "Nothing to be done" in snakemake(root, "-n")


@pytest.mark.slow
def test_a_setting_on_the_command_line_reruns_exactly_what_reads_it(finished):
    """``snakemake --config 'evaluation={w: 0.5}'`` plans estimate, plan and the reports (the params
    changed), nothing upstream, and its jobs would read w = 0.5 (the run's config file); an unknown
    setting is refused by the schema before any job."""
    root, _ = finished
    reruns = {"estimate", "plan", "report_trial", "report_campaign"}
    if (root / "data" / "e2e" / "trial_2").exists():
        reruns |= {"predict"}
    out = snakemake(root, "-n", "--config", "evaluation={w: 0.5}")
    assert planned_rules(out) == reruns, out
    written = [yaml.safe_load(p.read_text()) for p in (root / "results" / ".stringcast").glob("config-*.yaml")]
    w = [(c.get("evaluation") or {}).get("w") for c in written]    # None: the default
    assert 0.5 in w and None in w
    bad = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--cores", "1", "--directory", str(root),
                          "--config", "evaluation={ww: 0.5}"], cwd=root, capture_output=True, text=True)
    assert bad.returncode != 0 and "ww" in bad.stdout + bad.stderr
    assert "Nothing to be done" in snakemake(root, "-n")


@pytest.mark.slow
def test_a_new_target_reruns_only_planning_and_the_reports(finished):
    """The target reaches only the stages that read it (stringcast.core.stages.TARGET_COMMANDS): a new
    target in campaign.yaml plans the motions, the prediction check and the reports again, and
    leaves calibration, sync, tracking and the estimate as they are."""
    root, _ = finished
    path = root / "data" / "e2e" / "campaign.yaml"
    old = path.read_text()
    doc = yaml.safe_load(old)
    assert str(doc["target"]) == "1"
    try:
        path.write_text(yaml.safe_dump({**doc, "target": 2}))
        out = snakemake(root, "-n")
        reruns = {"plan_first", "plan", "report_trial", "report_campaign"}
        if (root / "data" / "e2e" / "trial_2").exists():
            reruns |= {"predict"}
        assert planned_rules(out) == reruns, out
    finally:
        path.write_text(old)
    out = snakemake(root, "-n")
    # the old file back, newer than the target's readers' outputs: they rerun, and nothing else
    assert planned_rules(out) <= reruns, out


@pytest.mark.slow
def test_a_configfile_that_changes_nothing_a_stage_reads_reruns_nothing(finished):
    """A --configfile that restates a default and changes only the virtual lab (which no stage
    reads) leaves every result as it is; one that changes a setting reruns."""
    root, _ = finished
    noop = root / "config" / "noop.yaml"
    noop.write_text(yaml.safe_dump({"evaluation": {"w": 1.0}, "estimation": {"optimizer": "cmaes"},   # ours' defaults
                                    "lab": {"scene_seed": 12}}))
    out = snakemake(root, "-n", "--configfile", str(noop))
    assert "Nothing to be done" in out or not planned_rules(out), out
    some = root / "config" / "some.yaml"
    some.write_text(yaml.safe_dump({"motion": {"flight_window_s": 0.6}}))
    rules = planned_rules(snakemake(root, "-n", "--configfile", str(some)))
    assert {"plan", "plan_first"} <= rules and not rules & {"calibrate", "sync", "track"}


@pytest.mark.slow
def test_a_broken_campaign_is_refused_and_the_others_run(finished):
    """A campaign.yaml typo in one campaign: a run of every campaign builds the others, lists the broken
    one and ends non-zero; a target of another campaign runs; a target of the broken one names its problem."""
    root, _ = finished
    snakemake(root)                                        # the built campaign up to date
    (root / "results" / "e2e" / "report.html").unlink()   # ... but for its page, which the next run makes
    broken = root / "data" / "broken"
    broken.mkdir()
    (broken / "campaign.yaml").write_text("string: 1\ntarget: [1\n")
    try:
        done = snapshot(root / "results" / "e2e")
        proc = subprocess.run([sys.executable, "-m", "snakemake", "--cores", "2", "--directory", str(root)], cwd=root,
                              capture_output=True, text=True, timeout=600)
        out = proc.stdout + proc.stderr
        assert proc.returncode != 0, out
        assert "data/broken was not built" in out and "data/broken/campaign.yaml" in out, out
        assert "Traceback" not in out
        after = snapshot(root / "results" / "e2e")
        assert (root / "results" / "e2e" / "report.html").exists()          # the other campaign was built
        kept = {k: v for k, v in done.items() if k.split("/")[0] not in ("logs", "benchmarks")}
        assert {k: v for k, v in after.items() if k in kept} == kept        # and nothing else of it remade
        assert not (root / "results" / "broken").exists()
        snakemake(root, "results/e2e/report.html")
        proc = subprocess.run([sys.executable, "-m", "snakemake", "--cores", "1", "--directory", str(root),
                               "results/broken/first_motion/motion.csv"], cwd=root, capture_output=True, text=True)
        out = proc.stdout + proc.stderr
        assert proc.returncode != 0 and "data/broken/campaign.yaml" in out and "none of its jobs is built" in out, out
    finally:
        (broken / "campaign.yaml").unlink()
        broken.rmdir()


def _job_processes(root: Path, log_name: str) -> list[int]:
    """Pids of the processes running the workflow job that logs to ``log_name`` in project ``root``."""
    pids = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            cmd = (proc / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            cwd = os.readlink(proc / "cwd")
        except OSError:
            continue
        if log_name in cmd and "stringcast" in cmd and cwd == str(root):
            pids.append(int(proc.name))
    return pids


def _signal(sig: int, pids) -> None:
    """Send ``sig`` to each of ``pids`` that still exists."""
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, sig)


def _wait_for(pred, timeout_s: float = 180.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.05)
    return False


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_killing_the_workflow_ends_its_jobs(finished):
    """kill -9 of Snakemake alone (not its process group): the running job and its workers end within
    seconds, leave nothing that looks finished, and the next run makes the same estimate."""
    root, _ = finished
    res = root / "results" / "e2e" / "trial_1"
    before = json.loads((res / "params.json").read_text())
    (res / "params.json").unlink()
    proc = subprocess.Popen([sys.executable, "-m", "snakemake", "--cores", "2", "--directory", str(root),
                             str(res.relative_to(root) / "params.json")],
                            cwd=root, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    jobs = []
    try:
        assert _wait_for(lambda: _job_processes(root, "estimate_1.log")), "the estimate job did not start"
        # the job held still (SIGSTOP) from its start until Snakemake is gone: a small trial's estimate could
        # otherwise finish before the kill on a fast machine, and the test would see no orphan to end
        jobs = _job_processes(root, "estimate_1.log")
        _signal(signal.SIGSTOP, jobs)
    finally:
        proc.kill()
        proc.wait()
        _signal(signal.SIGCONT, jobs)
    assert _wait_for(lambda: not _job_processes(root, "estimate_1.log"), 20), "the job outlived its workflow"
    assert not (res / "params.json").exists() and not list(res.glob(".params.json*"))
    assert all(not Path(f"/proc/{pid}").exists() or "Z" in Path(f"/proc/{pid}/stat").read_text().split()[2]
               for pid in jobs)
    snakemake(root, "--unlock")
    snakemake(root, str(res.relative_to(root) / "params.json"))
    assert json.loads((res / "params.json").read_text())["E_mm"] == pytest.approx(before["E_mm"], rel=1e-9)


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_two_runs_on_one_results_folder_lose_no_finished_output(finished):
    """A second run that Snakemake's own lock lets in (here by --nolock, as when another run ended and
    removed the locks) while the first remakes a trial's tracking is refused before any job, and every
    finished output survives byte for byte; the first run's remade files are as before."""
    root, _ = finished
    res = root / "results" / "e2e"
    target = str((res / "trial_1" / "params.json").relative_to(root))
    snakemake(root, target)
    finished_before = snapshot(res)
    tracks = finished_before["trial_1/tracks.parquet"][2]
    (res / "trial_1" / "tracks.parquet").unlink()
    # tracks.parquet asked for too: Snakemake remakes a missing file only where a requested output needs it
    first = subprocess.Popen([sys.executable, "-m", "snakemake", "--cores", "1", "--directory", str(root), target,
                              target.replace("params.json", "tracks.parquet")],
                             cwd=root, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        started = _wait_for(lambda: _job_processes(root, "track_1.log") or first.poll() is not None)
        assert started and first.poll() is None, first.communicate()[0] if first.poll() is not None else "no tracking"
        # the first run held still (SIGSTOP) while the second plans: on a loaded machine the small trial's
        # tracking could otherwise finish before the second run has built its DAG, leaving it nothing to do
        frozen = [first.pid, *_job_processes(root, "track_1.log")]
        _signal(signal.SIGSTOP, frozen)
        try:
            during = snapshot(res)
            second = subprocess.run([sys.executable, "-m", "snakemake", "--cores", "1", "--nolock", "--directory",
                                     str(root), target, target.replace("params.json", "tracks.parquet")], cwd=root,
                                    capture_output=True, text=True, timeout=300)
        finally:
            _signal(signal.SIGCONT, frozen)
        out = second.stdout + second.stderr
        assert second.returncode != 0 and "results/e2e/trial_1 is being made by another snakemake run" in out, out
        after_second = snapshot(res)
        # the second run touched nothing: every file there before it is there, the same bytes
        assert {k: v for k, v in after_second.items() if k in during and "logs/" not in k} == \
            {k: v for k, v in during.items() if "logs/" not in k}
    finally:
        first_out = first.communicate(timeout=600)[0]
    assert first.returncode == 0, first_out
    end = snapshot(res)
    assert end["trial_1/tracks.parquet"][2] == tracks
    # every output finished before both runs is there, the same bytes (the ones remade: the same content)
    for name, (_, _, digest) in finished_before.items():
        if name.startswith(("trial_1/", "logs/", "benchmarks/")) and name != "trial_1/tracks.parquet":
            continue
        assert end[name][2] == digest, name
