"""Shared fixtures: the project's config, a resolved demo campaign, a tiny lab clip."""
import copy
import dataclasses
import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from stringcast.core import PAPER_CONFIG, load_config, load_yaml, merge_config, resolve_campaign
from stringcast.core.settings import settings_from_config

ROOT = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent
LAB_USERS = ("stringcast_lab", "tiny_lab_trial", "lab_project", "small_camera_config")
"""What a test module names when it films or runs the virtual lab (the ``lab`` extra)."""


def _lab_installed() -> bool:
    try:
        import stringcast_lab  # noqa: F401
    except ImportError:
        return False
    return True


# A core install (``pip install stringcast``, no lab extra: ``make test-core``) runs every test module
# that does not use the virtual lab.
collect_ignore = [] if _lab_installed() else sorted(
    str(p.relative_to(HERE)) for p in HERE.rglob("test_*.py") if any(w in p.read_text() for w in LAB_USERS))
# the real camera data: $STRINGCAST_REAL_DATA, else ../shared/real beside the clone
SHARED_REAL = Path(os.environ.get("STRINGCAST_REAL_DATA", ROOT.parent / "shared" / "real"))


def pytest_configure(config):
    """pytest-xdist hands out ``--dist loadfile``'s files largest test count first unless told not
    to (``--no-loadscope-reorder``); that order would undo :func:`pytest_collection_modifyitems`'s,
    and left the Slurm test's file (four tests, three minutes) to the end of ``make test``."""
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False


def pytest_collection_modifyitems(config, items):
    """Files with a slow test first, each file's tests in their order: under ``make test``'s
    ``-n 2 --dist loadfile`` a file is one worker's unit of work, handed out in collection order
    (:func:`pytest_configure`), and the long ones handed out first let the two workers finish
    together (longest processing time first) instead of one running the workflow's files alone at
    the end."""
    slow = {item.path for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: item.path not in slow)           # stable: files stay contiguous


@pytest.fixture(scope="session")
def config():
    return load_config(ROOT / "config" / "config.yaml")


@pytest.fixture(scope="session")
def campaign(config):
    return resolve_campaign({"string": 1, "target": 1}, config, "test")


def small_camera_config(config: dict, name: str) -> dict:
    """A copy of config whose default set-up films with a 768 x 768, 500 fps mono camera ``name``
    (the lab's lens scaled to it) and a coarse, quickly settled string: arm stills for the
    calibration tests."""
    import copy

    cfg = copy.deepcopy({k: v for k, v in config.items() if k != "_path"})
    cfg["cameras"][name] = {"width_px": 768, "height_px": 768, "fps": 500.0, "bit_depth": 8, "mono": True}
    cfg["setups"]["default"]["camera"] = name
    cfg["lab"] = dict(cfg["lab"], links_per_point=2, settle_s=0.1)
    cfg["lab"]["camera"] = dict(cfg["lab"]["camera"], focal_px=1390.0 * 768 / 1024)
    return cfg


