"""What each stage reads: its inputs, by their one name, where each lives, and how it is passed.

The contract between the workflow's rules, the command line and ``stringcast next``: a stage's
input ``geometry`` is the rule's ``input.geometry``, the option ``--geometry``, the file
``results/<campaign>/trial_<k>/geometry.json`` and the stage function's parameter ``geometry``
(where the command's handler does not pass it itself). From :data:`INPUTS`:

* :func:`add_input_options` declares a subcommand's options (``stringcast.cli_parser``);
* :func:`stage_inputs` hands a stage function the inputs its handler left unbound, by name
  (``stringcast.cli``);
* :func:`input_argv` writes the options for one trial (``stringcast.chain``, as the rules do);
* ``tests/workflow/test_rules.py`` checks that each rule passes exactly its command's inputs,
  each under its own name.

So a stage gets a new input by three edits: the rule (declare it and pass ``--<name>``), the
stage (a parameter of that name) and :data:`INPUTS` here (``docs/data_contract.md`` lists the
files). The raw files' names are :class:`~stringcast.core.files.TrialFiles`'s.
"""
from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

TRIAL_RESULT = "results/{campaign}/trial_{trial}/"
"""A trial's products' folder (``{trial}``: k, or k - 1 for an input from the previous trial)."""

PRODUCT_FILES: dict[str, str] = {
    "campaign": "data/{campaign}/campaign.yaml",
    "calib_dir": "data/{campaign}/calib",
    "calib_views": "results/{campaign}/calib_views.npz",
    "intrinsics": "results/{campaign}/intrinsics.json",
    "frames": TRIAL_RESULT + "frames.npy",
    "calibration": TRIAL_RESULT + "calibration.json",
    "sync": TRIAL_RESULT + "sync.json",
    "geometry": TRIAL_RESULT + "geometry.json",
    "clock": TRIAL_RESULT + "clock.json",
    "tracks": TRIAL_RESULT + "tracks.parquet",
    "tracking": TRIAL_RESULT + "tracking.json",
    "params": TRIAL_RESULT + "params.json",
    "fit": TRIAL_RESULT + "fit.parquet",
    "prediction": TRIAL_RESULT + "prediction.json",
    "next_motion": TRIAL_RESULT + "motion.csv",
    "next_motion_meta": TRIAL_RESULT + "motion.json",
}
"""Each product's file, relative to the project root, by its one name (the rules' patterns)."""

RAW_FILES = {"video": "video", "joints": "joints", "video_meta": "video_meta", "played_motion": "played"}
"""The trial's raw files: their names here, and the :class:`~stringcast.core.files.TrialFiles` field
that finds each in ``data/<campaign>/trial_<k>``."""

INPUT_HELP = {
    "video": "the trial's video: video.<ext>, a video/ folder of frames, or video.cihx (docs/data_contract.md)",
    "joints": "the trial's joints.csv (t_s, q1_rad .. qJ_rad)",
    "video_meta": "the trial's video.yaml (fps, frames, trigger_time_s)",
    "played_motion": "motion.json of the motion played in this trial",
    "campaign": "data/<campaign>/campaign.yaml: the campaign's string, target, arm and set-up",
    "calib_dir": "data/<campaign>/calib/: ChArUco clip or images",
    "calib_views": "the campaign's calib_views.npz (its board views, found once); read instead of searching the "
                   "calib folder",
    "intrinsics": "the campaign's intrinsics.json (fitted to those views once by the calib_views rule); read "
                  "instead of refitting them (the same result)",
    "frames": "the trial's frames.npy (`stringcast decode`), read instead of decoding the video",
    "calibration": "the trial's calibration.json",
    "sync": "the trial's sync.json",
    "geometry": "the trial's geometry.json (or calibration.json)",
    "clock": "the trial's clock.json (or sync.json)",
    "tracks": "the trial's tracks.parquet",
    "tracking": "the trial's tracking.json",
    "params": "the trial's params.json (the estimate)",
    "fit": "the trial's fit.parquet",
    "prediction": "the trial's prediction.json (the previous estimate's check on this motion); none for trial 1",
    "next_motion": "the trial's next motion.csv",
    "next_motion_meta": "the trial's next motion's motion.json",
}
"""Each input's help line."""


@dataclass(frozen=True)
class Port:
    """One input of a subcommand.

    Attributes:
        name: the rule's input name, the option (``--`` + name with ``-`` for ``_``) and the stage
            parameter it binds; a product of :data:`PRODUCT_FILES` or :data:`RAW_FILES` unless ``product`` says which.
        optional: the option takes no file where there is none (``nargs="?"``: the rule passes
            ``--<name> {input.<name>:q}``, empty for trial 1 or a campaign without ``calib/``).
        previous: the file is the previous trial's (k - 1), not this trial's.
        product: the product's name, where the input's own name differs (estimate's ``prev``).
        help: the option's help; default :data:`INPUT_HELP` of the product.
    """

    name: str
    optional: bool = False
    previous: bool = False
    product: str = ""
    help: str = ""

    @property
    def flag(self) -> str:
        """The command line option, ``--video-meta`` for ``video_meta``."""
        return "--" + self.name.replace("_", "-")

    @property
    def of(self) -> str:
        """The product this input is (its :data:`PRODUCT_FILES` or :data:`RAW_FILES` key)."""
        return self.product or self.name

    @property
    def text(self) -> str:
        """The option's help line."""
        return self.help or INPUT_HELP[self.of]


