"""What a finished diagnosis report decided, as the apply route and the validation job use it: the effect
(or pair) to apply with its fitted parameters, and the identified base parameters it rests on."""

from __future__ import annotations

from typing import Any

from app.errors import AnalysisError


def chosen(report: dict[str, Any]) -> dict[str, dict[str, float]]:
    """The fitted parameters of the effect (or pair) a report decided on ({} when it decided on base parameters
    alone, see :func:`base_ratios`); typed error when there is nothing to apply."""
    decision = report["decision"]
    key = "+".join(decision["top"])
    if decision["status"] == "base_parameters":
        if decision.get("identify_first"):
            raise AnalysisError("the diagnosis stopped at a prior bound of a base parameter: identify the vehicle "
                                "first (lashscope identify, or POST /identifications)", code="nothing_to_apply")
        return {}
    if not key or decision["status"] not in ("explained", "partial", "ambiguous"):
        raise AnalysisError(f"the diagnosis decided {decision['status']!r}: there is no effect to apply",
                            code="nothing_to_apply")
    for cand in report["candidates"] + report["pairs"]:
        if cand["id"] == key:  # the base parameters fitted with it are applied from base_ratios
            return {k: v for k, v in cand["fit"]["params"].items() if k in decision["top"]}
    raise AnalysisError(f"candidate {key!r} is missing from the report", code="nothing_to_apply")


def base_ratios(report: dict[str, Any]) -> dict[str, float]:
    """The identified base parameters (ratios to the file's values) the decision rests on; {} when none."""
    if not report["decision"].get("base_parameters"):
        return {}
    ratios: dict[str, float] = (report.get("identification") or {}).get("ratios") or {}
    return dict(ratios)
