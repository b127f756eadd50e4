"""The command line: every option says what it is and shows its default; --method picks the config."""
import argparse
import os
import re
from pathlib import Path

import pytest
import yaml

from stringcast_lab.campaign import campaign_config
from stringcast.cli import build_parser, campaign_config_paths
from stringcast.core import DEFAULT_CONFIG, PAPER_CONFIG, Settings, load_config
from stringcast.core.settings import settings_from_config

ROOT = Path(__file__).resolve().parents[1]


def _subcommands(parser: argparse.ArgumentParser) -> argparse._SubParsersAction:
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))


def test_every_subcommand_and_option_has_help_and_shows_its_default(capsys):
    parser = build_parser()
    sub = _subcommands(parser)
    listed = {a.dest: a.help for a in sub._choices_actions}
    assert set(listed) == set(sub.choices) and all(h and h.strip() for h in listed.values()), listed
    assert all(a.help and a.help.strip() for a in parser._actions), "top-level options"
    for name, sp in sub.choices.items():
        with pytest.raises(SystemExit) as e:
            parser.parse_args([name, "--help"])
        assert e.value.code == 0
        text = " ".join(capsys.readouterr().out.split())  # argparse wraps lines
        for action in sp._actions:
            assert action.help and action.help.strip(), f"stringcast {name} {action.dest}: no help"
            assert " ".join(action.help.split()) in text, (name, action.dest)
            for opt in action.option_strings:
                assert opt in text, (name, opt)
            if not action.required and action.default not in (None, argparse.SUPPRESS):
                assert f"(default: {action.default})" in text, (name, action.dest)


def _leaves(doc: dict, prefix=()):
    for k, v in doc.items():
        if isinstance(v, dict):
            yield from _leaves(v, prefix + (k,))
        else:
            yield prefix + (k,), v


def test_ours_is_the_default_and_method_paper_merges_config_paper_yaml_last():
    parser = build_parser()
    for command in (["campaign", "c"], ["next", "data/c/trial_1"]):
        assert parser.parse_args(command).method == "ours"
    args = parser.parse_args(["campaign", "c"])
    assert campaign_config_paths(args) == []
    args = parser.parse_args(["--config", "mine.yaml", "campaign", "c", "--method", "paper"])
    assert campaign_config_paths(args) == ["mine.yaml", str(PAPER_CONFIG)]
    assert PAPER_CONFIG == ROOT / "config" / "paper.yaml"

    args = parser.parse_args(["campaign", "c", "--method", "paper"])
    config, given = campaign_config(ROOT, campaign_config_paths(args))
    assert given == [PAPER_CONFIG.resolve()]   # what Snakemake gets as --configfile
    ours = load_config(DEFAULT_CONFIG)
    paper = yaml.safe_load(PAPER_CONFIG.read_text())
    for path, value in _leaves(paper):
        got = config
        for k in path:
            got = got[k]
        assert got == value, path
    s_paper, s_ours = settings_from_config(config), settings_from_config(ours)
    assert s_ours == Settings()                   # ours: the defaults, config.yaml sets none
    # the paper's method as the paper wrote it: eqs. (2)-(3), Table 2's ranges, w = 0.1, Section V
    assert (s_paper.estimation.optimizer, s_paper.evaluation.w, s_paper.motion.planner) == \
        ("random_search", 0.1, "paper")
    assert s_paper.model.ranges["k_ph"] == (1e-3, 1e-2) and s_paper.model.ranges["c_ph"] == (1e-3, 1e-2)
    assert (s_paper.motion.replan_miss_mm, s_paper.motion.residual_correction) == (0.0, False)
    # everything paper.yaml does not set is ours
    assert config["targets"] == ours["targets"] and s_ours.model.ranges["k_s"] == s_paper.model.ranges["k_s"]
    assert s_ours.tracking == s_paper.tracking and s_ours.model.ranges["k_ph"] != s_paper.model.ranges["k_ph"]
    config_ours, given_ours = campaign_config(ROOT, campaign_config_paths(parser.parse_args(["campaign", "c"])))
    assert given_ours == [] and {k: v for k, v in config_ours.items() if k != "_path"} == \
        {k: v for k, v in ours.items() if k != "_path"}


