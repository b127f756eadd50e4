"""The workflow through a real Slurm: config/profiles/slurm gives the same results as a local run.

A small campaign's raw data (one trial, made by the virtual lab) are processed twice: locally
on 2 cores (the lab's driver, ``run_campaign``), and, in a copy of the same data, through
``--profile config/profiles/slurm`` on a real cluster (in CI the one-node cluster of
``make slurm``, .ci/slurm/setup.sh; docs/slurm.md). Every stage's outputs must be equal, and
every stage must have been a Slurm job that accounting (``sacct``) knows.

The profile run is the real one with a few numbers fitted to the node, named in
:func:`fitted_profile`. Without Slurm (no ``sinfo`` on PATH) the test is skipped, except
under CI (``$CI`` set), where it fails: CI must never skip it silently.
"""
import copy
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

from lab_project import ROOT, make_project
from stringcast_lab.campaign import run_campaign

REAL_PROFILE = ROOT / "config" / "profiles" / "slurm" / "config.yaml"
# the account and partition jobs are submitted to: make slurm's, unless set for another cluster
ACCOUNT = os.environ.get("STRINGCAST_SLURM_ACCOUNT", "stringcast")
PARTITION = os.environ.get("STRINGCAST_SLURM_PARTITION")   # None: the cluster's default partition
CORES = 2               # the local run's --cores (run_campaign's default)
QUICK_POLL = Path(__file__).with_name("snakemake_quick_poll.py")   # python -m snakemake, polling sacct every 3 s
TIMEOUT_S = 900         # the Slurm run, at most (a job that can never start would hang it)
# every rule of the workflow: the campaign's first motion, one trial's stages, the campaign report
RULES = {"plan_first", "decode", "calib_views", "calibrate", "sync", "sweep", "track", "estimate", "plan", "report_trial",
         "report_campaign"}
# What legitimately differs between two runs of the same data, by file; nothing else may.
#   params.json "seconds": the estimation's wall time.
#   frames.json "source": the decoded video's real path and modification time (each run has its
#   own copy of data/); frames.npy, the frames themselves, compares whole.
#   report.html (the trial's): its "estimation time" row (that same wall time).
#   report.html (the campaign's): its "Time per stage" table (from the benchmark files).
#   report.html (both): the "written <date and time>" note at the page's foot.
#   benchmarks/*.tsv: Snakemake's timings and memory of each job (only their columns compare).
#   campaign_summary.json: the lab driver's summary (with its timings), written only by the
#   local run (run_campaign), not by the workflow.
#   .stringcast/config-<hash>.yaml: each run's merged config for its jobs (the two runs name their
#   config files differently); the results compare, not the runs' bookkeeping.
# No other stage writes a host, a path of the run or a time of day into its JSON or YAML.
# The pages' provenance (git commit, library versions) compares whole: both runs run the same code.
RUN_DEPENDENT_FIELDS = {"params.json": {"seconds"}, "frames.json": {"source"}}   # top-level keys, by file name
HTML_RUN_DEPENDENT = [
    re.compile(r"(written )\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(\.\d+)?"),
    re.compile(r"(<td[^>]*>estimation time</td>\s*<td>)[^<]*"),
    re.compile(r"(<h2>Time per stage</h2>).*?</table>", re.S),
]
LOCAL_ONLY = {"campaign_summary.json"}


def require_slurm() -> None:
    """Skip without Slurm (no ``sinfo`` on PATH), but fail under CI, which must run this test."""
    if shutil.which("sinfo") is None:
        why = "no Slurm here: sinfo is not on PATH (make slurm, as root, starts a one-node cluster; docs/slurm.md)"
        if os.environ.get("CI"):
            pytest.fail(f"CI must run the Slurm test, but {why}")
        pytest.skip(why)


