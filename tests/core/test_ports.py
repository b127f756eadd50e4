"""The input contract (stringcast.core.ports): one declaration of a stage's input reaches the
command line, the stage and ``stringcast next``; the rules are checked against it in
tests/workflow/test_rules.py."""
from __future__ import annotations

from pathlib import Path

import pytest

from stringcast.core import TrialFiles, ports


def _trial(tmp_path, monkeypatch, k: int) -> None:
    monkeypatch.chdir(tmp_path)
    for j in range(1, k + 1):
        d = tmp_path / "data" / "c" / f"trial_{j}"
        d.mkdir(parents=True)
        (d / "video.mkv").write_bytes(b"")


def test_a_new_input_reaches_the_parser_the_stage_and_next(tmp_path, monkeypatch):
    """What a maintainer edits to give ``predict`` the previous trial's fit: the contract (here), the
    stage (a parameter ``fit``) and the rule; the parser, the handler and the chain follow."""
    from stringcast.chain import trial_steps
    from stringcast.cli import build_parser

    monkeypatch.setitem(ports.INPUTS, "predict", ports.INPUTS["predict"] + (ports.Port("fit", previous=True),))
    argv = ["predict", "--params", "p.json", "--tracks", "t.parquet", "--joints", "j.csv", "--campaign", "c.yaml",
            "--fit", "f.parquet", "--out", "o.json"]
    args = build_parser().parse_args(argv)
    assert args.fit == "f.parquet"
    with pytest.raises(SystemExit):                       # a required input left out is refused
        build_parser().parse_args([a for a in argv if a not in ("--fit", "f.parquet")])

    def stage(params, tracks, joints, campaign, out, fit=None, *, model=None):
        return fit

    bound = {"params": 1, "tracks": 2, "joints": 3, "campaign": 4, "out": 5}
    assert ports.stage_inputs(stage, "predict", args, bound) == {"fit": Path("f.parquet")}
    assert ports.stage_inputs(stage, "predict", args, {**bound, "fit": 6}) == {}     # the handler's own wins
    assert ports.stage_inputs(lambda params: 0, "predict", args, {}) == {"params": Path("p.json")}

    _trial(tmp_path, monkeypatch, 2)
    predict = next(s for s in trial_steps("c", 2, False, 2) if s.rule == "predict")
    i = predict.argv.index("--fit")
    assert predict.argv[i + 1] == "results/c/trial_1/fit.parquet"                 # previous=True: trial k - 1


def test_optional_inputs_pass_a_bare_option_where_there_is_no_file(tmp_path, monkeypatch):
    """Trial 1 has no previous estimate or prediction, a campaign without calib/ no views: the option
    stays, empty, as the rule's ``{input.<name>:q}`` of an empty input."""
    from stringcast.chain import trial_steps

    _trial(tmp_path, monkeypatch, 1)
    steps = {s.rule: s.argv for s in trial_steps("c", 1, False, 2)}
    est = steps["estimate"]
    assert est[est.index("--prev") + 1].startswith("--")
    cal = steps["calibrate"]
    assert cal[cal.index("--calib-views") + 1] == "--intrinsics" and "calib_views" not in steps
    rep = steps["report_trial"]
    assert rep[rep.index("--prediction") + 1].startswith("--")
    assert rep[rep.index("--video") + 1] == str(TrialFiles.in_folder("data/c/trial_1").video)


def test_input_argv_refuses_a_required_input_without_a_file():
    with pytest.raises(KeyError, match="geometry"):
        ports.input_argv("track", {"video": "v.mkv", "joints": "j.csv", "campaign": "c.yaml"})


def test_every_input_has_a_file_and_a_help_line():
    for command, inputs in ports.INPUTS.items():
        assert len({p.name for p in inputs}) == len(inputs), command
        for p in inputs:
            assert p.of in ports.PRODUCT_FILES or p.of in ports.RAW_FILES, (command, p.name)
            assert p.text, (command, p.name)
