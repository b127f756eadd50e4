"""``stringcast check data/<c>``: one bad input at a time in a small good campaign made here.

Each case breaks one thing and requires: the exit status (2 on an error, 0 on warnings only), a line
naming the file and the field or value, no traceback, and every raw file unchanged, nothing written.
"""
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from raw_campaign import Q0, RATE, good_campaign, write_board_image, write_joints, write_video
from stringcast.cli import main

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "config" / "config.yaml"


def snapshot(root: Path) -> dict:
    """Every file under root with its SHA-256 (and every folder): what a read-only check leaves."""
    return {str(p.relative_to(root)): (hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir")
            for p in sorted(root.rglob("*"))}


def run_check(c: Path, capsys, config=(CONFIG,)) -> tuple[int, str]:
    argv = [a for cfg in config for a in ("--config", str(cfg))] + ["check", str(c)]
    code = main(argv)
    out = capsys.readouterr()
    return code, out.out + out.err


# --- the breakages: each a function of the campaign folder c ------------------------------------
def _write(rel, text):
    return lambda c: (c / rel).write_text(text)


def _yaml_line(rel, old, new):
    def f(c):
        p = c / rel
        assert old in p.read_text()
        p.write_text(p.read_text().replace(old, new))
    return f


def _joints_text(edit):
    """Edit trial_1/joints.csv's lines: edit(lines) -> lines."""
    def f(c):
        p = c / "trial_1" / "joints.csv"
        p.write_text("\n".join(edit(p.read_text().splitlines())) + "\n")
    return f


def _set_cell(row, col, value):
    def edit(lines):
        cells = lines[row].split(",")
        cells[col] = value
        lines[row] = ",".join(cells)
        return lines
    return _joints_text(edit)


def _joints_in_degrees(c):
    write_joints(c / "trial_1" / "joints.csv", q=np.degrees(np.repeat(Q0[None], 51, 0)))


def _joints_beyond_limits(c):
    q = np.repeat(Q0[None], 51, 0)
    q[20:, 1] = -3.0   # q2's minimum is -150 deg (-2.618 rad)
    write_joints(c / "trial_1" / "joints.csv", q=q)


def _joints_in_ms(c):
    write_joints(c / "trial_1" / "joints.csv", t=np.arange(51) * 2.0)


def _log_ends_moving_before_video(c):
    t = np.arange(51) / RATE
    q = np.repeat(Q0[None], 51, 0)
    q[:, 0] += 1.0 * t                  # 57 deg/s: a third of the speed limit, to the log's end
    write_joints(c / "trial_1" / "joints.csv", q=q, t=t)
    _yaml_line("trial_1/video.yaml", "trigger_time_s: 0.01", "trigger_time_s: 0.2")(c)


def _motion_csv_off_clock(c):
    write_joints(c / "trial_1" / "motion.csv", t=np.arange(51) * 0.004)


def _motion_beyond_limits(c):
    q = np.repeat(Q0[None], 51, 0)
    q[:, 2] = -2.7                      # q3's minimum is -150 deg (-2.618 rad)
    write_joints(c / "trial_1" / "motion.csv", q=q)


def _second_video(c):
    write_video(c / "trial_1" / "video.avi")


def _no_video(c):
    (c / "trial_1" / "video.mkv").unlink()


def _corrupt(rel, data):
    return lambda c: (c / rel).write_bytes(data)


def _cut_png(c):
    p = c / "calib" / "board_1.png"
    p.write_bytes(p.read_bytes()[:-20])


def _gap(c):
    (c / "trial_1").rename(c / "trial_2")


def _unlink(rel):
    return lambda c: (c / rel).unlink()


SETUP = ("setup: {{camera: highspeed_1024, board_origin_mm: [780, -340], board: {{squares_x: {sx}, squares_y: 6, "
         "square_mm: 60, marker_mm: {m}, dictionary: {d}}}}}\n")

# (id, breakage, exit status, [what the output must hold])
CASES = [
    ("campaign-bad-yaml", _write("campaign.yaml", "string: 1\ntarget: [1\n"), 2,
     ["campaign.yaml: line 2: not valid YAML", "never closed?"]),
    ("campaign-not-a-mapping", _write("campaign.yaml", "- 1\n- 1\n"), 2,
     ["campaign.yaml: [1, 1]: expected a mapping with keys string and target, got a list"]),
    ("campaign-unknown-key", _write("campaign.yaml", "string: 1\ntarget: 1\ntagret: 2\n"), 2,
     ["campaign.yaml: tagret: unknown key: a typo of 'target'?"]),
    ("campaign-unknown-string-id", _write("campaign.yaml", "string: 99\ntarget: 1\n"), 2,
     ["campaign.yaml: string: 99: unknown string id"]),
    ("campaign-5000mm-string-10-points", _write("campaign.yaml", "string: {length_mm: 5000, n_points: 10}\n"
                                                                 "target: 1\n"), 2,
     ["campaign.yaml: string/n_points: 10: 5000 mm / 10 points puts them 500.0 mm apart", "148 or more points"]),
    ("campaign-stiff-section-off-string", _write("campaign.yaml", "string: {length_mm: 300, n_points: 10, "
                                                                  "stiff_sections: [{from_mm: 250, to_mm: 350}]}\n"
                                                                  "target: 1\n"), 2,
     ["campaign.yaml: string/stiff_sections/0: 250..350 mm: reaches past the string's end"]),
    ("campaign-weight-off-string", _write("campaign.yaml", "string: {length_mm: 300, n_points: 10, "
                                                           "weights: [{at_mm: 400}]}\ntarget: 1\n"), 2,
     ["campaign.yaml: string/weights/0/at_mm: 400: off the string (0..300 mm"]),
    ("campaign-missing-target", _write("campaign.yaml", "string: 1\n"), 2,
     ["campaign.yaml: target: missing: a required key"]),
    ("campaign-target-within-reach", _write("campaign.yaml", "string: 1\ntarget: {x_mm: 500, y_mm: 0}\n"), 2,
     ["campaign.yaml: target/x_mm: 500: target x = 500 mm is within the grasp's reach"]),
    ("campaign-board-marker-not-below-square", _write("campaign.yaml", "string: 1\ntarget: 1\n"
                                                      + SETUP.format(sx=9, m=60, d="DICT_5X5_100")), 2,
     ["campaign.yaml: setup/board/marker_mm: 60: marker_mm 60 must be smaller than square_mm 60"]),
    ("campaign-board-unknown-dictionary", _write("campaign.yaml", "string: 1\ntarget: 1\n"
                                                 + SETUP.format(sx=9, m=45, d="DICT_5x5_100")), 2,
     ["campaign.yaml: setup/board/dictionary: DICT_5x5_100: unknown ArUco dictionary", "did you mean DICT_5X5_100"]),
    ("campaign-board-dictionary-too-small", _write("campaign.yaml", "string: 1\ntarget: 1\n"
                                                   + SETUP.format(sx=20, m=45, d="DICT_5X5_50")), 2,
     ["campaign.yaml: setup/board/dictionary: DICT_5X5_50: a 20 x 6 board has 60 markers, but DICT_5X5_50 holds "
      "only 50"]),
    ("video-yaml-fps-0", _yaml_line("trial_1/video.yaml", "fps: 500.0", "fps: 0"), 2,
     ["trial_1/video.yaml: fps: 0: must be > 0"]),
    ("video-yaml-fps-negative", _yaml_line("trial_1/video.yaml", "fps: 500.0", "fps: -500"), 2,
     ["trial_1/video.yaml: fps: -500: must be > 0"]),
    ("video-yaml-fps-100000", _yaml_line("trial_1/video.yaml", "fps: 500.0", "fps: 100000"), 2,
     ["trial_1/video.yaml: fps: 100000: the video", "says 500 fps (200 x)", "fps_note"]),
    ("video-yaml-fps-missing", _yaml_line("trial_1/video.yaml", "fps: 500.0\n", ""), 2,
     ["trial_1/video.yaml: fps: missing: a required key"]),
    ("video-yaml-frames-wrong", _yaml_line("trial_1/video.yaml", "frames: 10", "frames: 12"), 2,
     ["trial_1/video.yaml: frames: 12: the video", "has 10 frames (-2)"]),
    ("video-yaml-width-wrong", _yaml_line("trial_1/video.yaml", "width_px: 32", "width_px: 64"), 2,
     ["trial_1/video.yaml: width_px: 64: the video", "is 32x24 px"]),
    ("video-yaml-not-a-mapping", _write("trial_1/video.yaml", "500\n"), 2,
     ["trial_1/video.yaml: 500: expected a mapping with fps and frames, got a number"]),
    ("video-yaml-missing", _unlink("trial_1/video.yaml"), 2, ["trial_1/video.yaml: file not found"]),
    ("two-videos", _second_video, 2,
     ["trial_1: video: 2 videos: video.avi, video.mkv; the workflow reads video.avi"]),
    ("no-video", _no_video, 2, ["trial_1: no video (expected video.mkv/.avi/.mp4"]),
    ("video-empty-file", _corrupt("trial_1/video.mkv", b""), 2, ["trial_1/video.mkv: empty file"]),
    ("video-corrupt", _corrupt("trial_1/video.mkv", b"\x1aE\xdf\xa3 not really matroska" * 40), 2,
     ["trial_1/video.mkv: not a video OpenCV can open"]),
    ("joints-in-degrees", _joints_in_degrees, 2, ["trial_1/joints.csv: q1_rad..q3_rad: -22.9183", "degrees?"]),
    ("joints-nan-row", _set_cell(5, 2, "nan"), 2,
     ["trial_1/joints.csv: NaN or infinite values in 1 rows (first at row 6)"]),
    ("joints-t-not-increasing", _set_cell(5, 0, "0.001"), 2,
     ["trial_1/joints.csv: t_s is not strictly increasing at row 6"]),
    ("joints-missing-column", _joints_text(lambda ls: [",".join(x.split(",")[:3]) for x in ls]), 2,
     ["trial_1/joints.csv: missing columns q3_rad (the arm ur5e_planar has 3 joints"]),
    ("joints-extra-joint-column", _joints_text(lambda ls: [ls[0] + ",q4_rad"] + [x + ",0" for x in ls[1:]]), 2,
     ["trial_1/joints.csv: joint columns q4_rad beyond the arm's"]),
    ("joints-empty", _write("trial_1/joints.csv", ""), 2, ["trial_1/joints.csv: not a readable CSV file: it is empty"]),
    ("joints-header-only", _write("trial_1/joints.csv", "t_s,q1_rad,q2_rad,q3_rad\n"), 2,
     ["trial_1/joints.csv: fewer than two rows"]),
    ("joints-text-in-number", _set_cell(2, 2, "abc"), 2,
     ["trial_1/joints.csv: row 3, column q2_rad: 'abc' is not a number"]),
    ("joints-beyond-limits", _joints_beyond_limits, 2,
     ["trial_1/joints.csv: q2_rad: -3: 31 rows beyond arm ur5e_planar's limits -150..150 deg"]),
    ("joints-t-in-ms", _joints_in_ms, 2, ["trial_1/joints.csv: t_s: one row per 2 s", "t_s in milliseconds?"]),
    ("joints-log-ends-before-video-moving", _log_ends_moving_before_video, 2,
     ["trial_1/joints.csv: t_s: the joint log spans 0.0000 .. 0.1000 s but the video frames span 0.2000 .. 0.2180 s",
      "the log ends with the arm moving"]),
    ("motion-json-missing", _unlink("trial_1/motion.json"), 2, ["trial_1/motion.json: file not found"]),
    ("motion-csv-missing", _unlink("trial_1/motion.csv"), 2, ["trial_1/motion.csv: file not found"]),
    ("motion-csv-malformed", _write("trial_1/motion.csv", "t_s;q1_rad;q2_rad;q3_rad\n0;0.2;-0.4;-0.3\n"), 2,
     ["trial_1/motion.csv: no 't_s' column in header", "separated by ';'?"]),
    ("motion-csv-off-the-controller-clock", _motion_csv_off_clock, 2,
     ["trial_1/motion.csv: t_s: t_s must step by the controller period 2.000 ms"]),
    ("motion-csv-beyond-limits", _motion_beyond_limits, 2, ["trial_1/motion.csv: q3_rad: -2.7: 51 rows beyond"]),
    ("motion-json-malformed", _write("trial_1/motion.json", "{\"T_s\": 0.1,"), 2,
     ["trial_1/motion.json: not valid JSON"]),
    ("motion-json-wrong-joints", _write("trial_1/motion.json", json.dumps(
        {"T_s": 0.1, "q0_rad": [0.1, 0.2], "control_points_rad_s": [[0.0]] * 2})), 2,
     ["trial_1/motion.json: q0_rad must have 3 values"]),
    ("calib-unreadable-image", _corrupt("calib/board_1.png", b"not an image at all"), 2,
     ["calib/board_1.png: not a PNG image"]),
    ("calib-image-cut-short", _cut_png, 2, ["calib/board_1.png: a PNG cut short"]),
    ("calib-image-other-size", lambda c: write_board_image(c / "calib" / "board_1.png", (48, 48)), 2,
     ["calib/board_1.png: 48x48 px, the other views 64x48 px"]),
    ("trial-numbers-gap", _gap, 2, ["trial_2: no trial_1/joints.csv before it"]),
    ("trial-leading-zero", lambda c: (c / "trial_1").rename(c / "trial_01"), 2,
     ["trial_01: a trial folder is named trial_<k>"]),
    # warnings only: exit status 0
    ("stopped-trial", lambda c: (c / "trial_1" / "joints.csv").rename(c / "trial_1" / "joints.partial.csv"), 0,
     ["warning: ", "trial_1/joints.partial.csv: a stopped trial"]),
    ("stray-video-file", _write("trial_1/video.mkv.bak", "x"), 0,
     ["warning: ", "trial_1/video.mkv.bak: not read (the trial's video is video.mkv)"]),
    ("video-yaml-key-typo", _yaml_line("trial_1/video.yaml", "trigger_time_s:", "trigger_time:"), 0,
     ["warning: ", "trial_1/video.yaml: trigger_time: not a key the stages read: a typo of 'trigger_time_s'?"]),
    ("video-yaml-fps-differs-with-note",
     _yaml_line("trial_1/video.yaml", "fps: 500.0", "fps: 1000.0\nfps_note: the container stores the playback rate"),
     0, ["check: "]),
]


@pytest.mark.parametrize("name,breakage,status,expected", CASES, ids=[c[0] for c in CASES])
def test_a_bad_input_is_named_in_one_line_and_nothing_changes(tmp_path, capsys, name, breakage, status, expected):
    c = good_campaign(tmp_path)
    breakage(c)
    before = snapshot(tmp_path)
    code, out = run_check(c, capsys)
    assert snapshot(tmp_path) == before, "the check changed or wrote a file"
    assert "Traceback" not in out
    assert code == status, out
    for text in expected:
        assert text in out, out
    lines = out.strip().splitlines()
    assert lines[-1].startswith(f"check: {c}: ") and ("ok" in lines[-1] if status == 0 and name.endswith("note")
                                                      else "error" in lines[-1] or "warning" in lines[-1])
    if status == 2:
        assert any(line.startswith("error: ") for line in lines[:-1]), out


def test_the_good_campaign_passes_clean(tmp_path, capsys):
    c = good_campaign(tmp_path, trials=(1, 2))
    before = snapshot(tmp_path)
    code, out = run_check(c, capsys)
    assert (code, out) == (0, f"check: {c}: ok (2 trials)\n")
    assert snapshot(tmp_path) == before


# the field recording from another lab: $STRINGCAST_FIELD_DATA, else ../shared/field beside the clone
FIELD = Path(os.environ.get("STRINGCAST_FIELD_DATA", ROOT.parent / "shared" / "field"))


@pytest.mark.skipif(not (FIELD / "field_1").is_dir(), reason="the field recording (../shared/field) is not here")
def test_the_field_campaign_passes_clean(capsys):
    code, out = run_check(FIELD / "field_1", capsys, config=(CONFIG, FIELD / "lab.yaml"))
    assert (code, out) == (0, f"check: {FIELD / 'field_1'}: ok (1 trial)\n")


def test_every_problem_is_reported_not_only_the_first(tmp_path, capsys):
    """Three files broken at once, in two trials: all three named, each on its own line."""
    c = good_campaign(tmp_path, trials=(1, 2))
    _write("campaign.yaml", "string: 1\ntarget: 1\ntagret: 2\n")(c)
    _yaml_line("trial_1/video.yaml", "frames: 10", "frames: 12")(c)
    _yaml_line("trial_1/video.yaml", "width_px: 32", "width_px: 64")(c)
    write_joints(c / "trial_2" / "joints.csv", q=np.degrees(np.repeat(Q0[None], 51, 0)))
    code, out = run_check(c, capsys)
    assert code == 2
    lines = out.strip().splitlines()
    assert [line.split(": ")[1].split("/")[-1] for line in lines[:-1]] == [
        "campaign.yaml", "video.yaml", "video.yaml", "joints.csv"], out
    assert lines[-1] == f"check: {c}: 4 errors, 0 warnings in 2 trials"


def test_the_check_runs_as_a_command_without_a_traceback(tmp_path):
    """The installed entry point as a user runs it: a bad video.yaml and a joint log in degrees."""
    c = good_campaign(tmp_path)
    _yaml_line("trial_1/video.yaml", "fps: 500.0", "fps: 0")(c)
    _joints_in_degrees(c)
    proc = subprocess.run([sys.executable, "-m", "stringcast.cli", "--config", str(CONFIG), "check", str(c)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr
    assert f"error: {c}/trial_1/video.yaml: fps: 0: must be > 0" in proc.stdout
    assert "degrees?" in proc.stdout
