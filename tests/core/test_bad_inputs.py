"""Bad input gets a clear DataError naming the file and the problem; no half-written output.

Covers issue 3's list: unreadable or truncated video, no board / too few corners, a frame
count that disagrees with video.yaml, non-monotonic or NaN joint times, a joint log that
does not cover the video.
"""
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from stringcast.calibrate.calibration import run_calibration
from stringcast.core.files import DataError, read_video_meta
from stringcast.core.joint_log import check_joint_coverage, check_joint_header, read_joint_table
from stringcast.video.container import check_frame_count, open_video


def _write_mkv(path, frames, fps=500.0):
    h, w = frames[0].shape
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), fps, (w, h), isColor=False)
    for f in frames:
        vw.write(f)
    vw.release()


def _board_image(campaign, width=640, height=480):
    """The campaign's ChArUco board drawn on a white (H, W) uint8 image."""
    b = campaign.setup.board
    img = campaign.setup.board.make().generateImage((int(b.squares_x * 60), int(b.squares_y * 60)), marginSize=0)
    canvas = np.full((height, width), 255, np.uint8)
    y0, x0 = (height - img.shape[0]) // 2, (width - img.shape[1]) // 2
    assert y0 >= 0 and x0 >= 0, "board image larger than the canvas"
    canvas[y0:y0 + img.shape[0], x0:x0 + img.shape[1]] = img
    return canvas, (x0, y0)


def _calibrate(settings, *args):
    """run_calibration(*args) with the project's settings."""
    return run_calibration(*args, board_check=settings.board_check)


def _no_output(trial, out_json):
    assert not out_json.exists()
    assert not [p.name for p in out_json.parent.iterdir() if p.name.startswith(f".{out_json.name}")]


@pytest.mark.parametrize("content", [b"", b"\x1aE\xdf\xa3 not really matroska" * 40])
def test_unreadable_video_stops_calibration_and_writes_nothing(tmp_path, campaign, settings, content):
    (tmp_path / "video.mkv").write_bytes(content)
    out = tmp_path / "calibration.json"
    with pytest.raises(DataError, match="video.mkv"):
        _calibrate(settings, tmp_path, None, campaign, out)
    _no_output(tmp_path, out)


def test_blank_video_no_board_found(tmp_path, campaign, settings):
    _write_mkv(tmp_path / "video.mkv", [np.full((240, 320), 128, np.uint8)] * 5)
    out = tmp_path / "calibration.json"
    with pytest.raises(DataError, match=r"video.mkv.*no ChArUco board found.*needs >= \d+"):
        _calibrate(settings, tmp_path, None, campaign, out)
    _no_output(tmp_path, out)


def test_board_mostly_hidden_too_few_corners(tmp_path, campaign, settings):
    img, (x0, y0) = _board_image(campaign)
    hidden = img.copy()
    hidden[:, x0 + 150:] = 255  # only the left 2.5 squares' columns stay visible ...
    hidden[y0 + 150:, :] = 255  # ... and the top 2.5 rows: at most 4 inner corners
    _write_mkv(tmp_path / "video.mkv", [hidden] * 3)
    out = tmp_path / "calibration.json"
    with pytest.raises(DataError, match=r"video.mkv.*only \d board corners found"):
        _calibrate(settings, tmp_path, None, campaign, out)
    _no_output(tmp_path, out)
    # the whole board in the same clip calibrates: the failure above was the hidden board
    _write_mkv(tmp_path / "video.mkv", [img] * 3)
    _calibrate(settings, tmp_path, None, campaign, out)
    assert out.exists()


def test_calibration_views_without_board(tmp_path, campaign, settings):
    img, _ = _board_image(campaign)
    _write_mkv(tmp_path / "video.mkv", [img] * 3)
    calib = tmp_path / "calib"
    calib.mkdir()
    for i in range(4):
        cv2.imwrite(str(calib / f"view_{i}.png"), np.full((480, 640), 40 * i, np.uint8))
    out = tmp_path / "calibration.json"
    with pytest.raises(DataError, match=r"calib.*board was found in 0 views"):
        _calibrate(settings, tmp_path, calib, campaign, out)
    _no_output(tmp_path, out)