def test_config_readme_lists_every_setting_as_the_code_defines_it():
    """config/README.md's reference (below its mark) is what ``stringcast settings --markdown``
    prints: every setting with the default that core.settings holds, and each stage's sections."""
    from stringcast.core import REFERENCE_MARK, settings_reference
    from stringcast.core import SECTION_CLASSES, markdown_table

    text = (Path(__file__).resolve().parents[1] / "config" / "README.md").read_text()
    assert REFERENCE_MARK in text, "config/README.md lacks the generated reference: run stringcast settings --markdown"
    assert text[text.index(REFERENCE_MARK):].strip() == settings_reference(markdown_table()).strip()
    for c in SECTION_CLASSES:
        assert f"### `{c.SECTION}`" in text


def test_jobs_read_the_config_files_the_workflow_names(tmp_path, monkeypatch):
    """Without --config a job reads $STRINGCAST_CONFIG (set by the workflow's shell prefix),
    so the rules' command lines carry no config path; --config, when given, wins."""
    from stringcast.cli import CONFIG_ENV, config_paths

    parser = build_parser()
    monkeypatch.setenv(CONFIG_ENV, f"a.yaml{os.pathsep}b.yaml")
    assert config_paths(parser.parse_args(["settings"])) == ["a.yaml", "b.yaml"]
    assert config_paths(parser.parse_args(["--config", "c.yaml", "settings"])) == ["c.yaml"]
    monkeypatch.delenv(CONFIG_ENV)
    assert config_paths(parser.parse_args(["settings"])) is None


def test_each_config_gives_its_own_settings_in_one_process(tmp_path):
    """The CLI builds the settings once per set of config files, not once per process: a second
    call with another file must not reuse the first call's settings."""
    from stringcast.cli import _settings, build_parser
    from stringcast.plan import run_first_plan

    mine = tmp_path / "mine.yaml"
    mine.write_text(yaml.safe_dump({"motion": {"flight_window_s": 0.7}}))
    parser = build_parser()
    paper = _settings(run_first_plan, parser.parse_args(["--config", str(DEFAULT_CONFIG), "settings"]))
    other = _settings(run_first_plan, parser.parse_args(["--config", str(DEFAULT_CONFIG), "--config", str(mine),
                                                         "settings"]))
    assert paper["motion"].flight_window_s == 0.5 and other["motion"].flight_window_s == 0.7


def test_stage_progress_prints_each_stage_start_and_end_from_snakemake_lines():
    """``stringcast campaign``'s live lines: a stage's start, then its end with its own seconds and
    the step count; stages side by side timed apart; ``all`` and other lines not printed."""
    import io

    from stringcast_lab.campaign import StageProgress

    out = io.StringIO()
    p = StageProgress("campaign c, trial 1", out)
    lines = ["Building DAG of jobs...", "rule decode:", "    input: data/c/trial_1/video.mkv", "    jobid: 3",
             "rule calibrate:", "    jobid: 5", "Finished jobid: 5 (Rule: calibrate)", "1 of 3 steps (33%) done",
             "Finished jobid: 3 (Rule: decode)", "2 of 3 steps (67%) done",
             "sync: warn: the video's offset is uncertain -> results/c/trial_1/sync.json", "localrule all:", "    jobid: 0",
             "Finished jobid: 0 (Rule: all)", "3 of 3 steps (100%) done"]
    for line in lines:
        p.feed(line + "\n")
    shown = out.getvalue().splitlines()
    assert shown[:2] == ["[campaign c, trial 1] decode ...", "[campaign c, trial 1] calibrate ..."]
    assert re.fullmatch(r"\[campaign c, trial 1\] calibrate done, \d+\.\d s \(1/3\)", shown[2])
    assert re.fullmatch(r"\[campaign c, trial 1\] decode done, \d+\.\d s \(2/3\)", shown[3])
    assert shown[4] == "[campaign c, trial 1]   sync: warn: the video's offset is uncertain -> results/c/trial_1/sync.json"
    assert len(shown) == 5 and p.tail[-1] == "3 of 3 steps (100%) done"


