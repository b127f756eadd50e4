"""The ``stringcast`` command line: one subcommand per stage (the Snakemake rules
call these) plus ``execute`` (play a motion file on an arm) and ``campaign`` (the
whole loop on the virtual lab).

Errors in the input (:class:`~stringcast.core.files.DataError`,
:class:`~stringcast.core.config.ConfigError`, :class:`~stringcast.core.arm.JointLimitError`)
print one line naming the file and the problem and exit with status 2.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from stringcast.core import METHOD_CONFIGS


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
    "calibrate": "stringcast.calibrate:run_calibration",
    "sync": "stringcast.sync:run_sync",
    "sweep": "stringcast.sync:run_sweep",
    "track": "stringcast.track:run_tracking",
    "estimate": "stringcast.estimate:run_estimation",
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
    parameters (:func:`stringcast.core.sections_read`). The rules' params are these sections."""
    from stringcast.core import sections_read

    return sections_read(stage_entry(command))


def _run(command: str, args, *positional):
    """Run ``command``'s stage on ``positional`` (its own order) and the settings it takes."""
    func = stage_entry(command)
    return func(*positional, **_settings(func, args))


def cmd_calibrate(args):
    calib_dir = Path(args.calib_dir) if args.calib_dir and Path(args.calib_dir).is_dir() else None
    cal = _run("calibrate", args, Path(args.trial_dir), calib_dir, _campaign(args), Path(args.out))
    bc = (cal.board_check or {}).get("residual_mm")
    extra = "" if bc is None else f", board-to-robot check {bc:.1f} mm"
    print(f"calibration: reprojection error {cal.reprojection_error_px:.3f} px{extra}, {cal.verdict.status} -> {args.out}")
    for reason in cal.verdict.reasons:
        print(f"  {cal.verdict.status}: {reason}")


def _frames(args) -> Path | None:
    return Path(args.frames) if args.frames else None


def cmd_decode(args):
    from stringcast.core import find_video

    out = _run("decode", args, find_video(Path(args.trial_dir)), Path(args.out))
    print(f"decoded {find_video(Path(args.trial_dir))} once -> {out}")


def cmd_sync(args):
    doc = _run("sync", args, Path(args.trial_dir), Path(args.calibration), _campaign(args), Path(args.out),
               _frames(args), int(args.workers))
    extra = "" if doc.get("time_residual_ms") is None else \
        f", time residual {doc['time_residual_ms']:.2f} ms, arm match residual {doc['residual_mm'] or float('nan'):.1f} mm"
    print(f"sync: offset {doc['offset_s']:.6f} s ({doc['method']}{extra}), verdict {doc['verdict']['status']} "
          f"-> {args.out}")


def cmd_sweep(args):
    geo, clock = _run("sweep", args, Path(args.trial_dir), Path(args.calibration), Path(args.sync), _campaign(args),
                      Path(args.out_geometry), Path(args.out_clock), _frames(args))
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


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows each option's default after its help, except where it has none (required, or None)."""

    def _get_help_string(self, action):
        if action.required or action.default is None:
            return action.help
        return super()._get_help_string(action)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="stringcast", description=__doc__.split("\n\n")[0],
                                formatter_class=_HelpFormatter)
    p.add_argument("--config", action="append", default=None,
                   help="config YAML (default: config/config.yaml); given again, each file is merged over the ones "
                        "before it, as Snakemake merges --configfile over the Snakefile's configfile")
    sub = p.add_subparsers(dest="command", required=True, help="the stage or tool to run")

    def add(name, func, help_):
        sp = sub.add_parser(name, help=help_, description=help_, formatter_class=_HelpFormatter)
        sp.set_defaults(func=func)
        return sp

    _add_analysis_commands(add)
    _add_planning_and_tools(add)
    return p


CAMPAIGN_HELP = "data/<campaign>/campaign.yaml: the campaign's string, target, arm and set-up"
TRIAL_HELP = "data/<campaign>/trial_<k>: the trial's raw files (video, video.yaml, joints.csv, motion.json)"
SEED_HELP = "random seed of {}"