def slurm(*args: str) -> str:
    """The output of a Slurm command; fails the test, naming the command, if it fails."""
    proc = subprocess.run(list(args), capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, f"{' '.join(args)} failed (exit {proc.returncode}): {proc.stderr.strip()}"
    return proc.stdout


def cluster_node() -> tuple[str, int, int]:
    """(partition, CPUs, memory in MB) of the partition's node, which must be up."""
    rows = [line.split() for line in slurm("sinfo", "-h", "-N", "-o", "%P %T %c %m").splitlines()]
    if PARTITION:
        rows = [r for r in rows if r[0].rstrip("*") == PARTITION]
    else:
        rows = [r for r in rows if r[0].endswith("*")]   # the default partition
    assert rows, f"no node in partition {PARTITION or '(the default)'}: sinfo shows {slurm('sinfo')}"
    up = [r for r in rows if r[1].rstrip("*~#") in ("idle", "mixed", "allocated", "completing")]
    assert up, f"no node is up (run make slurm; docs/slurm.md): sinfo shows\n{slurm('sinfo')}"
    part, _, cpus, mem = up[0]
    return part.rstrip("*"), int(cpus.rstrip("+")), int(mem.rstrip("+"))


def fitted_profile(real: dict, account: str, partition: str, cpus: int, mem_mb: int) -> dict:
    """config/profiles/slurm fitted to a small node; everything not named here is the real one's.

    * ``default-resources``: the account and partition to submit to (the real profile leaves
      them to the user).
    * ``set-threads`` and ``cpus_per_task``: at most ``cpus`` (the real profile asks 8 for
      estimate and plan; the one-node CI cluster has 2). The local run caps threads at its
      --cores in the same way.
    * ``mem_mb``: at most the node's memory (it has more than the profile asks in CI).
    * ``slurm-init-seconds-before-status-checks``: the first ``sacct`` poll after 2 s, not the
      plugin's 40 s, as each of these jobs takes seconds (and :mod:`snakemake_quick_poll`, which
      runs the profile, keeps the later polls 3 s apart).
    """
    prof = copy.deepcopy(real)
    prof["default-resources"] = {**prof.get("default-resources", {}), "slurm_account": account,
                                 "slurm_partition": partition}
    for res in [prof["default-resources"], *prof.get("set-resources", {}).values()]:
        if "cpus_per_task" in res:
            res["cpus_per_task"] = min(res["cpus_per_task"], cpus)
        if "mem_mb" in res:
            res["mem_mb"] = min(res["mem_mb"], mem_mb)
    prof["set-threads"] = {rule: min(n, cpus) for rule, n in prof.get("set-threads", {}).items()}
    prof["slurm-init-seconds-before-status-checks"] = 2
    return prof


def run_through_slurm(root: Path, profile: Path) -> str:
    """Run the whole workflow in ``root`` with ``profile``; returns Snakemake's output. On failure
    or timeout the output's tail and the queue are in the message (and the run's jobs cancelled)."""
    proc = subprocess.Popen([sys.executable, str(QUICK_POLL), "--profile", str(profile), "--directory", str(root)],
                            cwd=root, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    try:
        out, _ = proc.communicate(timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
        ids = re.findall(r"submitted with SLURM jobid (\d+)", out)
        queue = subprocess.run(["squeue", "-o", "%i %j %T %r"], capture_output=True, text=True).stdout
        if ids:
            subprocess.run(["scancel", *ids], capture_output=True)
        pytest.fail(f"the Slurm run took more than {TIMEOUT_S} s; squeue:\n{queue}\n{out[-4000:]}")
    assert proc.returncode == 0, f"the Slurm run failed (exit {proc.returncode}):\n{out[-6000:]}"
    return out


def submitted_jobs(out: str) -> dict[str, str]:
    """{Slurm job id: rule} from the executor plugin's "submitted with SLURM jobid" lines."""
    return {jid: rule for jid, rule in
            re.findall(r"has been submitted with SLURM jobid (\d+) \(log: \S*/slurm_logs/rule_(\w+)/", out)}


def _masked_html(text: str) -> str:
    """A report page with its run-dependent parts (HTML_RUN_DEPENDENT) replaced by "(run)"."""
    for pattern in HTML_RUN_DEPENDENT:
        text = pattern.sub(r"\1(run)", text)
    return text


def _first_difference(a, b, path: str = "") -> str:
    """Where two loaded JSON/YAML documents first differ, as a key path and the two values."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b), key=str):
            if k not in a or k not in b:
                return f"{path}.{k} only in one"
            if a[k] != b[k]:
                return _first_difference(a[k], b[k], f"{path}.{k}")
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (u, v) in enumerate(zip(a, b)):
            if u != v:
                return _first_difference(u, v, f"{path}[{i}]")
    return f"{path or '(top)'}: {str(a)[:80]} != {str(b)[:80]}"


def _text_difference(a: str, b: str) -> str:
    """Where two texts first differ, with some context from each."""
    i = next((k for k, (u, v) in enumerate(zip(a, b)) if u != v), min(len(a), len(b)))
    return f"at character {i}: {a[max(0, i - 60):i + 60]!r} != {b[max(0, i - 60):i + 60]!r}"


def compare_results(a: Path, b: Path) -> list[str]:
    """The differences between two results/ folders of the same data (empty: equal), by file;
    the run-dependent parts named at the top of this module are left out."""
    def kept(p: Path, root: Path) -> bool:
        return p.is_file() and p.name not in LOCAL_ONLY and p.relative_to(root).parts[0] != ".stringcast"

    files_a = {p.relative_to(a) for p in a.rglob("*") if kept(p, a)}
    files_b = {p.relative_to(b) for p in b.rglob("*") if kept(p, b)}
    diffs = [f"{f}: only in {a}" for f in sorted(files_a - files_b)]
    diffs += [f"{f}: only in {b}" for f in sorted(files_b - files_a)]
    for f in sorted(files_a & files_b):
        pa, pb = a / f, b / f
        try:
            if f.suffix == ".parquet":
                pd.testing.assert_frame_equal(pd.read_parquet(pa), pd.read_parquet(pb), check_exact=True)
            elif f.suffix == ".csv":
                pd.testing.assert_frame_equal(pd.read_csv(pa), pd.read_csv(pb), check_exact=True)
            elif f.suffix in (".json", ".yaml"):
                load = json.loads if f.suffix == ".json" else yaml.safe_load
                skip = RUN_DEPENDENT_FIELDS.get(f.name, set())
                da, db = (load(p.read_text()) for p in (pa, pb))
                if isinstance(da, dict) and isinstance(db, dict):
                    da, db = ({k: v for k, v in d.items() if k not in skip} for d in (da, db))
                assert da == db, _first_difference(da, db)
            elif f.suffix == ".html":
                ta, tb = (_masked_html(p.read_text()) for p in (pa, pb))
                assert ta == tb, _text_difference(ta, tb)
            elif f.suffix == ".npy":
                assert np.array_equal(np.load(pa, mmap_mode="r"), np.load(pb, mmap_mode="r")), "arrays differ"
            elif f.suffix == ".npz":
                with np.load(pa) as za, np.load(pb) as zb:
                    assert sorted(za.files) == sorted(zb.files), f"arrays {sorted(za.files)} / {sorted(zb.files)}"
                    bad = [k for k in za.files if not np.array_equal(za[k], zb[k])]
                    assert not bad, f"arrays differ: {bad}"
            elif f.suffix == ".png":
                ia, ib = (cv2.imread(str(p), cv2.IMREAD_UNCHANGED) for p in (pa, pb))
                assert ia is not None and ib is not None and np.array_equal(ia, ib), "pixels differ"
            elif f.suffix == ".tsv" and f.parts[-2] == "benchmarks":
                ca, cb = (pd.read_csv(p, sep="\t").columns.tolist() for p in (pa, pb))
                assert ca == cb, f"columns differ: {ca} / {cb}"
            elif f.suffix == ".log":
                ta, tb = pa.read_text(), pb.read_text()
                assert ta == tb, _text_difference(ta, tb)
            else:
                diffs.append(f"{f}: no comparison for a {f.suffix or 'suffix-less'} file (add one here)")
        except AssertionError as exc:
            diffs.append(f"{f}: {str(exc).strip().splitlines()[0] if str(exc).strip() else 'differs'}")
    return diffs


@pytest.mark.slow
@pytest.mark.slurm
def test_slurm_profile_reprocesses_a_campaign_as_a_local_run_does(tmp_path, config):
    require_slurm()
    partition, cpus, mem_mb = cluster_node()
    # the raw data of one trial, and the local run of every rule on them (run_campaign: --cores 2)
    t0 = time.monotonic()
    local = make_project(tmp_path / "local", config)
    summary = run_campaign("sc", "1", "1", config_path=str(local / "config" / "config.yaml"), max_executions=1,
                           cores=CORES, seed=3, root=local)
    assert summary["executions"] == 1
    t_local = time.monotonic() - t0

    # a copy of the same raw data, processed through the Slurm profile
    remote = make_project(tmp_path / "slurm", config)
    shutil.copytree(local / "data", remote / "data")
    real = yaml.safe_load(REAL_PROFILE.read_text())
    assert real["executor"] == "slurm", REAL_PROFILE
    (tmp_path / "profile").mkdir()
    (tmp_path / "profile" / "config.yaml").write_text(
        yaml.safe_dump(fitted_profile(real, ACCOUNT, partition, cpus, mem_mb)))
    t0 = time.monotonic()
    out = run_through_slurm(remote, tmp_path / "profile")
    t_slurm = time.monotonic() - t0
    print(f"[slurm test] local run {t_local:.0f} s (with the lab), Slurm run {t_slurm:.0f} s")

    # every rule ran as a Slurm job, and accounting has each one, finished, with the profile's resources
    jobs = submitted_jobs(out)
    assert sorted(jobs.values()) == sorted(RULES), out[-4000:]
    rows = slurm("sacct", "-X", "-P", "-n", "-j", ",".join(jobs),
                 "--format=JobIDRaw,State,Account,Partition,AllocCPUS,ReqMem,Timelimit").splitlines()
    acct = {r.split("|")[0]: r.split("|")[1:] for r in rows}
    assert set(acct) == set(jobs), (jobs, rows)
    for jid, (state, account, part, alloc, req_mem, limit) in acct.items():
        rule = jobs[jid]
        assert state == "COMPLETED" and account == ACCOUNT and part == partition, (rule, acct[jid])
        res = {**real["default-resources"], **real["set-resources"].get(rule, {})}
        assert int(alloc) == min(res["cpus_per_task"], cpus), (rule, acct[jid])
        assert req_mem == f"{min(res['mem_mb'], mem_mb)}M", (rule, acct[jid])
        assert limit == time.strftime("%H:%M:%S", time.gmtime(60 * res["runtime"])), (rule, acct[jid])

    # the same results, file by file
    diffs = compare_results(local / "results", remote / "results")
    assert not diffs, "the Slurm run's results differ from the local run's:\n" + "\n".join(diffs)


def test_compare_results_finds_what_differs(tmp_path):
    """The comparison the Slurm test relies on can fail: a changed number in a table, a changed
    field, a changed page or a missing file are differences; the named run-dependent parts are not."""
    page = ('<tr><td class="l">estimation time</td><td>{t} s</td></tr>\n<h2>Time per stage</h2>\n'
            '<table><tr><td>{t}</td></tr>\n</table>\n<p>{v} &middot; written 2026-01-0{d}T10:00:0{d}</p>')
    a, b = tmp_path / "a", tmp_path / "b"
    for root, d in ((a, 1), (b, 2)):
        (root / "trial_1").mkdir(parents=True)
        (root / "benchmarks").mkdir()
        pd.DataFrame({"x": [1.0, 2.0]}).to_parquet(root / "trial_1" / "tracks.parquet")
        (root / "trial_1" / "motion.csv").write_text("t_s,q1\n0,0.5\n")
        (root / "trial_1" / "params.json").write_text(json.dumps({"E_mm": 1.5, "params": {"k": 2}, "seconds": d}))
        (root / "report.html").write_text(page.format(t=1.5 * d, v="stringcast 0.1", d=d))
        (root / "benchmarks" / "track_1.tsv").write_text(f"s\tmax_rss\n{4.9 * d}\t390\n")
        (root / "trial_1" / "overlay.svg").write_text("<svg/>")
        np.savez(root / "calib_views.npz", image_points_0=np.ones((4, 2), np.float32))
    (a / "campaign_summary.json").write_text("{}")
    assert compare_results(a, b) == ["trial_1/overlay.svg: no comparison for a .svg file (add one here)"]

    pd.DataFrame({"x": [1.0, 2.0 + 1e-12]}).to_parquet(b / "trial_1" / "tracks.parquet")
    (b / "trial_1" / "params.json").write_text(json.dumps({"E_mm": 1.5, "params": {"k": 3}, "seconds": 2}))
    (b / "trial_1" / "motion.csv").write_text("t_s,q1\n0,0.6\n")
    (b / "report.html").write_text(page.format(t=3.0, v="stringcast 0.2", d=2))
    (b / "trial_1" / "tracking.json").write_text("{}")
    np.savez(b / "calib_views.npz", image_points_0=np.full((4, 2), 1.5, np.float32))
    diffs = compare_results(a, b)
    assert {d.split(":")[0] for d in diffs} == {"calib_views.npz", "trial_1/tracks.parquet", "trial_1/params.json", "trial_1/motion.csv",
                                                "report.html", "trial_1/tracking.json", "trial_1/overlay.svg"}
    assert "trial_1/params.json: .params.k: 2 != 3" in diffs and "stringcast 0.2" in " ".join(diffs)


def test_require_slurm_fails_under_ci_and_skips_otherwise(monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="CI must run the Slurm test"):
        require_slurm()
    monkeypatch.delenv("CI")
    with pytest.raises(pytest.skip.Exception, match="sinfo is not on PATH"):
        require_slurm()


def test_fitted_profile_changes_only_the_named_numbers():
    real = yaml.safe_load(REAL_PROFILE.read_text())
    fitted = fitted_profile(real, "acc", "part", cpus=2, mem_mb=3000)
    assert fitted["set-resources"]["estimate"] == {**real["set-resources"]["estimate"], "cpus_per_task": 2,
                                                   "mem_mb": 3000}
    assert fitted["set-threads"] == {rule: 2 for rule in real["set-threads"]}
    assert fitted["default-resources"]["slurm_account"] == "acc"
    # what is not fitted is the real profile's, and the real one is untouched
    assert {k: v for k, v in fitted.items() if k not in ("set-resources", "set-threads", "default-resources",
                                                         "slurm-init-seconds-before-status-checks")} == \
        {k: v for k, v in real.items() if k not in ("set-resources", "set-threads", "default-resources")}
    assert real == yaml.safe_load(REAL_PROFILE.read_text())
    # a big node: the real numbers
    big = fitted_profile(real, "acc", "part", cpus=64, mem_mb=10**6)
    assert big["set-resources"] == real["set-resources"] and big["set-threads"] == real["set-threads"]
