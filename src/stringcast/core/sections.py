"""The map from a stage to the settings it reads, and what is made from the settings classes.

A stage's entry point names the settings it reads by its parameters' types;
:func:`sections_read` reads them back (the workflow's rule params) and :func:`stage_kwargs`
hands them over (the CLI). :func:`settings_digest` names a set of settings;
:func:`markdown_table` documents them (config/README.md).
"""
from __future__ import annotations

import dataclasses
import inspect
import typing

from .section import plain
from .settings import SECTION_CLASSES, Settings


def _settings_parameters(func) -> dict[str, type]:
    """``{parameter: class}`` for ``func``'s parameters annotated with a settings class or
    :class:`Settings` (a stage that takes every section, as the reports' provenance does)."""
    hints = typing.get_type_hints(func)
    known = (*SECTION_CLASSES, Settings)
    return {name: h for name, h in hints.items() if name in inspect.signature(func).parameters and h in known}


def sections_read(func) -> tuple[str, ...]:
    """The config sections a stage reads: those of the settings classes among ``func``'s
    parameter annotations (in :data:`SECTION_CLASSES` order; every section for a parameter
    annotated :class:`Settings`).

    ``stringcast.cli`` hands each stage exactly these, and the workflow makes them the rule's
    params, so Snakemake reruns the rule when one of them changes and only then.
    """
    return _sections_of(set(_settings_parameters(func).values()))


def _sections_of(types: set) -> tuple[str, ...]:
    """The sections of the settings classes ``types``, in :data:`SECTION_CLASSES` order (all of them
    where :class:`Settings` is among ``types``)."""
    return tuple(c.SECTION for c in SECTION_CLASSES if c in types or Settings in types)


def sections_read_from_source(entry: str) -> tuple[str, ...]:
    """:func:`sections_read` of the stage entry point ``"stringcast.<module>:<function>"``, read
    from its source with :mod:`ast`, without importing the stage.

    The Snakefile asks every stage's sections when it is parsed, for every Snakemake call;
    importing the stages for it (numba, matplotlib, scipy, ...) took 1.3 s of each call's 2 s.
    The function is found in its module or, through ``from .x import name`` (at the top, or under
    a lazy face's ``if TYPE_CHECKING:``), in the sibling module a package re-exports it from; its parameters annotated with a settings class name
    (``tracking: TrackingSettings``) or ``Settings`` give the sections. ``tests/core`` holds this
    to :func:`sections_read` of the imported function for every stage.

    Raises:
        ValueError: the function is not defined where ``entry`` says (nor re-exported there).
    """
    import ast
    from pathlib import Path

    module, _, name = entry.partition(":")
    parts = module.split(".")[1:]                      # below stringcast/
    base = Path(__file__).resolve().parents[1].joinpath(*parts)
    path = base / "__init__.py" if base.is_dir() else base.with_suffix(".py")
    known = {c.__name__: c for c in (*SECTION_CLASSES, Settings)}
    for _ in range(4):                                 # a re-export chain is short
        tree = ast.parse(path.read_text())
        for node in tree.body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name == name:
                a = node.args
                return _sections_of({known[arg.annotation.id] for arg in (*a.posonlyargs, *a.args, *a.kwonlyargs)
                                     if isinstance(arg.annotation, ast.Name) and arg.annotation.id in known})
        top = [*tree.body, *(n for i in tree.body if isinstance(i, ast.If) for n in i.body)]  # lazy faces: under TYPE_CHECKING
        found = [n for n in top if isinstance(n, ast.ImportFrom) and n.level == 1
                 and any((al.asname or al.name) == name for al in n.names)]
        if not found:
            break
        name = next(al.name for al in found[0].names if (al.asname or al.name) == name)
        path = path.parent.joinpath(*found[0].module.split(".")).with_suffix(".py")
    raise ValueError(f"{entry}: no function {name} in {path}")


def stage_kwargs(func, settings: Settings) -> dict:
    """The keyword arguments ``{parameter: settings}`` that ``func`` takes from ``settings``:
    each section's object by its class, and ``settings`` itself for a :class:`Settings` one."""
    return {name: settings if h is Settings else getattr(settings, h.SECTION)
            for name, h in _settings_parameters(func).items()}


def settings_digest(settings: Settings) -> str:
    """SHA-256 (first 12 hex digits) of every section's settings as canonical JSON: two
    configs that give the same settings give the same digest, whatever their files say."""
    import hashlib
    import json

    doc = {s: getattr(settings, s).as_dict() for s in (c.SECTION for c in SECTION_CLASSES)}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:12]


def markdown_table() -> str:
    """Every setting with its default and help, one table per section (``config/README.md``)."""
    import yaml

    out = []
    for c in SECTION_CLASSES:
        summary = (c.__doc__ or "").strip().split("\n")[0].removeprefix(f"``{c.SECTION}``: ")
        out += [f"### `{c.SECTION}`", "", summary[:1].upper() + summary[1:], "",
                "| setting | default | meaning |", "| --- | --- | --- |"]
        for f in dataclasses.fields(c):
            value = getattr(c(), f.name)
            text = yaml.safe_dump(plain(value), default_flow_style=True, width=1000, sort_keys=False).strip()
            text = text.removesuffix("\n...").removesuffix("...").strip()
            out.append(f"| `{f.name}` | `{text}` | {f.metadata.get('help', '')} |")
        out.append("")
    return "\n".join(out)
