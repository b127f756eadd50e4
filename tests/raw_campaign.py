"""A small, good campaign's raw files, made here (the check's and the workflow's dry-run tests):
``data/c/campaign.yaml``, ``calib/`` and trials of a tiny FFV1 video with its ``video.yaml``, a joint
log covering it, ``motion.csv`` and ``motion.json``: every file ``stringcast check`` passes."""
import json
from pathlib import Path

import cv2
import numpy as np

from stringcast.core import write_joint_table

Q0 = np.array([0.2, -0.4, -0.3])   # within ur5e_planar's limits (config/config.yaml's first arm)
RATE = 500.0                        # its controller_rate_hz


def write_video(path, n=10, fps=500.0, size=(32, 24)):
    """A tiny FFV1 video (grey noise), as a camera's container holds one."""
    rng = np.random.default_rng(0)
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), fps, size, isColor=False)
    assert vw.isOpened()
    for _ in range(n):
        vw.write(rng.integers(0, 255, (size[1], size[0])).astype(np.uint8))
    vw.release()


def write_joints(path, q=None, t=None):
    """A still arm logged at the controller rate for 0.1 s (t: s, q: (K, 3) rad)."""
    t = np.arange(51) / RATE if t is None else t
    write_joint_table(path, t, np.repeat(Q0[None], len(t), 0) if q is None else q)


def write_board_image(path, size=(64, 48)):
    assert cv2.imwrite(str(path), np.full((size[1], size[0]), 200, np.uint8))


def good_campaign(root: Path, trials=(1,)) -> Path:
    """data/c: campaign.yaml (string 1, target 1), calib/ with three images, and trials each with a
    10-frame 500 fps video, video.yaml, a joint log covering it, motion.csv and motion.json."""
    c = root / "data" / "c"
    (c / "calib").mkdir(parents=True)
    (c / "campaign.yaml").write_text("string: 1\ntarget: 1\n")
    for i in range(3):
        write_board_image(c / "calib" / f"board_{i}.png")
    for k in trials:
        t = c / f"trial_{k}"
        t.mkdir()
        write_video(t / "video.mkv")
        (t / "video.yaml").write_text("fps: 500.0\nframes: 10\ntrigger_time_s: 0.01\nwidth_px: 32\nheight_px: 24\n")
        write_joints(t / "joints.csv")
        write_joints(t / "motion.csv")
        (t / "motion.json").write_text(json.dumps({
            "kind": "first", "T_s": 0.1, "q0_rad": Q0.tolist(), "control_points_rad_s": [[0.0, 0.0]] * 3,
            "controller_rate_hz": RATE, "arm": "ur5e_planar"}))
    return c
