"""The ``stringcast`` command line: one subcommand per stage (the Snakemake rules
call these) plus ``execute`` (play a motion file on an arm) and ``campaign`` (the
whole loop on the virtual lab).

Errors in the input (:class:`~stringcast.core.files.DataError`,
:class:`~stringcast.core.config.ConfigError`, :class:`~stringcast.core.arm.JointLimitError`)
print one line naming the file and the problem and exit with status 2; any other exception prints
one line (``stringcast <cmd>: internal error: <type>: <message>``) and where its full traceback was
written, and exits with status 1.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from stringcast import warm


CONFIG_ENV = "STRINGCAST_CONFIG"
"""Environment variable with the config files a job reads (``os.pathsep``-separated), set by
the workflow for its jobs in place of ``--config`` (so no config path is part of a rule's
command line; Snakemake compares the settings a stage reads instead)."""


def config_paths(args) -> list[str] | None:
    """The config files to merge, in order: each ``--config``, else ``$STRINGCAST_CONFIG``, else
    None (the project's config/config.yaml)."""
    if args.config:
        return [str(c) for c in args.config]
    env = os.environ.get(CONFIG_ENV, "")
    return [p for p in env.split(os.pathsep) if p] or None


_CONFIG_CACHE: dict = {}


def _config(args):
    """The merged, validated config (read once per process)."""
    from stringcast.core import load_config

    paths = config_paths(args)
    key = str(paths)
    if key not in _CONFIG_CACHE:
        _CONFIG_CACHE[key] = load_config(paths)
    return _CONFIG_CACHE[key]


def _campaign(args):
    from stringcast.core import load_campaign

    return load_campaign(args.campaign, _config(args))


def _settings(func, args) -> dict:
    """The settings objects ``func`` takes (by its annotations), built once from the config."""
    from stringcast.core import settings_from_config, stage_kwargs

    key = ("settings", str(config_paths(args)))
    if key not in _CONFIG_CACHE:
        _CONFIG_CACHE[key] = settings_from_config(_config(args))
    return stage_kwargs(func, _CONFIG_CACHE[key])


STAGES = {
    "decode": "stringcast.video:write_frame_cache",
    "calib-views": "stringcast.calibrate:write_calib_views",
    "calibrate": "stringcast.calibrate:run_calibration",
    "sync": "stringcast.sync:run_sync",
    "sweep": "stringcast.sync:run_sweep",
    "track": "stringcast.track:run_tracking",
    "estimate": "stringcast.estimate:run_estimation",
    "predict": "stringcast.estimate:run_prediction",
    "plan-first": "stringcast.plan:run_first_plan",
    "plan": "stringcast.plan:run_plan",
    "report-trial": "stringcast.report:write_trial_report",
    "report-campaign": "stringcast.report:write_campaign_report",
}
"""Each workflow subcommand's stage entry point, ``module:function``."""


def stage_entry(command: str):
    """The stage function a subcommand runs (imported on demand: each loads only its stage)."""
    import importlib

    module, _, name = STAGES[command].partition(":")
    return getattr(importlib.import_module(module), name)


def stage_sections(command: str) -> tuple[str, ...]:
    """The config sections a workflow subcommand reads: those of its stage entry's settings
    parameters, read from the source without importing the stage
    (:func:`stringcast.core.sections_read_from_source`). The rules' params are these sections."""
    from stringcast.core import sections_read_from_source

    return sections_read_from_source(STAGES[command])


def _run(command: str, args, *positional, **keywords):
    """Run ``command``'s stage on ``positional`` (its own order), ``keywords`` and the settings it takes."""
    func = stage_entry(command)
    return func(*positional, **keywords, **_settings(func, args))


def cmd_calib_views(args):
    campaign = _campaign(args)
    views = _run("calib-views", args, Path(args.calib_dir), campaign, Path(args.out))
    print(f"calibration views: {len(views)} of the board's {views.found} in {args.calib_dir} -> {args.out}")
    if args.out_intrinsics:
        from stringcast.calibrate import write_campaign_intrinsics

        intr = write_campaign_intrinsics(Path(args.out), campaign, Path(args.out_intrinsics),
                                         **_settings(write_campaign_intrinsics, args))
        print(f"intrinsics of the views: reprojection error {intr.rms_px:.3f} px over {intr.n_views} views "
              f"-> {args.out_intrinsics}")


def cmd_calibrate(args):
    calib_dir = Path(args.calib_dir) if args.calib_dir and Path(args.calib_dir).is_dir() else None
    calib = Path(args.calib_views) if args.calib_views else calib_dir
    if args.intrinsics and calib is None:
        from stringcast.core import DataError

        raise DataError(f"{args.intrinsics}: campaign intrinsics need the views they were fitted to "
                        "(--calib-views or a --calib-dir folder)")
    intrinsics = Path(args.intrinsics) if args.intrinsics else None
    cal = _run("calibrate", args, Path(args.trial_dir), calib, _campaign(args), Path(args.out),
               intrinsics_json=intrinsics)
    bc = (cal.board_check or {}).get("residual_mm")
    extra = "" if bc is None else f", board-to-robot check {bc:.1f} mm"
    print(f"calibration: reprojection error {cal.reprojection_error_px:.3f} px{extra}, {cal.verdict.status} -> {args.out}")
    for reason in cal.verdict.reasons:
        print(f"  {cal.verdict.status}: {reason}")


def _frames(args) -> Path | None:
    return Path(args.frames) if args.frames else None


def cmd_decode(args):
    from stringcast.core import find_video

    video = find_video(Path(args.trial_dir))
    print(f"decoded {video} once -> {_run('decode', args, video, Path(args.out))}")


def cmd_sync(args):
    doc = _run("sync", args, Path(args.trial_dir), Path(args.calibration), _campaign(args), Path(args.out),
               _frames(args), int(args.workers))
    extra = "" if doc.get("time_residual_ms") is None else \
        f", time residual {doc['time_residual_ms']:.2f} ms, arm match residual {doc['residual_mm'] or float('nan'):.1f} mm"
    print(f"sync: offset {doc['offset_s']:.6f} s ({doc['method']}{extra}), verdict {doc['verdict']['status']} "
          f"-> {args.out}")


def cmd_sweep(args):
    geo, clock = _run("sweep", args, Path(args.trial_dir), Path(args.calibration), Path(args.sync), _campaign(args),
                      Path(args.out_geometry), Path(args.out_clock), _frames(args), int(args.workers))
    sw = geo.get("sweep", {})
    if sw.get("applied"):
        print(f"sweep: {sw['rows_used']} link rows in {sw['frames']} frames; mapping moved up to {sw['moved_p95_mm']:.2f} mm "
              f"(p95), known to {sw['uncertainty_p95_mm']:.2f} mm; clock {sw['clock_correction_ms']:+.2f} ms, known to "
              f"{sw['clock_uncertainty_ms']:.2f} ms; verdicts {geo['verdict']['status']} / {clock['verdict']['status']} "
              f"-> {args.out_geometry}, {args.out_clock}")
    else:
        print(f"sweep: not applied ({sw.get('reason')}) -> {args.out_geometry}, {args.out_clock}")


def cmd_track(args):
    df = _run("track", args, Path(args.trial_dir), Path(args.calibration), Path(args.sync), _campaign(args),
              Path(args.out), Path(args.overlay) if args.overlay else None, _frames(args), int(args.workers))
    print(f"tracking: {df['frame'].nunique()} frames, valid share {df['valid'].mean():.3f} -> {args.out}")


def _earlier(args) -> tuple:
    """Pairs (tracks, joints) of the earlier trials fitted together (estimation.joint_trials)."""
    tracks, joints = args.earlier_tracks or [], args.earlier_joints or []
    if len(tracks) != len(joints):
        raise SystemExit(f"estimate: {len(tracks)} --earlier-tracks but {len(joints)} --earlier-joints")
    return tuple(zip(map(Path, tracks), map(Path, joints)))


def cmd_estimate(args):
    est = _run("estimate", args, Path(args.tracks), Path(args.joints), _campaign(args),
               Path(args.prev) if args.prev else None, int(args.trial), Path(args.out_params), Path(args.out_fit),
               _earlier(args))
    print(f"estimation: E = {est.E_m * 1000:.2f} mm after {est.n_evaluations} evaluations -> {args.out_params}")
    cause = f" (likely cause: {est.likely_cause})" if est.likely_cause else ""
    usable = {"ok": "", "warn": ": doubtful", "fail": ": the estimate is not usable"}[est.verdict.status]
    print(f"fit verdict: {est.verdict.status}{cause}{usable}")
    for reason in est.verdict.reasons:
        print(f"  - {reason}")


def cmd_predict(args):
    doc = _run("predict", args, Path(args.params), Path(args.tracks), Path(args.joints), _campaign(args), Path(args.out))
    figure = "no figure" if doc["median_mm"] is None else f"median {doc['median_mm']:.1f} mm, p95 {doc['p95_mm']:.1f} mm"
    print(f"next-motion prediction: {figure} over {doc['valid_frames']} of {doc['frames']} frames, "
          f"{doc['verdict']['status']} -> {args.out}")
    for reason in doc["verdict"]["reasons"]:
        print(f"  - {reason}")


def cmd_plan_first(args):
    out = Path(args.out_dir)
    _run("plan-first", args, _campaign(args), out / "motion.csv", out / "motion.json", int(args.seed))
    print(f"first motion -> {out / 'motion.csv'}")


def cmd_plan(args):
    out = Path(args.out_dir)
    _run("plan", args, Path(args.params), Path(args.played_motion), _campaign(args), out / "motion.csv",
         out / "motion.json", int(args.seed), Path(args.tracks) if args.tracks else None,
         Path(args.joints) if args.joints else None)
    print(f"next motion -> {out / 'motion.csv'}")
    doc = json.loads((out / "motion.json").read_text())
    if doc.get("planned_on_failed_fit"):
        fit = doc.get("failed_fit") or {}
        print(f"WARNING: planned on a failed fit (likely cause: {fit.get('likely_cause') or 'not named'}): the "
              f"estimate in {args.params} is not usable, nor is this motion's predicted hit; check before playing it")
        for reason in fit.get("reasons", []):
            print(f"  - {reason}")


def cmd_report_trial(args):
    _run("report-trial", args, Path(args.data_dir), Path(args.results_dir), _campaign(args), Path(args.out))
    print(f"trial report -> {args.out}")


def cmd_report_campaign(args):
    _run("report-campaign", args, Path(args.data_dir), Path(args.results_dir), _campaign(args), Path(args.out))
    print(f"campaign report -> {args.out}")


def cmd_execute(args):
    from stringcast.execute import execute

    execute(Path(args.motion), args.backend, Path(args.out), Path(args.campaign), config=_config(args),
            **_settings(execute, args), seed=int(args.seed), dry_run=bool(args.dry_run), robot_ip=args.robot_ip,
            move_to_start=bool(args.move_to_start))


def cmd_calib_clip(args):
    from stringcast.lab import write_calibration_clip

    path = write_calibration_clip(_campaign(args), _config(args), Path(args.out), int(args.seed))
    print(f"calibration clip -> {path}")


def campaign_config_paths(args) -> list[str]:
    """The config files ``stringcast campaign`` merges over the project's config/config.yaml, in
    order: each ``--config``, then ``--method``'s file (ours: config/ours.yaml) last."""
    from stringcast.core import METHOD_CONFIGS

    return (config_paths(args) or []) + [str(c) for c in METHOD_CONFIGS[args.method]]


def cmd_campaign(args):
    from stringcast.campaign import run_campaign

    run_campaign(args.name, args.string, args.target, config_path=campaign_config_paths(args),
                 max_executions=int(args.max_executions), cores=int(args.cores), seed=int(args.seed),
                 root=Path(args.root))


REFERENCE_MARK = "<!-- below: made by `stringcast settings --markdown`; tests/test_cli.py keeps it in step -->"


def settings_reference(tables: str) -> str:
    """config/README.md's generated part: which sections each workflow stage reads, then
    ``tables`` (every setting's default and meaning)."""
    rows = [f"| `{cmd}` | {', '.join(f'`{s}`' for s in stage_sections(cmd))} |" for cmd in STAGES]
    return "\n".join([REFERENCE_MARK, "", "## What each stage reads", "",
                      "| stage (`stringcast` command) | sections read |", "| --- | --- |", *rows, "",
                      "## Every setting", "", tables])


def cmd_settings(args):
    import yaml

    from stringcast.core import SECTION_CLASSES, markdown_table, settings_from_config

    if args.markdown:
        print(settings_reference(markdown_table()))
        return
    s = settings_from_config(_config(args))
    doc = {c.SECTION: getattr(s, c.SECTION).as_dict() for c in SECTION_CLASSES}
    print(yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=110), end="")