def test_truncated_videos(tmp_path):
    """A container, a TIFF stack and a Photron file that end before their announced count."""
    tifffile = pytest.importorskip("tifffile")
    from stringcast.video.photron import write_photron

    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 255, (48, 64)).astype(np.uint8) for _ in range(30)]
    _write_mkv(tmp_path / "full.mkv", frames)
    data = (tmp_path / "full.mkv").read_bytes()
    (tmp_path / "cut.mkv").write_bytes(data[: int(len(data) * 0.6)])
    with pytest.raises(DataError, match=r"cut.mkv: truncated or corrupt: frame \d+ of 30"):
        for _ in open_video(tmp_path / "cut.mkv"):
            pass
    tifffile.imwrite(tmp_path / "full.tif", np.stack(frames[:6]), photometric="minisblack")
    data = (tmp_path / "full.tif").read_bytes()
    (tmp_path / "cut.tif").write_bytes(data[: len(data) // 2])
    with pytest.raises(DataError, match=r"cut.tif: truncated"):
        open_video(tmp_path / "cut.tif")
    cihx = write_photron(tmp_path / "cut.cihx", frames[:6], fps=1000.0, color_bit=8)
    mraw = cihx.with_suffix(".mraw")
    mraw.write_bytes(mraw.read_bytes()[:-1])
    with pytest.raises(DataError, match=r"cut.mraw: truncated: .* 5 of the 6 frames"):
        open_video(cihx)


def test_frame_count_disagrees_with_video_yaml(tmp_path):
    _write_mkv(tmp_path / "video.mkv", [np.zeros((24, 32), np.uint8)] * 10, fps=500.0)
    yml = tmp_path / "video.yaml"
    v = open_video(tmp_path / "video.mkv")
    yml.write_text("fps: 500\nframes: 10\nwidth_px: 32\nheight_px: 24\n")
    assert check_frame_count(v, read_video_meta(yml), yml) == []
    yml.write_text("fps: 500\nframes: 12\n")
    with pytest.raises(DataError, match=r"video.yaml: frames: 12, but the video .*video.mkv has 10 frames \(-2\)"):
        check_frame_count(v, read_video_meta(yml), yml)
    yml.write_text("fps: 500\nframes: 10\nwidth_px: 64\n")
    with pytest.raises(DataError, match=r"video.yaml: width_px: 64, but .* is 32x24 px"):
        check_frame_count(v, read_video_meta(yml), yml)
    yml.write_text("fps: 250\nframes: 10\n")
    (warning,) = check_frame_count(v, read_video_meta(yml), yml)
    assert "fps 250" in warning and "500" in warning


@pytest.mark.parametrize("body,msg", [
    ("t_s,q1_rad,q2_rad\n0,0,0\n0.004,0,0\n0.002,0,0\n", r"t_s is not strictly increasing at row 4 \(0.004 then 0.002\)"),
    ("t_s,q1_rad,q2_rad\n0,0,0\nnan,0,0\n0.004,0,0\n", r"NaN or infinite values in 1 rows \(first at row 3\)"),
    ("t_s,q1_rad,q2_rad\n0,0,0\n0.002,inf,0\n", r"NaN or infinite values"),
    ("t_s,q1_rad,q2_rad\n0,0,0\n0.002,,0\n", r"NaN or infinite values"),  # an empty cell
])
def test_bad_joint_times_named(tmp_path, body, msg):
    p = tmp_path / "joints.csv"
    p.write_text(body)
    with pytest.raises(DataError, match=r"joints.csv: " + msg):
        read_joint_table(p)


def test_joint_log_must_cover_the_video(tmp_path):
    p = tmp_path / "joints.csv"
    t_j = np.arange(0.0, 1.0 + 1e-9, 0.002)
    check_joint_coverage(t_j, 0.01 + np.arange(400) / 500.0, p)  # 0.01 .. 0.808 s: covered
    check_joint_coverage(t_j, np.arange(-0.001, 1.0015, 0.002), p)  # within one joint period
    with pytest.raises(DataError, match=r"joints.csv: the joint log spans 0.0000 .. 1.0000 s but the video frames "
                                        r"span 0.5000 .. 1.4980 s.*0.4980 s after it"):
        check_joint_coverage(t_j, 0.5 + np.arange(500) / 500.0, p)
    with pytest.raises(DataError, match=r"span -0.2000 .. 0.7980 s.*0.2000 s before it"):
        check_joint_coverage(t_j, -0.2 + np.arange(500) / 500.0, p)
    with pytest.raises(DataError, match=r"before it and .* after it"):
        check_joint_coverage(t_j[100:200], np.arange(500) / 500.0, p)


def test_joint_log_missing_a_joint_column_names_file_and_columns(tmp_path, campaign):
    """A joints.csv without q2_rad is the arm's missing column, not a one-joint arm that fails later."""
    p = tmp_path / "joints.csv"
    p.write_text("t_s,q1_rad,q3_rad,q1_cmd_rad\n0,0,0,0\n0.002,0,0,0\n")
    arm = campaign.arm
    msg = (f"{p}: missing columns q2_rad (the arm {arm.name} has 3 joints: q1_rad, q2_rad, q3_rad)")
    with pytest.raises(DataError) as e:
        read_joint_table(p, n_joints=arm.n_joints, arm_name=arm.name)
    assert str(e.value) == msg
    with pytest.raises(DataError) as e:   # the header alone, as the workflow checks it before any job
        check_joint_header(p, arm.n_joints, arm.name)
    assert str(e.value) == msg
    p.write_text("t_s,q1_rad,q2_rad,q3_rad,q4_rad\n0,0,0,0,0\n0.002,0,0,0,0\n")
    with pytest.raises(DataError, match=r"joints.csv: joint columns q4_rad beyond the arm's \(the arm "):
        read_joint_table(p, n_joints=arm.n_joints, arm_name=arm.name)
    p.write_text("t_s,q1_rad,q2_rad,q3_rad\n0,0,0,0\n0.002,0,0,0\n")
    check_joint_header(p, arm.n_joints, arm.name)
    assert read_joint_table(p, n_joints=arm.n_joints, arm_name=arm.name)[1].shape == (2, 3)


def test_workflow_refuses_a_joint_log_missing_a_column_before_any_job(tmp_path):
    """snakemake -n names the trial's joints.csv and the missing column before any job, plans the
    refusal that ends the run non-zero, and no job of the campaign; fixed, the campaign is planned."""
    root_repo = Path(__file__).resolve().parents[2]
    (tmp_path / "Snakefile").symlink_to(root_repo / "Snakefile")
    (tmp_path / "workflow").symlink_to(root_repo / "workflow")
    (tmp_path / "config").mkdir()
    (tmp_path / "config" / "config.yaml").write_text((root_repo / "config" / "config.yaml").read_text())
    for k, header in ((1, "t_s,q1_rad,q2_rad,q3_rad"), (2, "t_s,q1_rad,q3_rad")):
        t = tmp_path / "data" / "c" / f"trial_{k}"
        t.mkdir(parents=True)
        (t / "joints.csv").write_text(f"{header}\n" + ",".join(["0"] * (header.count(",") + 1)) + "\n")
        (t / "video.yaml").write_text("fps: 500\nframes: 1\n")
        (t / "video.mkv").touch()
        (t / "motion.json").touch()
    (tmp_path / "data" / "c" / "campaign.yaml").write_text("string: 1\ntarget: 1\n")
    proc = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--cores", "1"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    out = proc.stdout + proc.stderr
    assert "stringcast: data/c is not built" in out, out[-2000:]
    assert ("data/c/trial_2/joints.csv: missing columns q2_rad (the arm ur5e_planar has 3 joints: "
            "q1_rad, q2_rad, q3_rad)") in out, out[-2000:]
    assert "refused_campaigns" in out and "rule decode" not in out and "rule plan_first" not in out