def _add_analysis_commands(add) -> None:
    """calibrate, sync, sweep, track, estimate: one trial's analysis, stage by stage (the rules call them)."""
    campaign_help, trial_help = CAMPAIGN_HELP, TRIAL_HELP
    frames_help = "the trial's frames.npy (`stringcast decode`), read instead of decoding the video"
    sp = add("decode", cmd_decode, "decode the trial's video once -> frames.npy (+ frames.json), read by sync, "
                                   "sweep and track")
    sp.add_argument("--trial-dir", required=True, help=trial_help)
    sp.add_argument("--out", required=True, help="frames.npy to write: (F, H, W) grey frames")

    sp = add("calibrate", cmd_calibrate, "ChArUco calibration of one trial -> calibration.json")
    sp.add_argument("--trial-dir", required=True, help=trial_help)
    sp.add_argument("--calib-dir", help="data/<campaign>/calib/: ChArUco clip or views for the camera intrinsics; "
                                        "if not given or not a folder, the board's homography only")
    sp.add_argument("--campaign", required=True, help=campaign_help)
    sp.add_argument("--out", required=True, help="calibration.json to write (intrinsics, board pose, px errors)")

    sp = add("sync", cmd_sync, "video-to-controller clock offset -> sync.json")
    sp.add_argument("--trial-dir", required=True, help=trial_help)
    sp.add_argument("--calibration", required=True, help="the trial's calibration.json")
    sp.add_argument("--campaign", required=True, help=campaign_help)
    sp.add_argument("--out", required=True, help="sync.json to write (offset in s: controller time of frame 0)")
    sp.add_argument("--frames", help=frames_help)
    sp.add_argument("--workers", default=1, help="processes matching frames side by side (with --frames)")

    sp = add("sweep", cmd_sweep, "the mapping and the clock refined by the arm's sweep -> geometry.json, clock.json")
    sp.add_argument("--trial-dir", required=True, help=trial_help)
    sp.add_argument("--calibration", required=True, help="the trial's calibration.json")
    sp.add_argument("--sync", required=True, help="the trial's sync.json")
    sp.add_argument("--campaign", required=True, help=campaign_help)
    sp.add_argument("--out-geometry", required=True, help="geometry.json to write (calibration.json's schema, refined)")
    sp.add_argument("--out-clock", required=True, help="clock.json to write (sync.json's schema, the offset corrected)")
    sp.add_argument("--frames", help=frames_help)

    sp = add("track", cmd_track, "markerless tracking -> tracks.parquet")
    sp.add_argument("--trial-dir", required=True, help=trial_help)
    sp.add_argument("--calibration", required=True, help="the trial's geometry.json (or calibration.json)")
    sp.add_argument("--sync", required=True, help="the trial's clock.json (or sync.json)")
    sp.add_argument("--campaign", required=True, help=campaign_help)
    sp.add_argument("--out", required=True, help="tracks.parquet to write: frame, t_s, point, x_m, y_m, valid "
                                                 "(m, robot frame; point 0 the grasp)")
    sp.add_argument("--overlay", help="tracking_overlay.png to write (tracked points on frames); "
                                      "if not given, none")
    sp.add_argument("--frames", help=frames_help)
    sp.add_argument("--workers", default=1, help="processes tracking frames side by side (with --frames)")

    sp = add("estimate", cmd_estimate, "fit the model's parameters -> params.json, fit.parquet")
    sp.add_argument("--tracks", required=True, help="the trial's tracks.parquet")
    sp.add_argument("--joints", required=True, help="the trial's joints.csv (t_s, q1_rad .. qJ_rad)")
    sp.add_argument("--campaign", required=True, help=campaign_help)
    sp.add_argument("--prev", help="previous trial's params.json (chi_best of eq. 3)")
    sp.add_argument("--trial", required=True, help="trial index k = executions so far (M of eq. 3)")
    sp.add_argument("--out-params", required=True, help="params.json to write: coefficients, masses, E in mm")
    sp.add_argument("--out-fit", required=True, help="fit.parquet to write: tracked and simulated points per "
                                                     "frame (m)")
    sp.add_argument("--earlier-tracks", nargs="*", help="earlier trials' tracks.parquet, fitted together")
    sp.add_argument("--earlier-joints", nargs="*", help="their joints.csv, in the same order")