def tiny_lab_trial(tmp_path, config, bands=None, view_up_mm=0.0):
    """A 0.35 s lab clip (320 x 240 px, 1.3 mm per px, 87 frames) of a 150 mm string of 5 points swung
    by the wrist, with ``lab.string_bands`` = bands (None: a plain string); calibrated
    and synced (the config's settings, sync ``method: trigger``). ``view_up_mm``: the camera and
    the board moved up by this much (110 mm: the string's lower part leaves the image's bottom
    edge). Writes ``campaign.yaml`` and ``config.yaml`` (the campaign's, whole) in ``tmp_path`` for the
    command line. Returns (trial folder, results folder, campaign, config)."""
    import copy

    lab = pytest.importorskip("stringcast_lab")
    from stringcast.core.arm import hand_pose
    from stringcast.calibrate.calibration import run_calibration
    from stringcast.core import resolve_campaign
    from stringcast.sync.offset import run_sync

    cfg = copy.deepcopy(config)
    q0 = np.array([0.2, -0.4, -0.3])
    g = hand_pose(resolve_campaign({"string": 1, "target": 1}, cfg, "t").arm, q0)[:2] * 1000
    cfg["cameras"]["tiny"] = {"width_px": 320, "height_px": 240, "fps": 250.0, "bit_depth": 8, "mono": True}
    cfg["lab"] = dict(cfg.get("lab", {}), links_per_point=2, settle_s=0.1, trigger_error_s=0.0)
    if bands:
        cfg["lab"]["string_bands"] = bands
    cfg["lab"]["camera"] = dict(cfg["lab"].get("camera", {}), focal_px=1900.0, center_mm=[g[0] + 60, g[1] - 90 + view_up_mm])
    doc = {"string": {"length_mm": 150.0, "n_points": 5, "weights": [], "stiff_sections": []},
           "target": {"x_mm": g[0] + 150, "y_mm": g[1] + 10, "radius_mm": 20.0}, "allow_reachable": True,
           "setup": {"camera": "tiny", "board": {"squares_x": 5, "squares_y": 4, "square_mm": 40.0,
                                                 "marker_mm": 30.0, "dictionary": "DICT_4X4_50"},
                     "board_origin_mm": [g[0] + 60, g[1] - 80 + view_up_mm], "board_angle_deg": 0.0, "board_flip_y": True}}
    campaign = resolve_campaign(doc, cfg, "tiny")
    from stringcast.core import write_yaml   # the campaign and its config as files, for the command line
    write_yaml(tmp_path / "campaign.yaml", doc)
    write_yaml(tmp_path / "config.yaml", {k: v for k, v in cfg.items() if k != "_path"})
    rate, T = 500.0, 0.16
    sw = 0.5 * (1 - np.cos(np.pi * np.arange(0, T, 1 / rate) / T))
    q = np.repeat(q0[None], len(sw), 0)
    q[:, 2] -= 0.35 * sw
    q_cmd = np.concatenate([np.repeat(q0[None], 60, 0), q, np.repeat(q[-1:], 60, 0)])
    trial, res = tmp_path / "trial_1", tmp_path / "res"
    lab.run_trial(np.arange(len(q_cmd)) / rate, q_cmd, campaign, cfg, trial, seed=3, motion_start_s=0.12)
    st = settings_from_config(config)
    run_calibration(trial, None, campaign, res / "calibration.json", board_check=st.board_check)
    run_sync(trial, res / "calibration.json", campaign, res / "sync.json",
             sync=dataclasses.replace(st.sync, method="trigger"), board_check=st.board_check)
    return trial, res, campaign, cfg


@pytest.fixture(scope="session")
def settings(config):
    """Every stage's settings (:class:`stringcast.core.Settings`) of the paper's method: the project's
    config with ``config/paper.yaml`` over it. The stages' unit tests exercise the paper's algorithms
    (the random search of eq. 3, the Section V planner) on it; ours' settings (the defaults) are
    tested where they differ, by the tests that name them, and end to end by the workflow's tests."""
    return settings_from_config(merge_config(copy.deepcopy(config), load_yaml(PAPER_CONFIG)))


def random_frames(n, h=40, w=56, dtype=np.uint8, seed=0):
    """n random (h, w) frames of ``dtype`` (the video tests' footage)."""
    rng = np.random.default_rng(seed)
    hi = 255 if dtype == np.uint8 else 65535
    return [rng.integers(0, hi, (h, w)).astype(dtype) for _ in range(n)]


def write_ffv1(path, frames, fps=500.0):
    """``frames`` (grey, 8- or 16-bit) as a lossless FFV1 video at ``path``."""
    h, w = frames[0].shape
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), fps, (w, h), isColor=False)
    assert vw.isOpened()
    for f in frames:
        vw.write(f)
    vw.release()
