"""``campaign.yaml`` checked against the config: its YAML and schema, the ids it names, the string's
points (30-34 mm apart, README), weights and stiff sections on the string, the target beyond the
grasp's reach, and a ChArUco board that can exist.

The specs' own constructors (:class:`~stringcast.core.StringSpec`, :class:`~stringcast.core.ArmSpec`,
:class:`~stringcast.core.SetupSpec`, :meth:`~stringcast.core.BoardSpec.make`) and
:func:`~stringcast.core.target_reach_problem` judge what the stages judge, with their messages; each
entry is built on its own, so that every wrong entry is named, not only the first.
"""
from __future__ import annotations

import difflib
import json
import math
import re
from importlib import resources
from pathlib import Path
from typing import Any
from collections.abc import Mapping

from stringcast.core import (NO_TARGET, ArmSpec, BoardSpec, Campaign, ConfigError, SetupSpec, StringSpec, TargetSpec, load_yaml,
                             resolve_campaign, schema_problems, target_reach_problem)
from .problem import Problem, from_error, kind_of, guarded_with, problem, show

SPACING_MM = (30.0, 34.0)
"""The model's points lie this far apart along the string, mm: length_mm / n_points (README)."""

ENTRIES = (("string", "strings"), ("target", "targets"), ("arm", "arms"), ("setup", "setups"))
"""``campaign.yaml``'s keys that name a config entry, and the config's table of them."""


def _schema(schema_name: str) -> dict:
    """A packaged JSON schema (``stringcast/core/schemas/``), as the core's readers validate by it."""
    return json.loads(resources.files("stringcast.core").joinpath("schemas", schema_name).read_text())


def schema_keys(schema_name: str, definition: str | None = None) -> list[str]:
    """The keys a packaged schema (or its ``$defs/<definition>``) names."""
    doc = _schema(schema_name)
    doc = doc["$defs"][definition] if definition else doc
    return list(doc.get("properties", {}))


def schema_findings(doc: Any, path: str | Path, schema_name: str, definition: str | None = None,
                    prefix: str = "") -> list[Problem]:
    """One problem per way ``doc`` breaks the schema (:func:`~stringcast.core.schema_problems`): an
    unknown key named with the known ones it may be a typo of, a missing key named.

    Args:
        prefix: the document's place in the file (``"string/"`` for an inline string entry).
    """
    known = schema_keys(schema_name, definition)
    out = []
    for where, message in schema_problems(doc, schema_name, definition):
        field = prefix + ("" if where == "(top level)" else where)
        unexpected = re.match(r"Additional properties are not allowed \((.*) (was|were) unexpected\)", message)
        required = re.match(r"'([^']+)' is a required property", message)
        if unexpected and where == "(top level)":
            for key in re.findall(r"'([^']*)'", unexpected.group(1)):
                close = difflib.get_close_matches(key, known, n=1, cutoff=0.6)
                guess = f"a typo of {close[0]!r}?" if close else "not a key of this file"
                out.append(problem(path, f"unknown key: {guess} (the keys: {', '.join(known)})", prefix + key))
        elif required:
            out.append(problem(path, "missing: a required key", "/".join(x for x in (field.rstrip("/"), required.group(1))
                                                                        if x)))
        else:
            out.append(problem(path, message, field or None))
    return out


