"""The ``stringcast`` command line's arguments: one subparser per subcommand (:mod:`stringcast.cli` runs them).

Every option says what it is and shows its default (``tests/test_cli.py`` checks both).
"""
from __future__ import annotations

import argparse

from stringcast.core import METHOD_CONFIGS
from stringcast.core import INPUT_HELP, INPUTS, add_input_options


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows each option's default after its help, except where it has none (required, or None)."""

    def _get_help_string(self, action):
        if action.required or action.default is None:
            return action.help
        return super()._get_help_string(action)


def build_parser(handlers: dict, description: str) -> argparse.ArgumentParser:
    """The ``stringcast`` command line; ``handlers`` maps each subcommand to its function (``args -> None``)."""
    p = argparse.ArgumentParser(prog="stringcast", description=description,
                                formatter_class=_HelpFormatter)
    p.add_argument("--config", action="append", default=None,
                   help="config YAML (default: config/config.yaml); given again, each file is merged over the ones "
                        "before it, as Snakemake merges --configfile over the Snakefile's configfile")
    p.add_argument("--log", default=None,
                   help="write everything the command prints to this file, and only its verdict or error line to "
                        "the terminal (the workflow's rules: results/<campaign>/logs/<rule>_<k>.log)")
    sub = p.add_subparsers(dest="command", required=True, help="the stage or tool to run")

    def add(name, help_):
        sp = sub.add_parser(name, help=help_, description=help_, formatter_class=_HelpFormatter)
        sp.set_defaults(func=handlers[name])
        if name in INPUTS:
            add_input_options(sp, name)
        return sp

    _add_analysis_commands(add)
    _add_planning_and_tools(add)
    return p


CAMPAIGN_HELP = INPUT_HELP["campaign"]
SEED_HELP = "random seed of {}"


def _add_analysis_commands(add) -> None:
    """decode, calib-views, calibrate, sync, sweep, track, estimate, predict: one trial's analysis, stage by
    stage (the rules call them). Their input files' options come from :data:`stringcast.core.ports.INPUTS`."""
    sp = add("decode", "decode the trial's video once -> frames.npy (+ frames.json), read by sync, "
                       "sweep and track")
    sp.add_argument("--out", required=True, help="frames.npy to write: (F, H, W) grey frames")

    sp = add("calib-views", "find the ChArUco board's views in a campaign's calib/ once -> calib_views.npz")
    sp.add_argument("--out", required=True, help="calib_views.npz to write (the views' corners, for calibrate)")
    sp.add_argument("--out-intrinsics", help="intrinsics.json to write as well: the views' own intrinsics, fitted "
                                             "and judged once for every trial's calibrate")

    sp = add("calibrate", "ChArUco calibration of one trial -> calibration.json")
    sp.add_argument("--calib-dir", help="data/<campaign>/calib/: ChArUco clip or views for the camera intrinsics; "
                                        "if not given or not a folder, the board's homography only")
    sp.add_argument("--out", required=True, help="calibration.json to write (intrinsics, board pose, px errors)")

    sp = add("sync", "video-to-controller clock offset -> sync.json")
    sp.add_argument("--out", required=True, help="sync.json to write (offset in s: controller time of frame 0)")
    sp.add_argument("--workers", default=1, help="processes matching frames side by side (with --frames)")

    sp = add("sweep", "the mapping and the clock refined by the arm's sweep -> geometry.json, clock.json")
    sp.add_argument("--out-geometry", required=True, help="geometry.json to write (calibration.json's schema, refined)")
    sp.add_argument("--out-clock", required=True, help="clock.json to write (sync.json's schema, the offset corrected)")
    sp.add_argument("--workers", default=1, help="processes reading the frames' link rows side by side")

    sp = add("track", "markerless tracking -> tracks.parquet, tracking.json")
    sp.add_argument("--out", required=True, help="tracks.parquet to write: frame, t_s, point, x_m, y_m, valid "
                                                 "(m, robot frame; point 0 the grasp)")
    sp.add_argument("--out-quality", help="tracking.json to write: the tracking's self-measures and verdict "
                                          "(default: beside --out)")
    sp.add_argument("--overlay", help="tracking_overlay.png to write (tracked points on frames); "
                                      "if not given, none")
    sp.add_argument("--workers", default=1, help="processes tracking frames side by side (with --frames)")

    sp = add("estimate", "fit the model's parameters -> params.json, fit.parquet")
    sp.add_argument("--trial", required=True, help="trial index k = executions so far (M of eq. 3)")
    sp.add_argument("--out-params", required=True, help="params.json to write: coefficients, masses, E in mm")
    sp.add_argument("--out-fit", required=True, help="fit.parquet to write: tracked and simulated points per "
                                                     "frame (m)")

    sp = add("predict", "the previous trial's estimate predicting this trial's tip -> prediction.json")
    sp.add_argument("--out", required=True, help="prediction.json to write: the tip's error, mm (median, p95), "
                                                 "frames compared, verdict")


