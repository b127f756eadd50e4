"""Verdicts: every stage that can be wrong says so, ``ok``, ``warn`` or ``fail``, with its reasons.

A stage writes its verdict into its output (``calibration.json``, ``sync.json``,
``params.json``, ...) as ``{"status": ..., "reasons": [...]}``; the reports show it at the top
and a later stage that plans on a failed one says so. A reason is one sentence a person can
act on: what was measured, against what, and what to do.
"""
from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Mapping

STATUSES = ("ok", "warn", "fail")
"""The statuses from best to worst."""


@dataclass(frozen=True)
class Verdict:
    """A stage's verdict: ``status`` (one of :data:`STATUSES`) and the reasons behind it.

    Raises:
        ValueError: an unknown status, or a warn/fail without a reason.
    """

    status: str = "ok"
    reasons: tuple[str, ...] = ()

    def __post_init__(self):
        if self.status not in STATUSES:
            raise ValueError(f"verdict status must be one of {STATUSES}, got {self.status!r}")
        if self.status != "ok" and not self.reasons:
            raise ValueError(f"a {self.status} verdict needs a reason")

    def add(self, status: str, reason: str) -> Verdict:
        """This verdict with ``reason`` added, its status the worse of the two."""
        worse = max(self.status, status, key=STATUSES.index)
        return Verdict(worse, (*self.reasons, reason))

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def as_dict(self) -> dict:
        """``{"status": str, "reasons": [str, ...]}`` (JSON)."""
        return {"status": self.status, "reasons": list(self.reasons)}

    @classmethod
    def from_dict(cls, d: Mapping | None) -> Verdict:
        """The verdict written by :meth:`as_dict`; a missing one (older files) is ``ok``."""
        if not d:
            return cls()
        return cls(str(d.get("status", "ok")), tuple(d.get("reasons", ())))


def worst(*verdicts: Verdict) -> Verdict:
    """One verdict for several: the worst status and every reason, in order."""
    out = Verdict()
    for v in verdicts:
        for r in v.reasons:
            out = out.add(v.status, r)
    return out
