"""The ``stringcast`` command line: one subcommand per stage (the Snakemake rules
call these) plus ``check`` (every raw file of a campaign, before any decode), ``execute``
(play a motion file on an arm) and ``campaign`` (the whole loop on the virtual lab).

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

from stringcast.core import INTERNAL_ERROR_STATUS, TRACEBACK_DIR_ENV, JobLog, internal_error  # noqa: F401
from stringcast.core import STAGES, reads_target, settings_reference, stage_entry


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
    """The campaign ``--campaign`` names; its target required, but by a stage that never reads it."""
    from stringcast.core import load_campaign

    optional = args.command in STAGES and not reads_target(args.command)
    return load_campaign(args.campaign, _config(args), require_target=not optional)


def _settings(func, args) -> dict:
    """The settings objects ``func`` takes (by its annotations), built once from the config."""
    from stringcast.core import settings_from_config, stage_kwargs

    key = ("settings", str(config_paths(args)))
    if key not in _CONFIG_CACHE:
        _CONFIG_CACHE[key] = settings_from_config(_config(args))
    return stage_kwargs(func, _CONFIG_CACHE[key])


def _run(command: str, args, *positional, **keywords):
    """Run ``command``'s stage on ``positional`` (its own order), ``keywords``, the settings it takes and,
    by name, each of the command's inputs that it takes and the handler did not pass
    (:func:`stringcast.core.ports.stage_inputs`: a new input needs no handler)."""
    import inspect

    from stringcast.core import stage_inputs

    func = stage_entry(command)
    settings = _settings(func, args)
    bound = {**inspect.signature(func).bind_partial(*positional, **keywords).arguments, **settings}
    return func(*positional, **keywords, **stage_inputs(func, command, args, bound), **settings)


_LOG = JobLog()


def _verdict_line(stage: str, verdict, summary: str, out, note: str = "") -> None:
    """The stage's one terminal line: ``<stage>: <status>[, <note>]: <first reason, or the summary> -> <out>``
    (``verdict``: a :class:`~stringcast.core.Verdict` or its dict; ``note``: what the status means, without
    a colon); the other reasons go to the log."""
    status, reasons = (verdict.get("status", "ok"), list(verdict.get("reasons", []))) if isinstance(verdict, dict) \
        else (verdict.status, list(verdict.reasons))
    first = reasons[0] if reasons else summary
    more = f" (+{len(reasons) - 1} more reasons in the log)" if len(reasons) > 1 else ""
    _LOG.say(f"{stage}: {status}{', ' + note if note else ''}: {first}{more} -> {out}")
    for reason in reasons[1:]:
        print(f"  {status}: {reason}")


def cmd_calib_views(args):
    campaign = _campaign(args)
    views = _run("calib-views", args, Path(args.calib_dir), campaign, Path(args.out))
    summary = f"the board in {len(views)} of {views.found} views of {args.calib_dir}"
    if not args.out_intrinsics:
        _LOG.say(f"calibration views: {summary} -> {args.out}")
        return
    from stringcast.calibrate import write_campaign_intrinsics
    from stringcast.core import read_json

    intr = write_campaign_intrinsics(Path(args.out), campaign, Path(args.out_intrinsics),
                                     **_settings(write_campaign_intrinsics, args))
    rejected = f", {intr.views_rejected} rejected" if intr.views_rejected else ""
    print(f"calibration views: {summary} -> {args.out}")
    _verdict_line("intrinsics", read_json(args.out_intrinsics)["verdict"],
                  f"reprojection error {intr.rms_px:.3f} px over {intr.n_views} views{rejected}", args.out_intrinsics)


def cmd_calibrate(args):
    calib_dir = Path(args.calib_dir) if args.calib_dir and Path(args.calib_dir).is_dir() else None
    calib = Path(args.calib_views) if args.calib_views else calib_dir
    if args.intrinsics and calib is None:
        from stringcast.core import DataError

        raise DataError(f"{args.intrinsics}: campaign intrinsics need the views they were fitted to "
                        "(--calib-views or a --calib-dir folder)")
    intrinsics = Path(args.intrinsics) if args.intrinsics else None
    cal = _run("calibrate", args, _trial(args), calib, _campaign(args), Path(args.out),
               intrinsics_json=intrinsics)
    bc = (cal.board_check or {}).get("residual_mm")
    extra = "" if bc is None else f", board-to-robot check {bc:.1f} mm"
    _verdict_line("calibration", cal.verdict, f"reprojection error {cal.reprojection_error_px:.3f} px{extra}", args.out)


def _frames(args) -> Path | None:
    return Path(args.frames) if args.frames else None


def _trial(args):
    """The trial's raw files named on the command line (stringcast.core.TrialFiles)."""
    from stringcast.core import TrialFiles

    meta = getattr(args, "video_meta", None)
    return TrialFiles(Path(args.video), Path(args.joints), Path(meta) if meta else None)


