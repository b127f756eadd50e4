"""What produced a result: the method, the code and the libraries (the reports' footer).

:func:`provenance` gives, for the merged config a stage ran with (``load_config``'s dict):

* ``method``: ``the paper's method`` when the config equals ``config/config.yaml``'s,
  ``ours`` when it equals ``config/config.yaml`` with ``config/ours.yaml`` merged over it
  (``stringcast campaign --method ours``), else ``custom config <digest>``;
* ``config_digest``: the first 12 hex digits of the SHA-256 of the config's canonical JSON
  (keys sorted, no spaces; ``_path``, which only names the files read, left out);

both compare the lab's sections as they are and every stage's settings as
:func:`~stringcast.core.settings_from_config` builds them, every default filled in: a file that
sets a setting to its default means the same config as one that leaves it out.
* ``commit``: ``git rev-parse HEAD`` of the project's checkout, with ``-dirty`` when
  ``git status --porcelain`` shows changes to tracked files; ``unknown`` when the code
  is not a git checkout (an installed package) or git cannot say;
* ``versions``: stringcast's and the main libraries' (``importlib.metadata``).
"""
from __future__ import annotations

import functools
import hashlib
import json
import subprocess
from importlib import metadata
from pathlib import Path
from typing import Mapping

from stringcast import __version__
from stringcast.core import (DEFAULT_CONFIG, OURS_CONFIG, SECTION_CLASSES, ConfigError, load_config,
                             settings_from_config)

PROJECT_ROOT = DEFAULT_CONFIG.parents[1]
"""The project folder of this code (holding ``config/``), as for ``DEFAULT_CONFIG``."""

LIBRARIES: dict[str, tuple[str, ...]] = {
    "numpy": ("numpy",), "numba": ("numba",), "scipy": ("scipy",),
    "opencv": ("opencv-contrib-python-headless", "opencv-contrib-python", "opencv-python-headless", "opencv-python"),
    "pandas": ("pandas",), "snakemake": ("snakemake",), "mujoco": ("mujoco",), "cma": ("cma",),
}
"""Library name as shown -> the distributions that provide it (the first installed one counts)."""


def _canonical(config: Mapping) -> dict:
    """The config's lab sections (``_path`` left out) and each stage's settings with its defaults."""
    sections = {c.SECTION for c in SECTION_CLASSES}
    settings = settings_from_config(config)
    return {**{k: v for k, v in config.items() if k != "_path" and k not in sections},
            **{s: getattr(settings, s).as_dict() for s in sorted(sections)}}


def config_digest(config: Mapping) -> str:
    """First 12 hex digits of the SHA-256 of the config's canonical JSON (module doc)."""
    text = json.dumps(_canonical(config), sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def method(config: Mapping) -> str:
    """``the paper's method``, ``ours`` or ``custom config <digest>`` (module doc)."""
    canonical = _canonical(config)
    try:
        if canonical == _canonical(load_config(DEFAULT_CONFIG)):
            return "the paper's method"
        if canonical == _canonical(load_config([DEFAULT_CONFIG, OURS_CONFIG])):
            return "ours"
    except ConfigError:  # no config/ beside the code (an installed package): nothing to compare with
        pass
    return f"custom config {config_digest(config)}"


def _git(root: Path, *args: str) -> str:
    return subprocess.run(["git", "--no-optional-locks", *args], cwd=root, capture_output=True, text=True,
                          check=True, timeout=30).stdout.strip()


@functools.cache
def git_commit(root: Path = PROJECT_ROOT) -> str:
    """The checkout's HEAD commit, ``-dirty`` if tracked files changed; ``unknown`` outside a checkout."""
    root = Path(root)
    try:
        # the code's own checkout only, not one that happens to hold it (a venv inside a project)
        if Path(_git(root, "rev-parse", "--show-toplevel")).resolve() != root.resolve():
            return "unknown"
        head = _git(root, "rev-parse", "HEAD")
        dirty = _git(root, "status", "--porcelain", "--untracked-files=no")
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return head + ("-dirty" if dirty else "")


@functools.cache
def library_versions() -> dict[str, str]:
    """stringcast's version and each of :data:`LIBRARIES`' (``not installed`` where absent)."""
    out = {"stringcast": __version__}
    for name, dists in LIBRARIES.items():
        out[name] = "not installed"
        for dist in dists:
            try:
                out[name] = metadata.version(dist)
                break
            except metadata.PackageNotFoundError:
                continue
    return out


def provenance(config: Mapping) -> dict:
    """``{"method", "config_digest", "commit", "versions"}`` for a merged config (module doc)."""
    return {"method": method(config), "config_digest": config_digest(config), "commit": git_commit(),
            "versions": dict(library_versions())}
