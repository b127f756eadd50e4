"""Configuration: load and merge ``config/config.yaml`` and the files given over it.

The lab it describes becomes frozen specs in :mod:`.specs`; the stages' settings, frozen
settings objects in :mod:`.settings`. The JSON schema in ``stringcast/core/schemas/config.schema.json`` (also used by the
Snakefile through ``snakemake.utils.validate``) is checked first, so a wrong key
or value stops with a message naming it.

Errors: :class:`ConfigError` (a ``ValueError``) naming the file and the key.
"""
from __future__ import annotations

import copy
import json
import math
from importlib import resources
from pathlib import Path
from typing import Any
from collections.abc import Mapping, Sequence

import numpy as np
import yaml

from .errors import ConfigError
from .settings import PARAM_NAMES, settings_schema


DEFAULT_CONFIG = Path(__file__).resolve().parents[3] / "config" / "config.yaml"
PAPER_CONFIG = DEFAULT_CONFIG.parent / "paper.yaml"
"""The paper's method, as the paper wrote it, merged over the config (ours: the settings' defaults) by
``--method paper``."""
METHOD_CONFIGS: dict[str, tuple[Path, ...]] = {"ours": (), "paper": (PAPER_CONFIG,)}
"""The files each method merges over the config, after any others given."""


def _schema(name: str) -> dict:
    """A packaged JSON schema; ``config.schema.json`` with its stage sections made from the settings
    classes (:func:`.settings.settings_schema`: each setting declared once, there)."""
    schema = json.loads(resources.files("stringcast.core").joinpath("schemas", name).read_text())
    if name == "config.schema.json":
        schema["properties"].update(settings_schema())
    return schema


def schema_problems(doc: Any, schema_name: str, definition: str | None = None) -> list[tuple[str, str]]:
    """Every way ``doc`` breaks a packaged JSON schema, in document order.

    Args:
        doc: the parsed document.
        schema_name: a file in ``stringcast/core/schemas/`` (``campaign.schema.json``, ...).
        definition: check against the schema's ``$defs/<definition>`` instead of the whole schema
            (``config.schema.json``'s ``string``, ``target``, ``setup``: a campaign's inline entries).

    Returns:
        ``[(where, message), ...]``: the JSON path of each error (``"(top level)"`` for the
        document itself) and jsonschema's message, or, where the schema holds, the first number
        that is not finite (YAML's ``.nan``, ``.inf``: JSON Schema's ``number`` takes them, and no
        setting, length or position is one); empty when ``doc`` conforms.
    """
    import jsonschema

    schema = _schema(schema_name)
    if definition is not None:
        schema = {"$defs": schema["$defs"], "$ref": f"#/$defs/{definition}"}
    validator = jsonschema.Draft202012Validator(schema)
    errors = sorted(validator.iter_errors(doc), key=lambda e: list(e.absolute_path))
    out = [("/".join(str(p) for p in e.absolute_path) or "(top level)", e.message) for e in errors]
    bad = None if out else _not_finite(doc)
    return out + ([(bad[0] or "(top level)", f"{bad[1]} is not a finite number")] if bad else [])


def validate(doc: Any, schema_name: str, source: str | Path) -> None:
    """Validate ``doc`` against a packaged JSON schema.

    A number that is not finite (YAML's ``.nan``, ``.inf``; JSON Schema's ``number`` takes them) is
    an error too: no setting, length or position is one.

    Raises:
        ConfigError: naming ``source`` and the JSON path of the first error (:func:`schema_problems`).
    """
    problems = schema_problems(doc, schema_name)
    if problems:
        where, message = problems[0]
        raise ConfigError(f"{source}: at '{where}': {message}")


def _not_finite(doc: Any, where: str = "") -> tuple[str, float] | None:
    """(the path, the value) of the first float in ``doc`` (nested mappings and lists) that is NaN or
    infinite, or None."""
    if isinstance(doc, float):
        return None if math.isfinite(doc) else (where, doc)
    items = doc.items() if isinstance(doc, Mapping) else enumerate(doc) if isinstance(doc, (list, tuple)) else ()
    for k, v in items:
        found = _not_finite(v, f"{where}/{k}" if where else str(k))
        if found is not None:
            return found
    return None


