"""One problem the check found in a raw file: :class:`Problem`, and how the check's parts make them.

Every part of the check returns a list of problems and raises nothing: a reader's
:class:`~stringcast.core.DataError` or :class:`~stringcast.core.ConfigError` becomes a problem
(:func:`from_error`), and an exception nobody foresaw becomes one too (:func:`guarded`), so a
broken file can never stop the check of the others.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal
from collections.abc import Callable

import yaml

from stringcast.core import ConfigError, DataError, JointLimitError

Severity = Literal["error", "warn"]
SEVERITIES: tuple[str, ...] = ("error", "warn")


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def show(value: Any, limit: int = 60) -> str:
    """A value as a problem quotes it: one line, at most ``limit`` characters."""
    text = _one_line(value if isinstance(value, str) else repr(value) if isinstance(value, (list, dict))
                     else str(value))
    return text if len(text) <= limit else text[: limit - 3] + "..."


@dataclass(frozen=True)
class Problem:
    """A problem in a raw file.

    Attributes:
        path: the file (or folder) to fix, as the check was given it (``data/c/trial_1/video.yaml``).
        field: the key, column or line within it, or None.
        value: the value found there, as text, or None.
        message: what is wrong, and the likely mistake.
        severity: ``"error"`` (a stage would fail or be misled: the workflow must not run the
            campaign) or ``"warn"`` (the campaign runs; worth a look).

    ``str()`` is one line: ``<file>: <field>: <value>: <message>``, empty parts left out.
    """

    path: str
    field: str | None
    value: str | None
    message: str
    severity: Severity = "error"

    def __post_init__(self):
        if self.severity not in SEVERITIES:
            raise ValueError(f"Problem: severity must be one of {SEVERITIES}, got {self.severity!r}")

    @property
    def is_error(self) -> bool:
        return self.severity == "error"

    def __str__(self) -> str:
        parts = [self.path, self.field, self.value, self.message]
        return ": ".join(_one_line(p) for p in parts if p not in (None, ""))


def kind_of(doc: Any) -> str:
    """What a parsed YAML document is, as a problem says it ("an empty file", "a list", "a number")."""
    if doc is None:
        return "an empty file"
    if isinstance(doc, bool):
        return "true or false"
    if isinstance(doc, (int, float)):
        return "a number"
    if isinstance(doc, str):
        return "a line of text"
    return f"a {type(doc).__name__}"


def problem(path: str | Path, message: str, field: str | None = None, value: Any = None,
            severity: Severity = "error") -> Problem:
    """A :class:`Problem` (``value`` shown by :func:`show`; None stays None)."""
    return Problem(str(path), field, None if value is None else show(value), _one_line(message), severity)


def from_error(exc: BaseException, path: str | Path, field: str | None = None, value: Any = None,
               severity: Severity = "error", hint: str = "") -> Problem:
    """The problem a reader's error names: its message without the leading ``<path>: `` (the
    problem's path says it), ``hint`` (the likely mistake) appended after "; ".

    A YAML syntax error (a :class:`~stringcast.core.ConfigError` raised from PyYAML's) is told by its
    line and column: ``campaign.yaml: line 3: not valid YAML: ...``.
    """
    cause = exc.__cause__
    if isinstance(cause, yaml.MarkedYAMLError) and cause.problem_mark is not None:
        mark, opened = cause.problem_mark, cause.context_mark
        what = _one_line(" ".join(x for x in (cause.context, cause.problem) if x))
        if opened is not None and opened.line != mark.line and "flow" in str(cause.context):
            where = f"line {opened.line + 1}"
            likely = f"a '[' or '{{' opened on line {opened.line + 1} and never closed?"
        else:
            where = f"line {mark.line + 1}"
            likely = "an unquoted ':' or '#', a tab, or an indentation that does not match the lines above?"
        return problem(path, f"not valid YAML: {what} (line {mark.line + 1}, column {mark.column + 1}); {likely}",
                       where, severity=severity)
    text = _one_line(str(exc))
    for prefix in (f"{path}: ", f"{Path(path)}: "):
        if text.startswith(prefix):
            text = text[len(prefix):]
            break
    return problem(path, f"{text}; {hint}" if hint else text, field, value, severity)


EXPECTED = (DataError, ConfigError, JointLimitError)
"""The errors the project's readers raise for a bad file (each names the file)."""


def guarded(path: str | Path, check: Callable[..., list[Problem]], *args, **kwargs) -> list[Problem]:
    """``check(*args, **kwargs)``'s problems; a reader's error it lets through is a problem of
    ``path`` (:func:`from_error`), and so is any other exception (named, "please report it"), so
    that no input stops the check."""
    try:
        return list(check(*args, **kwargs))
    except EXPECTED as exc:
        return [from_error(exc, path)]
    except Exception as exc:  # noqa: BLE001 -- the check must report, never raise, on any input
        return [problem(path, f"the check could not read it ({type(exc).__name__}: {show(exc, 200)}); "
                              "please report this as a bug in stringcast check")]


def guarded_with(path: str | Path, check: Callable[..., tuple], *args,
                 default: Any = None) -> tuple[list[Problem], Any]:
    """:func:`guarded` for a check that returns ``(problems, result)``: ``(problems, result)``, or
    ``(problems, default)`` where it raised."""
    box: list = []

    def run():
        box.append(check(*args))
        return box[0][0]

    found = guarded(path, run)
    return found, (box[0][1] if box else default)