def cmd_decode(args):
    _LOG.say(f"decode: {args.video} decoded once -> {_run('decode', args, Path(args.video), Path(args.out))}")


def cmd_sync(args):
    doc = _run("sync", args, _trial(args), Path(args.calibration), _campaign(args), Path(args.out),
               _frames(args), int(args.workers))
    extra = "" if doc.get("time_residual_ms") is None else \
        f", time residual {doc['time_residual_ms']:.2f} ms, arm match residual {doc['residual_mm'] or float('nan'):.1f} mm"
    _verdict_line("sync", doc["verdict"], f"offset {doc['offset_s']:.6f} s ({doc['method']}{extra})", args.out)


def cmd_sweep(args):
    geo, clock = _run("sweep", args, _trial(args), Path(args.calibration), Path(args.sync), _campaign(args),
                      Path(args.out_geometry), Path(args.out_clock), _frames(args), int(args.workers))
    sw = geo.get("sweep", {})
    if sw.get("applied"):
        print(f"sweep: {sw['rows_used']} link rows in {sw['frames']} frames; mapping moved up to "
              f"{sw['moved_p95_mm']:.2f} mm (p95)")
        _verdict_line("sweep (mapping)", geo["verdict"], f"known to {sw['uncertainty_p95_mm']:.2f} mm (p95)",
                      args.out_geometry)
        _verdict_line("sweep (clock)", clock["verdict"], f"corrected by {sw['clock_correction_ms']:+.2f} ms, known to "
                      f"{sw['clock_uncertainty_ms']:.2f} ms", args.out_clock)
    else:
        _verdict_line("sweep", geo["verdict"], f"not applied ({sw.get('reason')})", f"{args.out_geometry}, {args.out_clock}")


def cmd_track(args):
    from stringcast.core import read_json

    quality_json = Path(args.out_quality) if args.out_quality else Path(args.out).with_name("tracking.json")
    df = _run("track", args, _trial(args), Path(args.geometry), Path(args.clock), _campaign(args),
              Path(args.out), Path(args.overlay) if args.overlay else None, _frames(args), int(args.workers),
              quality_json)
    quality = read_json(quality_json)
    _verdict_line("tracking", quality.get("verdict") or {},
                  f"{df['frame'].nunique()} frames, valid share {df['valid'].mean():.3f}", args.out)


def cmd_estimate(args):
    upstream = {"geometry": Path(args.geometry), "clock": Path(args.clock), "tracking": Path(args.tracking)}
    est = _run("estimate", args, Path(args.tracks), Path(args.joints), _campaign(args),
               Path(args.prev) if args.prev else None, int(args.trial), Path(args.out_params), Path(args.out_fit),
               upstream=upstream)
    print(f"estimation: E = {est.E_m * 1000:.2f} mm after {est.n_evaluations} evaluations")
    usable = {"ok": "", "warn": "doubtful", "fail": "the estimate is not usable"}[est.verdict.status]
    cause = f"likely cause {est.likely_cause}" if est.likely_cause else ""
    _verdict_line("fit", est.verdict, f"E = {est.E_m * 1000:.2f} mm", args.out_params,
                  note=", ".join(x for x in (usable, cause) if x))