def load_yaml(path: str | Path) -> Any:
    """Read a YAML file. Raises ConfigError naming the file if missing, unreadable, not text or malformed."""
    path = Path(path)
    try:
        with open(path) as f:
            return yaml.safe_load(f)
    except FileNotFoundError as exc:
        raise ConfigError(f"{path}: file not found") from exc
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {exc}") from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not a text file (not UTF-8: {exc.reason} at byte {exc.start})") from exc
    except OSError as exc:
        raise ConfigError(f"{path}: not readable: {exc.strerror or exc}") from exc


def merge_config(into: dict, over: Mapping) -> dict:
    """Merge ``over`` into ``into`` in place, mappings key by key, anything else replaced
    (as Snakemake merges ``--configfile`` over the Snakefile's ``configfile:``). Returns ``into``."""
    for key, value in over.items():
        if isinstance(value, Mapping) and isinstance(into.get(key), dict):
            merge_config(into[key], value)
        else:
            into[key] = copy.deepcopy(value)
    return into


def typed_overrides(overrides: Mapping) -> dict:
    """Snakemake's ``--config KEY=VALUE`` with a YAML value, as the command line gives a section
    (``--config 'evaluation={w: 0.5}'``; its parser takes top-level keys only, refusing
    ``evaluation.w``), typed as a config file would be: Snakemake reads such a value with YAML's
    BaseLoader, which keeps every scalar a string (``{'w': '0.5'}``), so each string inside a
    section is read again as YAML (``0.5``, ``true``, ``[0.3, 0.9]``). Top-level scalars, which
    Snakemake types itself, are kept. Returns a new mapping to merge over the config
    (:func:`merge_config`).
    """
    def typed(value):
        if isinstance(value, Mapping):
            return {k: typed(v) for k, v in value.items()}
        if isinstance(value, list):
            return [typed(v) for v in value]
        if isinstance(value, str):
            try:
                return yaml.safe_load(value)
            except yaml.YAMLError:
                return value
        return value

    return {k: typed(v) if isinstance(v, (Mapping, list)) else v for k, v in dict(overrides or {}).items()}


def load_config(path: str | Path | Sequence | None = None) -> dict:
    """Load and schema-validate the config (default ``config/config.yaml``).

    ``path`` may be several files: each is merged over the ones before it
    (:func:`merge_config`), as Snakemake merges ``--configfile`` files over the
    Snakefile's, and the result is validated.

    Parameters
    ----------
    path : str, Path, or list or tuple of them, optional
        The config file, or files merged in order; None (or empty): ``config/config.yaml``.

    Returns
    -------
    dict
        The merged, validated config, with ``_path`` naming its file(s) (joined by ``" + "``).

    Raises
    ------
    ConfigError
        A missing or malformed file, or a merged config the schema refuses (named).
    """
    paths = [Path(p) for p in path] if isinstance(path, (list, tuple)) else [Path(path) if path else DEFAULT_CONFIG]
    if not paths:
        paths = [DEFAULT_CONFIG]
    doc: dict = {}
    for p in paths:
        part = load_yaml(p)
        if not isinstance(part, Mapping):
            raise ConfigError(f"{p}: a config file must be a mapping of sections")
        merge_config(doc, part)
    source = " + ".join(map(str, paths))
    validate(doc, "config.schema.json", source)
    doc["_path"] = source
    return doc


def model_ranges(model) -> tuple[np.ndarray, np.ndarray, tuple[float, float]]:
    """Table 2 ranges from :class:`~stringcast.core.settings.ModelSettings` ``model``:
    (p_min (10,), p_max (10,), (mu_min, mu_max)).

    Raises:
        ConfigError: a range that is not 0 < min <= max.
    """
    r = model.ranges
    lo = np.array([r[k][0] for k in PARAM_NAMES], float)
    hi = np.array([r[k][1] for k in PARAM_NAMES], float)
    if np.any(lo <= 0) or np.any(hi < lo):
        raise ConfigError("model.ranges: each range must be 0 < min <= max")
    return lo, hi, (float(r["mu"][0]), float(r["mu"][1]))
