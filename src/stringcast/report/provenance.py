"""What produced a result: the method, the code and the libraries (the reports' footer).

:func:`provenance` gives, for the settings the stages ran with (:class:`~stringcast.core.Settings`):

* ``method``: ``ours`` when they are the defaults (``config/config.yaml`` sets none), ``the
  paper's method`` when they are ``config/paper.yaml``'s (``--method paper``), else ``custom
  settings <digest>``. A file that sets a setting to its default means
  the same method as one that leaves it out, and what only the virtual lab reads (``lab``)
  is not part of it;
* ``settings_digest``: :func:`~stringcast.core.settings_digest`, the first 12 hex digits of
  the SHA-256 of every section's settings as canonical JSON;
* ``commit``: ``git rev-parse HEAD`` of the project's checkout, with ``-dirty`` when
  ``git status --porcelain`` shows changes to tracked files; ``unknown`` when the code
  is not a git checkout (an installed package) or git cannot say;
* ``versions``: stringcast's and the main libraries' (``importlib.metadata``).
"""
from __future__ import annotations

import functools
import subprocess
from importlib import metadata
from pathlib import Path

from stringcast import __version__
from stringcast.core import (DEFAULT_CONFIG, PAPER_CONFIG, ConfigError, Settings, load_yaml, settings_digest,
                             settings_from_config)

PROJECT_ROOT = DEFAULT_CONFIG.parents[1]
"""The project folder of this code (holding ``config/``), as for ``DEFAULT_CONFIG``."""

LIBRARIES: dict[str, tuple[str, ...]] = {
    "numpy": ("numpy",), "numba": ("numba",), "scipy": ("scipy",),
    "opencv": ("opencv-contrib-python-headless", "opencv-contrib-python", "opencv-python-headless", "opencv-python"),
    "pandas": ("pandas",), "snakemake": ("snakemake",), "mujoco": ("mujoco",), "cma": ("cma",),
}
"""Library name as shown -> the distributions that provide it (the first installed one counts)."""


def method(settings: Settings) -> str:
    """``ours``, ``the paper's method`` or ``custom settings <digest>`` (module doc)."""
    if settings == Settings():
        return "ours"
    try:
        if settings == settings_from_config(load_yaml(PAPER_CONFIG)):
            return "the paper's method"
    except ConfigError:  # no config/ beside the code (an installed package): nothing to compare with
        pass
    return f"custom settings {settings_digest(settings)}"


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


def provenance(settings: Settings) -> dict:
    """``{"method", "settings_digest", "commit", "versions"}`` for the stages' settings (module doc)."""
    return {"method": method(settings), "settings_digest": settings_digest(settings), "commit": git_commit(),
            "versions": dict(library_versions())}