def cmd_predict(args):
    doc = _run("predict", args, Path(args.params), Path(args.tracks), Path(args.joints), _campaign(args), Path(args.out))
    figure = "no figure" if doc["median_mm"] is None else f"median {doc['median_mm']:.1f} mm, p95 {doc['p95_mm']:.1f} mm"
    _verdict_line("next-motion prediction", doc["verdict"],
                  f"{figure} over {doc['valid_frames']} of {doc['frames']} frames", args.out)


def cmd_plan_first(args):
    out = Path(args.out_dir)
    result = _run("plan-first", args, _campaign(args), out / "motion.csv", out / "motion.json", int(args.seed))
    _plan_line("first motion", result, out)


def cmd_plan(args):
    out = Path(args.out_dir)
    result = _run("plan", args, Path(args.params), Path(args.played_motion), _campaign(args), out / "motion.csv",
                  out / "motion.json", int(args.seed), Path(args.tracks) if args.tracks else None,
                  Path(args.joints) if args.joints else None)
    doc = _plan_line("next motion", result, out)
    for reason in (doc.get("failed_fit") or {}).get("reasons", []) if doc.get("planned_on_failed_fit") else []:
        print(f"  - the fit ({args.params}): {reason}")


def _plan_line(what: str, result, out: Path) -> dict:
    """The plan stage's terminal line: its verdict (motion.json), the predicted closest approach; returns
    the motion.json it read."""
    doc = json.loads((out / "motion.json").read_text())
    note = f"{what} predicted {result.d_min * 1000:.1f} mm from the target ({doc.get('origin') or 'planned'})"
    _verdict_line("plan", doc.get("verdict") or {}, "the predicted hit is not doubted", out / "motion.csv", note)
    return doc


def cmd_report_trial(args):
    from stringcast.core import TrialFiles, TrialResults

    trial = TrialFiles(Path(args.video), Path(args.joints), played=Path(args.played_motion))
    results = TrialResults(*(Path(p) for p in (args.geometry, args.clock, args.tracks, args.tracking, args.params,
                                                args.fit, args.next_motion, args.next_motion_meta)),
                           prediction=Path(args.prediction) if args.prediction else None)
    _run("report-trial", args, trial, results, _campaign(args), Path(args.out))
    _LOG.say(f"trial report -> {args.out}")


def cmd_report_campaign(args):
    _run("report-campaign", args, Path(args.data_dir), Path(args.results_dir), _campaign(args), Path(args.out))
    _LOG.say(f"campaign report -> {args.out}")


def cmd_execute(args):
    from stringcast.execute import execute

    info = execute(Path(args.motion), args.backend, Path(args.out), Path(args.campaign), config=_config(args),
                   **_settings(execute, args), seed=int(args.seed), dry_run=bool(args.dry_run),
                   robot_ip=args.robot_ip, move_to_start=bool(args.move_to_start))
    if not info.get("dry_run"):
        _LOG.say(f"executed {args.motion} on {args.backend}: {info['samples']} samples, {info['duration_s']:.3f} s "
                 f"(motion from {info['motion_start_s']:.3f} s) -> {args.out}")


def cmd_calib_clip(args):
    from stringcast.execute import lab_module

    write_calibration_clip = lab_module(needed_by="stringcast calib-clip").write_calibration_clip
    path = write_calibration_clip(_campaign(args), _config(args), Path(args.out), int(args.seed))
    print(f"calibration clip -> {path}")


def campaign_config_paths(args) -> list[str]:
    """The config files ``stringcast campaign`` merges over the project's config/config.yaml, in
    order: each ``--config``, then ``--method``'s file (paper: config/paper.yaml; ours sets none) last."""
    from stringcast.core import METHOD_CONFIGS

    return (config_paths(args) or []) + [str(c) for c in METHOD_CONFIGS[args.method]]


