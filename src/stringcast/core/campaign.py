"""Resolving a campaign (``data/<campaign>/campaign.yaml``) against the config: the ids it names
looked up in the config's tables (or given inline), the target's reach checked, the result a
:class:`~stringcast.core.specs.Campaign`.

Errors: :class:`~stringcast.core.config.ConfigError` naming the file and the key.
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from .config import ConfigError, load_config, load_yaml, validate
from .specs import ArmSpec, Campaign, SetupSpec, StringSpec, TargetSpec


def _lookup(table: Mapping, key, what: str, source) -> Mapping:
    k = str(key)
    if k not in table:
        raise ConfigError(f"{source}: unknown {what} {key!r} (known: {', '.join(map(str, table))})")
    return table[k]


def campaign_entries(doc: Mapping, config: Mapping, source: str | Path = "campaign.yaml") -> dict:
    """The config's entries a campaign mapping (``campaign.yaml``) names.

    Returns:
        ``{"string", "target", "arm", "setup"}``: each ``(id, entry)``, the id None for an inline
        entry (the mapping as written; no ``"target"`` where the mapping has none); the arm defaults to the config's first, the set-up to
        ``default``. ``"camera"``: the set-up's camera entry (None if the config has none by
        that name: :class:`SetupSpec` says so).

    Raises:
        ConfigError: an id the config does not know (named, with the known ones).
    """
    out = {}
    for key, table, ref in (("string", "strings", doc["string"]), ("target", "targets", doc.get("target")),
                            ("arm", "arms", doc.get("arm", next(iter(config["arms"])))),
                            ("setup", "setups", doc.get("setup", "default"))):
        if ref is None:   # no target: a campaign read without one (WITHOUT_TARGET)
            continue
        out[key] = (None, ref) if isinstance(ref, Mapping) else (str(ref), _lookup(config[table], ref, key, source))
    out["camera"] = config["cameras"].get(str(out["setup"][1].get("camera")))
    return out


REACH_MARGIN = 0.05
"""A target must lie beyond the grasp's reach by this, m (README: reach + 50 mm)."""


def target_reach_problem(target: TargetSpec, arm: ArmSpec) -> str | None:
    """What is wrong with a target the hanging string could reach without casting, or None.

    The target's x must exceed the grasp's reach (:attr:`ArmSpec.reach`) + :data:`REACH_MARGIN`;
    ``campaign.yaml``'s ``allow_reachable: true`` waives this (the caller's decision).
    """
    if target.x <= arm.reach + REACH_MARGIN:
        return (f"target x = {target.x * 1000:.0f} mm is within the grasp's reach "
                f"({arm.reach * 1000:.0f} mm) + {REACH_MARGIN * 1000:.0f} mm: the hanging string could touch it "
                "without casting. Move the target or set allow_reachable: true.")
    return None


NO_TARGET = ("missing: a required key (target: <id> from the config's targets, or inline x_mm, y_mm and "
             "radius_mm)")
"""The message for a campaign file without a target, read where one is needed."""

TARGET_KEYS = ("target", "allow_reachable")
"""The campaign.yaml keys only the target's readers need (:func:`without_target`)."""


def without_target(doc: Mapping) -> dict:
    """A campaign mapping less :data:`TARGET_KEYS`: what the workflow gives the stages that never read
    the target, so that a new target reruns only the stages that do (plan, predict, the reports)."""
    return {k: v for k, v in doc.items() if k not in TARGET_KEYS}


def resolve_campaign(doc: Mapping, config: Mapping, name: str = "campaign",
                     source: str | Path = "campaign.yaml", require_target: bool = True) -> Campaign:
    """Turn a campaign mapping (``campaign.yaml``) into a :class:`Campaign`.

    Args:
        require_target: False to read a mapping without a target (:func:`without_target`) into a
            campaign whose ``target`` is None.

    Raises:
        ConfigError: unknown ids, bad inline values, no target where one is required, or a target
            that the hanging string could reach without casting (unless ``allow_reachable: true``).
    """
    validate(dict(doc), "campaign.schema.json", source)
    if require_target and "target" not in doc:
        raise ConfigError(f"{source}: target: {NO_TARGET}")
    e = campaign_entries(doc, config, source)
    sid, sd = e["string"]
    string = StringSpec.from_config(f"{name}-inline" if sid is None else sid, sd)
    arm_id, ad = e["arm"]
    arm = ArmSpec.from_config(arm_id, ad)
    su, sd = e["setup"]
    setup = SetupSpec.from_config(su or "inline", sd, config["cameras"])
    target = None
    if "target" in e:
        tid, td = e["target"]
        target = TargetSpec(tid or "inline", td["x_mm"] / 1000, td["y_mm"] / 1000,
                            td.get("radius_mm", 20.0) / 1000)
        problem = None if doc.get("allow_reachable", False) else target_reach_problem(target, arm)
        if problem:
            raise ConfigError(f"{source}: {problem}")
    return Campaign(name, string, target, arm, setup, sid, dict(config))


def load_campaign(path: str | Path, config: Mapping | None = None, require_target: bool = True) -> Campaign:
    """Read ``data/<campaign>/campaign.yaml`` and resolve it against the config.

    The campaign's name is the file's folder (:func:`resolve_campaign`).

    Parameters
    ----------
    path : str or Path
        The ``campaign.yaml`` file.
    config : mapping, optional
        The merged config whose lab tables (arms, cameras, setups, strings, targets) resolve the campaign's
        ids; None: :func:`~stringcast.core.config.load_config`'s default.
    require_target : bool
        False to read a campaign without a target (its ``target`` is then None).

    Returns
    -------
    Campaign
        The resolved campaign (string, target, arm, setup).

    Raises
    ------
    ConfigError
        A missing, unreadable or malformed file, one that is not a mapping, or what
        :func:`resolve_campaign` refuses: unknown ids, bad inline values, no target where one is
        required, or a target that the hanging string could reach without casting (unless
        ``allow_reachable: true``).
    """
    path = Path(path)
    config = config if config is not None else load_config()
    doc = load_yaml(path)
    if not isinstance(doc, Mapping):
        raise ConfigError(f"{path}: expected a mapping with keys string, target")
    return resolve_campaign(doc, config, path.parent.name, path, require_target)