def _ports(*names: str, optional: tuple[str, ...] = (), **special: Port) -> tuple[Port, ...]:
    return tuple(special.get(n) or Port(n, optional=n in optional) for n in names)


_PREV = Port("prev", optional=True, previous=True, product="params",
             help="previous trial's params.json (chi_best of eq. 3); none for trial 1")

INPUTS: dict[str, tuple[Port, ...]] = {
    "decode": _ports("video"),
    "calib-views": _ports("calib_dir", "campaign"),
    "calibrate": _ports("video", "joints", "calib_views", "intrinsics", "campaign",
                        optional=("calib_views", "intrinsics")),
    "sync": _ports("video", "video_meta", "joints", "calibration", "campaign", "frames", optional=("frames",)),
    "sweep": _ports("video", "joints", "calibration", "sync", "campaign", "frames", optional=("frames",)),
    "track": _ports("video", "joints", "geometry", "clock", "campaign", "frames", optional=("frames",)),
    "estimate": _ports("tracks", "joints", "campaign", "prev", "geometry", "clock", "tracking", prev=_PREV),
    "predict": _ports("params", "tracks", "joints", "campaign", params=Port(
        "params", previous=True, help="the previous trial's params.json (the estimate that predicts)")),
    "plan-first": _ports("campaign"),
    "plan": _ports("params", "played_motion", "tracks", "joints", "campaign", optional=("tracks", "joints"),
                   played_motion=Port("played_motion", help="motion.json of the motion just played")),
    "report-trial": _ports("video", "joints", "played_motion", "geometry", "clock", "tracks", "tracking", "params",
                           "fit", "next_motion", "next_motion_meta", "prediction", "campaign",
                           optional=("prediction",)),
    "report-campaign": _ports("campaign"),
}
"""Each workflow subcommand's inputs, in the order its rule passes them."""


def add_input_options(parser, command: str) -> None:
    """Declare ``command``'s inputs (:data:`INPUTS`) on its argparse subparser: required, or
    ``nargs="?"`` where optional."""
    for port in INPUTS[command]:
        if port.optional:
            parser.add_argument(port.flag, nargs="?", help=port.text)
        else:
            parser.add_argument(port.flag, required=True, help=port.text)


def stage_inputs(func: Callable, command: str, args, bound: Mapping) -> dict[str, Path | None]:
    """The inputs of ``command`` that ``func`` takes by name and its handler left unbound.

    Args:
        func: the stage function. args: the parsed command line. bound: the arguments the
            handler passes (:meth:`inspect.Signature.bind_partial`'s ``arguments``).

    Returns:
        ``{name: Path or None}`` to pass as keywords (None: an optional input not given).
    """
    params = inspect.signature(func).parameters
    out = {}
    for port in INPUTS.get(command, ()):
        if port.name in params and port.name not in bound:
            value = getattr(args, port.name, None)
            out[port.name] = Path(value) if value else None
    return out


def trial_inputs(campaign: str, k: int, raw, has_calib: bool) -> dict[str, str | None]:
    """Every input's path for trial ``k`` of ``campaign``, relative to the project root, as the
    workflow's rules name them; None where the rule passes none (no previous trial, no ``calib/``).

    Args:
        raw: the trial's :class:`~stringcast.core.files.TrialFiles` (its video found by name).
    """
    paths: dict[str, str | None] = {name: str(getattr(raw, field)) for name, field in RAW_FILES.items()}
    for name, pattern in PRODUCT_FILES.items():
        paths[name] = pattern.format(campaign=campaign, trial=k)
    if k > 1:
        paths.update({f"previous {n}": pattern.format(campaign=campaign, trial=k - 1) for n, pattern in PRODUCT_FILES.items()})
    else:
        paths["prediction"] = None
    if not has_calib:
        paths["calib_views"] = paths["intrinsics"] = None
    return paths


def input_argv(command: str, paths: Mapping[str, str | None]) -> tuple[str, ...]:
    """``command``'s input options for the files in ``paths`` (:func:`trial_inputs`): ``--<name> <path>``,
    an optional input without a file as its bare option (as the rule's empty ``{input.<name>:q}``).

    Raises:
        KeyError: a required input has no path in ``paths``.
    """
    argv: list[str] = []
    for port in INPUTS[command]:
        path = paths.get(f"previous {port.of}" if port.previous else port.of)
        if path is None and not port.optional:
            raise KeyError(f"{command}: no file for its input {port.name!r}")
        argv += [port.flag] + ([path] if path is not None else [])
    return tuple(argv)