def cmd_campaign(args):
    from stringcast.execute import lab_module

    run_campaign = lab_module("stringcast_lab.campaign", needed_by="stringcast campaign").run_campaign
    run_campaign(args.name, args.string, args.target, config_path=campaign_config_paths(args),
                 max_executions=int(args.max_executions), cores=int(args.cores), seed=int(args.seed),
                 root=Path(args.root))


def cmd_next(args):
    from stringcast.chain import run_next, trial_location
    from stringcast.core import METHOD_CONFIGS

    base = trial_location(args.trial_dir)[0] / "config" / "config.yaml"
    paths = ([str(base)] if base.is_file() else []) + (args.config or []) + [str(c) for c in METHOD_CONFIGS[args.method]]
    log = _LOG
    motion = run_next(args.trial_dir, paths, main, say=log.say)
    log.say(f"next motion -> {motion}")


def check_summary(campaign_dir: str, problems: list, n_trials: int) -> str:
    """``stringcast check``'s last line: the counts of errors and warnings, or ok."""
    errors = sum(p.is_error for p in problems)
    trials = f"{n_trials} trial{'s' if n_trials != 1 else ''}"
    if not problems:
        return f"check: {campaign_dir}: ok ({trials})"
    return (f"check: {campaign_dir}: {errors} error{'s' if errors != 1 else ''}, {len(problems) - errors} "
            f"warning{'s' if len(problems) - errors != 1 else ''} in {trials}")


def cmd_check(args) -> int:
    from stringcast.check import check_campaign, trial_dirs

    config = _config(args)
    problems = check_campaign(Path(args.campaign_dir), config)
    for p in problems:
        print(f"{'error' if p.is_error else 'warning'}: {p}")
    n_trials = len(trial_dirs(args.campaign_dir)[1]) if Path(args.campaign_dir).is_dir() else 0
    print(check_summary(str(args.campaign_dir), problems, n_trials))
    return 2 if any(p.is_error for p in problems) else 0


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
            "calib-clip": cmd_calib_clip, "campaign": cmd_campaign, "next": cmd_next, "settings": cmd_settings, "check": cmd_check}
"""Each subcommand's function."""


def build_parser() -> argparse.ArgumentParser:
    """The command line (:func:`stringcast.cli_parser.build_parser` with :data:`HANDLERS`)."""
    from stringcast.cli_parser import build_parser as build

    return build(HANDLERS, __doc__.split("\n\n")[0])


def main(argv: list[str] | None = None) -> int:
    """Run one subcommand; its exit status: 0, 2 for an input error (one line naming the file),
    :data:`INTERNAL_ERROR_STATUS` for any other exception (:func:`internal_error`: one line, and the
    traceback in the log or a file it names), 130 when interrupted. A workflow stage run by the
    workflow (``$STRINGCAST_WORKFLOW_PID``) ends with it (:mod:`stringcast.core.lifeline`)."""
    global _LOG
    argv = sys.argv[1:] if argv is None else list(argv)
    from stringcast.core import ConfigError, DataError, JointLimitError, start_lifeline

    args = build_parser().parse_args(argv)
    outer, _LOG = _LOG, JobLog(args.log)        # a command run by another (``next``) gives its log back
    if args.command in STAGES:
        start_lifeline()
    try:
        code = args.func(args)
    except (DataError, ConfigError, JointLimitError) as exc:
        _LOG.say(f"stringcast {args.command}: error: {exc}", error=True)
        return 2
    except KeyboardInterrupt:
        _LOG.say(f"stringcast {args.command}: interrupted; nothing finished was written", error=True)
        return 130
    except Exception as exc:  # noqa: BLE001  (a defect, not bad input: one line, the traceback kept)
        _LOG.say(internal_error(args.command, exc, in_log=bool(args.log)), error=True)
        return INTERNAL_ERROR_STATUS
    finally:
        _LOG.close()
        _LOG = outer
    return code if isinstance(code, int) else 0


if __name__ == "__main__":
    sys.exit(main())