def _add_planning_and_tools(add) -> None:
    """plan-first, plan, the reports, and the tools around the workflow (execute, calib-clip,
    campaign, settings)."""
    campaign_help, seed_help = CAMPAIGN_HELP, SEED_HELP
    plan_seed_help = seed_help.format("the planner's search (beside the config's motion.seed)")

    sp = add("plan-first", "first motion with Table 2's minimum parameters")
    sp.add_argument("--out-dir", required=True, help="folder for motion.csv (t_s, q1_rad ..) and motion.json")
    sp.add_argument("--seed", default=0, help=plan_seed_help)

    sp = add("plan", "next motion from estimated parameters (--tracks and --joints: motion.residual_correction)")
    sp.add_argument("--out-dir", required=True, help="folder for the next motion's motion.csv and motion.json")
    sp.add_argument("--seed", default=0, help=plan_seed_help)

    sp = add("report-trial", "self-contained HTML page for one trial")
    sp.add_argument("--out", required=True, help="report.html to write")

    sp = add("report-campaign", "campaign page: one row per execution")
    sp.add_argument("--data-dir", required=True, help="data/<campaign>")
    sp.add_argument("--results-dir", required=True, help="results/<campaign>")
    sp.add_argument("--out", required=True, help="report.html to write")

    sp = add("execute", "play a motion file on an arm and record the next trial's raw files")
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

    sp = add("calib-clip", "virtual lab: film the ChArUco board for intrinsics -> calib/")
    sp.add_argument("--campaign", required=True, help=campaign_help)
    sp.add_argument("--out", required=True, help="folder to write the board's frames to (data/<campaign>/calib)")
    sp.add_argument("--seed", default=0, help=seed_help.format("the board's poses and the camera's noise"))

    sp = add("campaign", "the whole loop on the virtual lab until the tip hits")
    sp.add_argument("name", help="campaign name: data/<name>/ and results/<name>/")
    sp.add_argument("--string", default="1", help="string type id from the config")
    sp.add_argument("--target", default="1", help="target id from the config")
    sp.add_argument("--max-executions", default=5, help="stop after this many executions without a hit")
    sp.add_argument("--cores", default=2, help="CPU cores Snakemake runs the jobs on")
    sp.add_argument("--seed", default=0, help="seed of the campaign (campaign.yaml) and of the virtual lab's "
                                              "noise in each execution")
    sp.add_argument("--root", default=".", help="project folder holding Snakefile, data/ and results/")
    sp.add_argument("--method", choices=list(METHOD_CONFIGS), default="ours",
                    help="ours: the config as given (ours is the settings' defaults); paper: the paper's method, "
                         "config/paper.yaml merged over it, after any --config")

    sp = add("next", "one trial's stages in this process, in the workflow's order, to its next motion.csv: "
                     "decode, calibrate, sync, sweep, track, estimate, predict, plan, reports (the same files "
                     "and logs as the workflow's rules)")
    sp.add_argument("trial_dir", help="<project>/data/<campaign>/trial_<k>: the trial just played and filmed; "
                                      "results go to <project>/results/<campaign>/trial_<k>/")
    sp.add_argument("--method", choices=list(METHOD_CONFIGS), default="ours",
                    help="ours: the config as given; paper: config/paper.yaml merged over it, after any --config. "
                         "The config, as the workflow reads it: <project>/config/config.yaml, then each --config")

    sp = add("check", "check every raw file of a campaign before any decode (campaign.yaml, calib/, each "
                      "trial's video header, video.yaml, joints.csv, motion.csv, motion.json): one line per "
                      "problem, exit status 2 on any error")
    sp.add_argument("campaign_dir", help="data/<campaign>: the campaign's folder (campaign.yaml, calib/, trial_<k>/)")

    sp = add("settings", "print the settings the stages would run with (the merged config over "
                                       "the defaults), as YAML")
    sp.add_argument("--markdown", action="store_true",
                    help="print every setting's default and meaning as Markdown tables instead (config/README.md)")