def string_findings(path: str, field: str, entry: Mapping) -> list[Problem]:
    """The string entry's points 30-34 mm apart (:data:`SPACING_MM`; the n_points that would fit
    named), and its weights and stiff sections on the string, from the grasp (0) to its length.

    ``field``: the entry's place (``"string"`` inline, ``"strings/4"`` in the config).
    """
    out = []
    length, n = float(entry["length_mm"]), int(entry["n_points"])
    lo, hi = SPACING_MM
    spacing = length / n
    if not lo <= spacing <= hi:
        fits = [k for k in range(max(2, math.floor(length / hi)), math.ceil(length / lo) + 1) if lo <= length / k <= hi]
        most = int(_schema("config.schema.json")["$defs"]["string"]["properties"]["n_points"]["maximum"])
        nearest = max(2, round(length / (0.5 * (lo + hi))))
        what = (f"{length:g} mm / {n} points puts them {spacing:.1f} mm apart; the model's points must lie "
                f"{lo:g}-{hi:g} mm apart (README)")
        if fits and fits[0] > most:
            out.append(problem(path, f"{what}, which takes {fits[0]} or more points, beyond the {most} the model "
                                     f"takes: is length_mm in another unit, or the string too long for the model?",
                               f"{field}/n_points", n))
        elif fits:
            fit = str(fits[0]) if len(fits) == 1 else f"{fits[0]} to {min(fits[-1], most)}"
            out.append(problem(path, f"{what}: n_points {fit} would fit (or is length_mm in another unit?)",
                               f"{field}/n_points", n))
        elif n != nearest:
            out.append(problem(path, f"{what}: no n_points fits a {length:g} mm string; {nearest} comes nearest",
                               f"{field}/n_points", n))
        else:
            out.append(problem(path, f"{what}: no n_points fits a {length:g} mm string, and {n} comes nearest",
                               f"{field}/n_points", n, "warn"))
    for i, w in enumerate(entry.get("weights") or []):
        at = float(w["at_mm"])
        if not 0 <= at <= length + 1e-6:
            out.append(problem(path, f"off the string (0..{length:g} mm from the grasp point): measured from the tip, "
                                     "or another string's?", f"{field}/weights/{i}/at_mm", w["at_mm"]))
    for i, sec in enumerate(entry.get("stiff_sections") or []):
        a, b = float(sec["from_mm"]), float(sec["to_mm"])
        if not a < b:
            out.append(problem(path, f"from_mm {a:g} must be below to_mm {b:g} (measured from the grasp point)",
                               f"{field}/stiff_sections/{i}", f"{a:g}..{b:g} mm"))
        elif b > length + 1e-6:
            out.append(problem(path, f"reaches past the string's end ({length:g} mm from the grasp point): "
                                     "measured from the tip, or another string's?",
                               f"{field}/stiff_sections/{i}", f"{a:g}..{b:g} mm"))
    return out


def board_findings(path: str, field: str, board: Mapping) -> list[Problem]:
    """A ChArUco board that can exist: marker smaller than square; a dictionary OpenCV knows, with a
    marker for every other square (:meth:`~stringcast.core.BoardSpec.make`)."""
    out = []
    square, marker = float(board["square_mm"]), float(board["marker_mm"])
    if marker >= square:
        out.append(problem(path, f"marker_mm {marker:g} must be smaller than square_mm {square:g} (each marker sits "
                                 "inside a white square): the two swapped, or one in another unit?",
                           f"{field}/marker_mm", board["marker_mm"]))
        marker = 0.5 * square   # the dictionary is judged all the same
    spec = BoardSpec(int(board["squares_x"]), int(board["squares_y"]), square / 1000, marker / 1000,
                     str(board["dictionary"]), bool(board.get("legacy_pattern", False)))
    try:
        spec.make()
    except ConfigError as exc:
        out.append(problem(path, str(exc).removeprefix("board: "), f"{field}/dictionary", board["dictionary"]))
    return out


def _entry(doc: Mapping, config: Mapping, key: str, table: str, path: str) -> tuple[list[Problem], Any, str]:
    """(problems, the entry or None, its place: ``key`` inline, ``<table>/<id>`` from the config) for one
    of :data:`ENTRIES`."""
    default = {"arm": next(iter(config.get("arms") or {"": None})), "setup": "default"}.get(key)
    ref = doc.get(key, default)
    if ref is None:
        return [], None, key      # missing: the schema's problem
    if isinstance(ref, Mapping):
        if key == "arm":
            return [], None, key  # an arm is named, never inline: the schema's problem
        found = schema_findings(ref, path, "config.schema.json", key, f"{key}/")
        return found, (None if found else ref), key
    entries = config.get(table) or {}
    if str(ref) not in entries:
        close = difflib.get_close_matches(str(ref), list(map(str, entries)), n=1, cutoff=0.6)
        guess = f"; a typo of {close[0]!r}?" if close else f"; add it to the config's {table}, or write it inline"
        where = "" if key in doc else f" (the default {key})"
        return [problem(path, f"unknown {key} id{where} (known: {', '.join(map(str, entries))}){guess}", key,
                        ref)], None, key
    return [], entries[str(ref)], f"{table}/{ref}"


