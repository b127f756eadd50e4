"""Small project roots for the end-to-end workflow tests (test_workflow.py, test_slurm.py).

A project root links the repo's Snakefile and workflow/ and holds its own config: a 512 x 512
camera at 250 fps with a larger ChArUco board, and small search budgets, so that a campaign's
executions finish in a few minutes on 2 cores.
"""
import copy
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]


def small_config(config: dict) -> dict:
    cfg = copy.deepcopy({k: v for k, v in config.items() if k != "_path"})
    cfg["cameras"]["small"] = {"width_px": 512, "height_px": 512, "fps": 250.0, "bit_depth": 8, "mono": True}
    cfg["setups"]["default"].update(camera="small", board_origin_mm=[700.0, -250.0], board={
        "squares_x": 6, "squares_y": 4, "square_mm": 100.0, "marker_mm": 75.0, "dictionary": "DICT_4X4_50"})
    cfg["lab"]["camera"]["focal_px"] = 695.0
    cfg.setdefault("estimation", {}).update(iterations=256, batch=64)
    cfg.setdefault("motion", {}).update(max_candidates=4096, extra_after_hit=64)
    return cfg


def make_project(root: Path, config: dict) -> Path:
    """A project at ``root`` (created): the repo's Snakefile and workflow/ linked, and
    config/config.yaml = :func:`small_config` of ``config``. Returns ``root``."""
    (root / "config").mkdir(parents=True)
    (root / "Snakefile").symlink_to(ROOT / "Snakefile")
    (root / "workflow").symlink_to(ROOT / "workflow")
    (root / "config" / "config.yaml").write_text(yaml.safe_dump(small_config(config)))
    return root
