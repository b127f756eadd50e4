"""check_campaign / check_trial as the workflow calls them: one-line problems, never a raise on any
input, never a decoded frame, never the virtual lab."""
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from stringcast.check import Problem, check_campaign, check_trial
from stringcast.core import load_campaign, load_config
from stringcast.video.container import ContainerReader

sys.path.insert(0, str(Path(__file__).parent))
from test_check_cases import CONFIG, good_campaign, snapshot, write_video  # noqa: E402


@pytest.fixture(scope="module")
def config():
    return load_config([CONFIG])


def test_a_problem_is_one_line_with_its_empty_parts_left_out():
    assert str(Problem("a/video.yaml", "fps", "0", "must be > 0", "error")) == "a/video.yaml: fps: 0: must be > 0"
    assert str(Problem("a/trial_1", None, None, "no video", "warn")) == "a/trial_1: no video"
    assert str(Problem("f", "k", None, "two\n  lines", "error")) == "f: k: two lines"
    with pytest.raises(ValueError, match="severity"):
        Problem("f", None, None, "m", "fatal")


def _forbid(*names):
    def refuse(*args, **kwargs):
        raise AssertionError(f"the check decoded frames ({names})")
    return refuse


def test_no_code_path_decodes_the_video(tmp_path, config, monkeypatch):
    """Frame iteration, random reads, a counting pass and the per-frame timestamps (a pass too) are
    never called: a clean campaign, one with wrong frames, and a 2000 fps Matroska file whose count
    only a pass would give exactly (the header's is known to a few frames)."""
    for name in ("__iter__", "read", "_decode_pass"):
        monkeypatch.setattr(ContainerReader, name, _forbid(name))
    monkeypatch.setattr(ContainerReader, "timestamps_s", property(_forbid("timestamps_s")))
    c = good_campaign(tmp_path, trials=(1, 2))
    write_video(c / "trial_2" / "video.mkv", n=300, fps=2000.0)
    (c / "trial_2" / "video.yaml").write_text("fps: 2000\nframes: 300\ntrigger_time_s: 0.01\n")
    assert check_campaign(c, config) == []
    (c / "trial_1" / "video.yaml").write_text("fps: 500\nframes: 11\n")
    (c / "trial_2" / "video.yaml").write_text("fps: 2000\nframes: 320\n")
    found = check_campaign(c, config)
    assert [(Path(p.path).parent.name, p.field, p.value) for p in found] == [
        ("trial_1", "frames", "11"), ("trial_2", "frames", "320")]
    assert "(announced, to 3 frames)" in found[1].message


def _garbage(rng, n):
    return bytes(rng.integers(0, 256, n, dtype=np.uint8))


@pytest.mark.parametrize("seed", range(3))
def test_garbage_in_any_raw_file_is_a_problem_never_a_raise(tmp_path, config, seed):
    """Each raw file in turn replaced by random bytes, text or nothing (seeded): problems, each one
    line and naming the file, and every file left as it was."""
    rng = np.random.default_rng(seed)
    names = ["campaign.yaml", "calib/board_0.png", "trial_1/video.mkv", "trial_1/video.yaml", "trial_1/joints.csv",
             "trial_1/motion.csv", "trial_1/motion.json"]
    contents = [b"", _garbage(rng, 64), _garbage(rng, 4096), b"\xff\xfe" + _garbage(rng, 30),
                b"- [\n", b"{a: 1}\n", b"t_s,q1_rad\n1,2\n", b"nan\n", "\u00e9t\u00e9: 1\n".encode()]
    for i, name in enumerate(names):
        root = tmp_path / f"{i}"
        c = good_campaign(root)
        data = contents[int(rng.integers(len(contents)))]
        (c / name).write_bytes(data)
        before = snapshot(root)
        found = check_campaign(c, config)
        assert snapshot(root) == before
        assert all(isinstance(p, Problem) and "\n" not in str(p) for p in found)
        assert any(p.path.endswith(name) for p in found), (name, data[:20], [str(p) for p in found])
        assert not any("please report" in p.message for p in found), [str(p) for p in found]


@pytest.mark.parametrize("make", ["missing", "file", "campaign-dir"])
def test_a_missing_or_odd_folder_is_a_problem(tmp_path, config, make):
    d = tmp_path / "c"
    if make == "file":
        d.write_text("x")
    elif make == "campaign-dir":
        d.mkdir()
        (d / "campaign.yaml").mkdir()
    found = check_campaign(d, config)
    assert found and all(p.is_error for p in found)
    assert str(d) in str(found[0])


def test_check_trial_with_and_without_the_campaign(tmp_path, config):
    c = good_campaign(tmp_path)
    campaign = load_campaign(c / "campaign.yaml", config)
    assert check_trial(c / "trial_1", campaign, config) == []
    (c / "trial_1" / "joints.csv").write_text("t_s,q1_rad,q2_rad,q3_rad\n0,20,20,20\n0.002,20,20,20\n")
    (found,) = check_trial(c / "trial_1", campaign, config)
    assert found.field == "q1_rad..q3_rad" and "degrees?" in found.message
    assert check_trial(c / "trial_1", None, config) == []   # without the arm: the reader's checks only
    assert check_trial(c / "trial_9", campaign, config)[0].message == "not a folder"


def test_a_broken_campaign_yaml_still_checks_its_trials(tmp_path, config):
    """campaign.yaml's error and a trial's are both named: the arm's checks need only the arm."""
    c = good_campaign(tmp_path)
    (c / "campaign.yaml").write_text("string: 99\ntarget: 1\n")
    (c / "trial_1" / "video.yaml").write_text("fps: 0\nframes: 10\n")
    cv2.imwrite(str(c / "calib" / "board_2.png"), np.zeros((10, 10), np.uint8))
    found = check_campaign(c, config)
    assert [(Path(p.path).name, p.field) for p in found] == [
        ("campaign.yaml", "string"), ("board_2.png", None), ("video.yaml", "fps")]


def test_the_check_loads_neither_the_lab_nor_a_physics_engine(tmp_path):
    c = good_campaign(tmp_path)
    code = ("import sys\nfrom stringcast.core import load_config\nfrom stringcast.check import check_campaign\n"
            f"assert check_campaign({str(c)!r}, load_config([{str(CONFIG)!r}])) == []\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('mujoco', 'elastica', 'numba')"
            " or m.startswith('stringcast_lab')))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