def test_calibrate_refuses_campaign_intrinsics_without_their_views(tmp_path, capsys):
    """`calibrate --intrinsics` without the views they were fitted to is an error naming the file (exit 2),
    not intrinsics silently dropped."""
    from stringcast.cli import main

    code = main(["calibrate", "--video", str(tmp_path / "trial_1" / "video.mkv"), "--joints",
                 str(tmp_path / "trial_1" / "joints.csv"), "--intrinsics", str(tmp_path / "intrinsics.json"),
                 "--campaign", str(tmp_path / "campaign.yaml"), "--out", str(tmp_path / "calibration.json")])
    err = capsys.readouterr().err
    assert code == 2 and "intrinsics.json: campaign intrinsics need the views" in err
    assert not (tmp_path / "calibration.json").exists()


def test_a_job_log_takes_the_output_and_the_terminal_gets_the_error_line(tmp_path, capfd):
    """With --log (the workflow's rules) the error line reaches the terminal as well, naming the log; the
    streams are given back after the command."""
    from stringcast.cli import main

    log = tmp_path / "logs" / "calibrate_1.log"
    code = main(["--log", str(log), "calibrate", "--video", str(tmp_path / "trial_1" / "video.mkv"),
                 "--joints", str(tmp_path / "trial_1" / "joints.csv"), "--intrinsics",
                 str(tmp_path / "intrinsics.json"), "--campaign", str(tmp_path / "campaign.yaml"),
                 "--out", str(tmp_path / "calibration.json")])
    out, err = capfd.readouterr()
    assert code == 2 and out == ""
    assert err.strip() == (f"stringcast calibrate: error: {tmp_path / 'intrinsics.json'}: campaign intrinsics need "
                           f"the views they were fitted to (--calib-views or a --calib-dir folder) (log: {log})")
    assert "campaign intrinsics need the views" in log.read_text()
    print("streams back")
    assert capfd.readouterr().out == "streams back\n"


def test_an_internal_error_is_one_line_on_the_terminal_and_a_traceback_in_the_log(tmp_path, capfd, monkeypatch):
    import stringcast.cli as cli

    def broken(args):
        raise ZeroDivisionError("a bug")

    monkeypatch.setitem(cli.HANDLERS, "settings", broken)
    log = tmp_path / "settings.log"
    assert cli.main(["--log", str(log), "settings"]) == 1
    _, err = capfd.readouterr()
    assert err.strip() == (f"stringcast settings: internal error: ZeroDivisionError: a bug\n  (unexpected: not an input "
                           f"error stringcast knows; the traceback is in the log) (log: {log})")
    assert "Traceback (most recent call last)" in log.read_text() and "Traceback" not in err


def test_a_stage_prints_its_verdict_line_with_its_first_reason(capfd, tmp_path):
    from stringcast.cli import JobLog, _verdict_line
    from stringcast.core import Verdict

    import stringcast.cli as cli

    log = tmp_path / "x.log"
    cli._LOG = JobLog(str(log))
    try:
        _verdict_line("sync", Verdict().add("warn", "first reason").add("ok", "second"), "offset 0.1 s", "sync.json")
        _verdict_line("sync", Verdict(), "offset 0.1 s", "sync.json")
        _verdict_line("fit", Verdict().add("fail", "worse than the hand"), "E", "p.json", note="likely cause model")
    finally:
        cli._LOG.close()
        cli._LOG = JobLog()
    _, err = capfd.readouterr()
    assert err.splitlines() == ["sync: warn: first reason (+1 more reasons in the log) -> sync.json",
                                "sync: ok: offset 0.1 s -> sync.json",
                                "fit: fail, likely cause model: worse than the hand -> p.json"]
    from stringcast_lab.campaign import _JOB_LINE

    assert all(_JOB_LINE.match(line) for line in err.splitlines())
    assert "  warn: second" in log.read_text()
