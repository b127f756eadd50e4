"""The machinery of the settings classes (:mod:`.settings`): a field with its default, help and
JSON-schema constraints (:func:`setting`), the section base class that builds itself from a config
section and refuses unknown keys (:class:`Section`), and the JSON schema made from a class
(:func:`section_schema`): each setting is declared once, where its class declares it.
"""
from __future__ import annotations

import dataclasses
import typing
from dataclasses import field
from types import MappingProxyType
from collections.abc import Mapping

from .errors import ConfigError


def setting(default, help: str, **schema):
    """A field with its default, its help text (``config/README.md``) and its JSON-schema constraints
    (``minimum``, ``enum``, ``items``, ...; the type comes from the annotation: :func:`section_schema`)."""
    meta = {"help": help, "schema": schema}
    if isinstance(default, Mapping):
        frozen = MappingProxyType(dict(default))
        return field(default_factory=lambda: frozen, metadata=meta)
    return field(default=default, metadata=meta)


_JSON_TYPES = {"float": "number", "int": "integer", "bool": "boolean", "str": "string"}


def _json_type(annotation: str):
    """The JSON-schema type of a settings field's annotation (``float | None`` -> ``["number", "null"]``)."""
    a = annotation.replace(" ", "")
    optional = a.endswith("|None")
    base = a.removesuffix("|None")
    t = _JSON_TYPES.get(base) or ("array" if base.startswith("tuple") else "object" if base.startswith("Mapping")
                                  else None)
    if t is None:
        raise TypeError(f"no JSON-schema type for the settings annotation {annotation!r}")
    return [t, "null"] if optional else t


def section_schema(cls) -> dict:
    """The JSON schema of one settings section, made from its class: each field's type (its annotation),
    constraints (:func:`_f`) and help as the description; no other key. The config's schema
    (``config.schema.json``) takes its stage sections from here, so a setting is declared once."""
    props = {}
    for f in dataclasses.fields(cls):
        spec = dict(f.metadata.get("schema", {}))
        spec.setdefault("type", _json_type(str(f.type)))
        props[f.name] = {**spec, "description": f.metadata.get("help", "")}
    return {"type": "object", "additionalProperties": False, "description": (cls.__doc__ or "").split("\n")[0],
            "properties": props}


def frozen(value):
    """Lists become tuples and mappings read-only, recursively (a setting cannot be changed)."""
    if isinstance(value, Mapping):
        return MappingProxyType({k: frozen(v) for k, v in value.items()})
    if isinstance(value, (list, tuple)):
        return tuple(frozen(v) for v in value)
    return value


def plain(value):
    """The inverse of :func:`frozen`: dicts and lists, for JSON, YAML and Snakemake params."""
    if isinstance(value, Mapping):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, tuple):
        return [plain(v) for v in value]
    return value


def one_of(section: str, name: str, value, allowed: tuple) -> None:
    """Raise ConfigError naming ``section.name`` unless ``value`` is one of ``allowed``."""
    if value not in allowed:
        raise ConfigError(f"{section}.{name} must be one of {', '.join(map(str, allowed))}, got {value!r}")


class Section:
    """Shared behaviour of the settings classes: built from a config section, and back."""

    SECTION: typing.ClassVar[str] = ""

    @classmethod
    def from_mapping(cls, d: Mapping | None):
        """The section's settings: ``d`` (the config's section, may be None) over the defaults.

        Raises:
            ConfigError: a key this section does not have, naming it and the section.
        """
        d = dict(d or {})
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise ConfigError(f"{cls.SECTION}: unknown setting(s) {', '.join(unknown)} "
                              f"(known: {', '.join(sorted(names))})")
        defaults = cls()
        for k, v in d.items():  # a mapping-valued setting is merged over its default, key by key
            if isinstance(v, Mapping) and isinstance(getattr(defaults, k), Mapping):
                d[k] = {**getattr(defaults, k), **v}
        return cls(**{k: frozen(v) for k, v in d.items()})

    def as_dict(self) -> dict:
        """The settings as plain data (lists, dicts), every key present."""
        return {f.name: plain(getattr(self, f.name)) for f in dataclasses.fields(self)}