HANDLERS = {"decode": cmd_decode, "calib-views": cmd_calib_views, "calibrate": cmd_calibrate, "sync": cmd_sync, "sweep": cmd_sweep, "track": cmd_track,
            "estimate": cmd_estimate, "predict": cmd_predict, "plan-first": cmd_plan_first, "plan": cmd_plan,
            "report-trial": cmd_report_trial, "report-campaign": cmd_report_campaign, "execute": cmd_execute,
            "calib-clip": cmd_calib_clip, "campaign": cmd_campaign, "settings": cmd_settings}
"""Each subcommand's function."""


def build_parser() -> argparse.ArgumentParser:
    """The command line (:func:`stringcast.cli_parser.build_parser` with :data:`HANDLERS`)."""
    from stringcast.cli_parser import build_parser as build

    return build(HANDLERS, __doc__.split("\n\n")[0])


def main(argv: list[str] | None = None) -> int:
    """Run one subcommand; its exit status: 0, 2 for bad input (one line naming the file), or
    :data:`INTERNAL_ERROR_STATUS` for any other exception (:func:`internal_error`: one line and where
    its traceback went). A workflow stage runs in the run's warm server where there is one
    (:mod:`stringcast.warm`), else here."""
    argv = sys.argv[1:] if argv is None else list(argv)
    code = warm.run_in_server(argv, wait_s=0.0 if argv[:1] and argv[0] in START_AT_ONCE else WARM_WAIT_S)
    if code is not None:
        return code
    from stringcast.core import ConfigError, DataError, JointLimitError

    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except (DataError, ConfigError, JointLimitError) as exc:
        print(f"stringcast {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # noqa: BLE001  (a defect, not bad input: one line, the traceback kept)
        print(internal_error(args.command, exc), file=sys.stderr)
        return INTERNAL_ERROR_STATUS
    return 0


INTERNAL_ERROR_STATUS = 1
"""The exit status of a subcommand that ended in an unexpected exception (a defect of stringcast,
not of its input: bad input exits with 2)."""
TRACEBACK_DIR_ENV = "STRINGCAST_TRACEBACK_DIR"
"""Environment variable naming the folder an internal error's full traceback is written to
(default: the system's temporary folder)."""


def internal_error(command: str, exc: BaseException) -> str:
    """The message for an unexpected exception ``exc`` in ``stringcast command``: its first line
    ``stringcast <command>: internal error: <type>: <message>`` (the message's first line, at most
    300 characters), its second where the full traceback was written (a file
    ``stringcast-<command>-<time>-<pid>.traceback`` in ``$STRINGCAST_TRACEBACK_DIR`` or the
    system's temporary folder) or, where it cannot be written, the traceback itself."""
    import tempfile
    import time
    import traceback

    text = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    first = (str(exc).strip().splitlines() or [""])[0]
    first = first if len(first) <= 300 else first[:297] + "..."
    head = f"stringcast {command}: internal error: {type(exc).__name__}: {first}"
    folder = Path(os.environ.get(TRACEBACK_DIR_ENV) or tempfile.gettempdir())
    path = folder / f"stringcast-{command}-{time.strftime('%Y%m%dT%H%M%S')}-{os.getpid()}.traceback"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        path.write_text(f"stringcast {command}\n{text}")
    except OSError:
        return f"{head}\n  (the full traceback could not be written to {folder}; here it is)\n{text}"
    return f"{head}\n  (unexpected: not an input error stringcast knows; the full traceback is in {path})"


START_AT_ONCE = ("decode",)
"""Stages that run cold at once rather than wait for a starting warm server: the video's decode, a
trial's first job, imports only OpenCV and NumPy, and every later stage waits for it."""
WARM_WAIT_S = 30.0
"""How long any other stage waits for a starting warm server (its imports take 2-3 s) rather than
import the same stages itself, beside the decode (:func:`stringcast.warm.run_in_server`)."""
PRELOAD_SKIPS = ("report-trial", "report-campaign")
"""Stages the warm server does not import: the reports (matplotlib, Jinja2: 0.7 s of CPU that the
video's decode shares) come after the next motion, and their jobs import them themselves."""


def preload_stages() -> None:
    """Import the workflow's stages up to the next motion and what they import when first used (the
    config's schema check, Parquet), and set up numba's compiler (0.4 s, shared by every cached kernel
    a job then loads) with a throwaway function that starts no threads: the warm server's preload."""
    import jsonschema  # noqa: F401
    import numba
    import pyarrow.dataset  # noqa: F401
    import pyarrow.parquet  # noqa: F401

    for command in STAGES:
        if command not in PRELOAD_SKIPS:
            stage_entry(command)
    numba.njit(lambda x: x + 1)(1)


def warm_server(argv: list[str] | None = None) -> None:
    """The workflow's warm server (:data:`stringcast.warm.SERVER_ENTRY`; arguments SOCKET
    PARENT_PID): forks each workflow stage's job from a process that has imported them all."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 2 or not args[1].isdigit():
        sys.exit("usage: warm_server SOCKET PARENT_PID")
    try:
        warm.serve(args[0], preload_stages, lambda a: a[0] in STAGES, main, parent=int(args[1]), log=sys.stdout)
    finally:   # without the interpreter's teardown of every stage's modules (1 s that Snakemake waits for)
        sys.stdout.flush()
        os._exit(0)


if __name__ == "__main__":
    sys.exit(main())