def _add_planning_and_tools(add) -> None:
    """plan-first, plan, the reports, and the tools around the workflow (execute, calib-clip,
    campaign, settings)."""
    campaign_help, seed_help = CAMPAIGN_HELP, SEED_HELP
    plan_seed_help = seed_help.format("the planner's search (beside the config's motion.seed)")

    sp = add("plan-first", cmd_plan_first, "first motion with Table 2's minimum parameters")
    sp.add_argument("--campaign", required=True, help=campaign_help)
    sp.add_argument("--out-dir", required=True, help="folder for motion.csv (t_s, q1_rad ..) and motion.json")
    sp.add_argument("--seed", default=0, help=plan_seed_help)

    sp = add("plan", cmd_plan, "next motion from estimated parameters")
    sp.add_argument("--params", required=True, help="the trial's params.json (the estimate)")
    sp.add_argument("--played-motion", required=True, help="motion.json of the motion just played")
    sp.add_argument("--tracks", help="tracks.parquet of the played trial (motion.residual_correction)")
    sp.add_argument("--joints", help="joints.csv of the played trial (motion.residual_correction)")
    sp.add_argument("--campaign", required=True, help=campaign_help)
    sp.add_argument("--out-dir", required=True, help="folder for the next motion's motion.csv and motion.json")
    sp.add_argument("--seed", default=0, help=plan_seed_help)

    sp = add("report-trial", cmd_report_trial, "self-contained HTML page for one trial")
    sp.add_argument("--data-dir", required=True, help="data/<campaign>/trial_<k>")
    sp.add_argument("--results-dir", required=True, help="results/<campaign>/trial_<k>")
    sp.add_argument("--campaign", required=True, help=campaign_help)
    sp.add_argument("--out", required=True, help="report.html to write")

    sp = add("report-campaign", cmd_report_campaign, "campaign page: one row per execution")
    sp.add_argument("--data-dir", required=True, help="data/<campaign>")
    sp.add_argument("--results-dir", required=True, help="results/<campaign>")
    sp.add_argument("--campaign", required=True, help=campaign_help)
    sp.add_argument("--out", required=True, help="report.html to write")

    sp = add("execute", cmd_execute, "play a motion file on an arm and record the next trial's raw files")
    sp.add_argument("motion", help="motion.csv (its motion.json beside it is copied along)")
    sp.add_argument("--backend", choices=["virtual", "ur-rtde"], default="virtual",
                    help="virtual: the simulated lab's arm and camera; ur-rtde: a UR arm over RTDE")
    sp.add_argument("--out", required=True, help="data/<campaign>/trial_<k> to create")
    sp.add_argument("--campaign", required=True, help="data/<campaign>/campaign.yaml")
    sp.add_argument("--seed", default=0,
                    help=seed_help.format("the virtual lab's trial: joint and camera noise, trigger delay"))
    sp.add_argument("--dry-run", action="store_true", help="check and print the plan, move nothing")
    sp.add_argument("--robot-ip", help="ur-rtde: the UR controller's address")
    sp.add_argument("--move-to-start", action="store_true",
                    help="ur-rtde: moveJ slowly to the start posture if the arm is not there (else refuse)")

    sp = add("calib-clip", cmd_calib_clip, "virtual lab: film the ChArUco board for intrinsics -> calib/")
    sp.add_argument("--campaign", required=True, help=campaign_help)
    sp.add_argument("--out", required=True, help="folder to write the board's frames to (data/<campaign>/calib)")
    sp.add_argument("--seed", default=0, help=seed_help.format("the board's poses and the camera's noise"))

    sp = add("campaign", cmd_campaign, "the whole loop on the virtual lab until the tip hits")
    sp.add_argument("name", help="campaign name: data/<name>/ and results/<name>/")
    sp.add_argument("--string", default="1", help="string type id from the config")
    sp.add_argument("--target", default="1", help="target id from the config")
    sp.add_argument("--max-executions", default=5, help="stop after this many executions without a hit")
    sp.add_argument("--cores", default=2, help="CPU cores Snakemake runs the jobs on")
    sp.add_argument("--seed", default=0, help="seed of the campaign (campaign.yaml) and of the virtual lab's "
                                              "noise in each execution")
    sp.add_argument("--root", default=".", help="project folder holding Snakefile, data/ and results/")
    sp.add_argument("--method", choices=list(METHOD_CONFIGS), default="paper",
                    help="paper: the config as given (config/config.yaml: the paper's method); ours: "
                         "config/ours.yaml merged over it, after any --config")

    sp = add("settings", cmd_settings, "print the settings the stages would run with (the merged config over "
                                       "the defaults), as YAML")
    sp.add_argument("--markdown", action="store_true",
                    help="print every setting's default and meaning as Markdown tables instead (config/README.md)")


def main(argv: list[str] | None = None) -> int:
    from stringcast.core import ConfigError, DataError, JointLimitError

    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except (DataError, ConfigError, JointLimitError) as exc:
        print(f"stringcast {args.command}: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
