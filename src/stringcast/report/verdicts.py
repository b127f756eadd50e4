"""What the pages say about the stages' verdicts and the estimate's bounds.

* :func:`stage_verdicts`: each stage's verdict as written (calibration.json or geometry.json, sync.json
  or clock.json, tracking.json, params.json's fit), the worst of them on top.
* :func:`verdict_box`: the trial page's box built from it: one line per stage with its status and its
  first reason, each reason said once on the page (a later stage that carries an earlier one's reason,
  as the fit carries the calibration's, does not repeat it), the others folded below.
* :func:`at_bounds`: which estimated coefficients and mass points sit at a bound of their range: there
  the range, not the footage, decided the value.
"""
from __future__ import annotations

import re

import numpy as np

from stringcast.core import Verdict, worst

STAGE_PREFIX = re.compile(r"^(calibration|geometry|sync|clock|sweep|tracking|fit|intrinsics)( \w+)?: ")
"""A reason's leading ``<stage>: `` (or ``<stage> <status>: ``), as a later stage quotes an earlier one's."""

BOUND_SHARE = 0.01
"""A value within this share of its range's log width from a bound is at that bound."""


def stage_verdicts(docs: dict) -> dict:
    """The page's verdict banner from each stage's JSON document (None: the stage wrote no file).

    Args:
        docs: stage name -> its JSON (calibration.json, sync.json, tracking.json, params.json) or None.

    Returns:
        {"status": the worst status, "rows": [{"stage", "status", "reasons", "cause"}]}: one row per
        document given; a document without a ``"verdict"`` has status "not judged". Raises nothing:
        a malformed verdict is shown as not judged.
    """
    rows, judged = [], []
    for stage, doc in docs.items():
        if doc is None:
            continue
        raw = doc.get("verdict") if isinstance(doc, dict) else None
        try:
            v = Verdict.from_dict(raw) if raw else None
        except (ValueError, TypeError, AttributeError):
            v = None
        if v is not None:
            judged.append(v)
        rows.append({"stage": stage, "status": v.status if v else "not judged", "reasons": list(v.reasons) if v else [],
                     "cause": str(raw.get("likely_cause") or "") if isinstance(raw, dict) else ""})
    status = worst(*judged).status if judged else "not judged"
    return {"status": status, "rows": rows}


def reason_key(reason: str) -> str:
    """A reason without the stage prefix another stage quotes it with (:data:`STAGE_PREFIX`), for
    telling a repeat from a new reason."""
    return STAGE_PREFIX.sub("", str(reason).strip()).strip()


def verdict_box(docs: dict) -> dict:
    """:func:`stage_verdicts` for the trial page's box: each reason once.

    Returns:
        ``stage_verdicts``' dict, each row with ``first`` (its first reason no earlier row gave, or "")
        and ``more`` (its other new reasons, folded on the page), and ``said``: every reason key on the
        box (:func:`reason_key`), so that the page's notes below it leave them out.
    """
    banner = stage_verdicts(docs)
    said: set[str] = set()
    rows = []
    for row in banner["rows"]:
        new = []
        for r in row["reasons"]:
            key = reason_key(r)
            if key and key not in said:
                said.add(key)
                new.append(r)
        rows.append({**row, "first": new[0] if new else "", "more": new[1:],
                     "repeats": len(row["reasons"]) - len(new)})
    return {**banner, "rows": rows, "said": said}


def at_bound(value: float, lo: float, hi: float, share: float = BOUND_SHARE) -> str:
    """``"lower"``, ``"upper"`` or ``""``: whether ``value`` lies within ``share`` of the log width of
    [lo, hi] from a bound (all > 0)."""
    if not (np.isfinite(value) and value > 0 and 0 < lo < hi):
        return ""
    width = np.log10(hi) - np.log10(lo)
    if np.log10(value) - np.log10(lo) <= share * width:
        return "lower"
    if np.log10(hi) - np.log10(value) <= share * width:
        return "upper"
    return ""


def at_bounds(values, lo, hi, mu, mu_range: tuple[float, float]) -> tuple[list[str], dict]:
    """Which of an estimate's coefficients and mass points sit at a bound (:func:`at_bound`).

    Args:
        values, lo, hi: (P,) the coefficients and Table 2's range of each.
        mu: (n,) the relative masses; mu_range: their (min, max).

    Returns:
        (per coefficient ``"lower"``/``"upper"``/``""``, ``{"lower": k, "upper": k, "n": n}`` of the masses).
    """
    flags = [at_bound(float(v), float(a), float(b)) for v, a, b in zip(values, lo, hi)]
    m = [at_bound(float(x), *map(float, mu_range)) for x in np.asarray(mu, float)]
    return flags, {"lower": m.count("lower"), "upper": m.count("upper"), "n": len(m)}