def _specs(entries: dict, doc: Mapping, config: Mapping, path: str) -> tuple[list[Problem], dict]:
    """Each entry built into its spec on its own, its problems named; ``{key: spec}`` of those built."""
    out, specs = [], {}
    src = str(config.get("_path") or "the config")

    def where(key):   # an entry from the config is fixed there; an inline one in campaign.yaml
        return path if entries[key][1] == key else src

    if entries.get("string") is not None:
        e, field = entries["string"][0], entries["string"][1]
        found = string_findings(where("string"), field, e)
        out += found
        if not any(q.is_error for q in found):
            try:
                specs["string"] = StringSpec.from_config(field, e)
            except ConfigError as exc:
                out.append(from_error(exc, where("string"), field))
    if entries.get("target") is not None:
        e = entries["target"][0]
        specs["target"] = TargetSpec("t", e["x_mm"] / 1000, e["y_mm"] / 1000, e.get("radius_mm", 20.0) / 1000)
    if entries.get("arm") is not None:
        try:
            specs["arm"] = ArmSpec.from_config(entries["arm"][1].partition("/")[2], entries["arm"][0])
        except ConfigError as exc:
            out.append(from_error(exc, src, entries["arm"][1]))
    if entries.get("setup") is not None:
        e, field = entries["setup"][0], entries["setup"][1]
        cams = config.get("cameras") or {}
        if str(e["camera"]) not in cams:
            out.append(problem(where("setup"), f"unknown camera (known: {', '.join(map(str, cams))})",
                               f"{field}/camera", e["camera"]))
        board = board_findings(where("setup"), f"{field}/board", e["board"])
        out += board
        if not board and str(e["camera"]) in cams:
            try:
                specs["setup"] = SetupSpec.from_config(field, e, cams)
            except ConfigError as exc:
                out.append(from_error(exc, where("setup"), field))
    if "target" in specs and "arm" in specs and not doc.get("allow_reachable", False):
        reach = target_reach_problem(specs["target"], specs["arm"])
        if reach:   # fixed in campaign.yaml: another target, or allow_reachable
            inline = entries["target"][1] == "target"
            out.append(problem(path, reach, "target/x_mm" if inline else "target",
                               entries["target"][0]["x_mm"] if inline else doc.get("target")))
    return out, specs


def _check(path: Path, config: Mapping, name: str) -> tuple[list[Problem], Campaign | None, ArmSpec | None]:
    p = str(path)
    if not path.is_file():
        return [problem(p, "file not found: every campaign needs one (string, target: ids from the config or "
                           "inline)")], None, None
    try:
        doc = load_yaml(path)
    except ConfigError as exc:
        return [from_error(exc, p)], None, None
    if not isinstance(doc, Mapping):
        return [problem(p, f"expected a mapping with keys string and target, got {kind_of(doc)}",
                        value=None if doc is None else show(doc))], None, None
    out = schema_findings(dict(doc), p, "campaign.schema.json")
    if "target" not in doc:      # the schema lets the workflow's target-free copy pass; a campaign needs one
        out.append(problem(p, NO_TARGET, "target"))
    flagged = {q.field for q in out}
    entries = {}
    for key, table in ENTRIES:
        if key in flagged:          # the schema's problem already says what is wrong with it
            entries[key] = None
            continue
        found, entry, field = _entry(doc, config, key, table, p)
        out += found
        entries[key] = None if entry is None else (entry, field)
    found, specs = _specs(entries, doc, config, p)
    out += found
    campaign = None
    if not any(q.is_error for q in out):
        try:
            campaign = resolve_campaign(doc, config, name, path)
        except ConfigError as exc:
            out.append(from_error(exc, p))
    return out, campaign, (campaign.arm if campaign else specs.get("arm"))


def check_campaign_yaml(path: str | Path, config: Mapping, name: str = "campaign"
                        ) -> tuple[list[Problem], Campaign | None, ArmSpec | None]:
    """Check ``data/<campaign>/campaign.yaml`` against the config (see the module docstring).

    Returns:
        (problems, the resolved campaign or None where an error stops it, the campaign's arm where
        it can be built, for the trials' checks). Raises nothing.
    """
    def run():
        found, campaign, arm = _check(Path(path), config, name)
        return found, (campaign, arm)

    found, (campaign, arm) = guarded_with(path, run, default=(None, None))
    return found, campaign, arm
