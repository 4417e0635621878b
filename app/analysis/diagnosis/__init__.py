"""Diagnosis of the sim-to-real gap: where it lies, which unmodelled effect causes it, how far it shrinks.

Public entry points::

    result = diagnose_signals(signals, vehicle, DiagnosisOptions(candidates=..., seed=...), progress)
    doc    = report_dict(result)                        # the documented JSON report (see .report)
    check  = validate_on(result, other_signals, vehicle) # shrink of the chosen effect on another drive
    augmented = augmented_vehicle(result)                # the vehicle with the diagnosed effect applied

Modules: :mod:`.split` (frozen event split), :mod:`.noise` (model-free noise floor),
:mod:`.forward` (event windows through the simulator), :mod:`.calibrate` (bounded joint fits on
calibration events), :mod:`.localise` (phases, bands, coherence), :mod:`.score` and
:mod:`.decide` (held-out statistics and the decision), :mod:`.select` (the procedure),
:mod:`.validate` (another drive), :mod:`.report` (JSON), :mod:`.synthetic` (truth drives).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the real names for the type checker; at run time they resolve lazily (below)
    from app.analysis.diagnosis.decide import STATUSES, Decision, DecisionRules
    from app.analysis.diagnosis.report import SCHEMA_VERSION, report_dict
    from app.analysis.diagnosis.select import DiagnosisOptions, DiagnosisResult, Progress, run_diagnosis
    from app.analysis.diagnosis.validate import (
        Validation,
        augmented_vehicle,
        chosen_effects,
        diagnose_checked,
        diagnose_signals,
        validate_effects,
        validate_on,
    )

# Names resolve on first use (PEP 562): the vehicle identification (app.identify) fits through this
# package's forward model and calibration, and the procedure here identifies the vehicle first;
# importing a submodule such as .calibrate must therefore not pull in .select.
_EXPORTS = {
    "SCHEMA_VERSION": "report", "report_dict": "report",
    "STATUSES": "decide", "Decision": "decide", "DecisionRules": "decide",
    "DiagnosisOptions": "select", "DiagnosisResult": "select", "Progress": "select", "run_diagnosis": "select",
    "Validation": "validate", "augmented_vehicle": "validate", "chosen_effects": "validate",
    "diagnose_checked": "validate", "diagnose_signals": "validate", "validate_effects": "validate",
    "validate_on": "validate",
}
__all__ = [
    "SCHEMA_VERSION", "STATUSES", "Decision", "DecisionRules", "DiagnosisOptions", "DiagnosisResult", "Progress",
    "Validation", "augmented_vehicle", "chosen_effects", "diagnose_checked", "diagnose_signals", "report_dict",
    "run_diagnosis",
    "validate_effects", "validate_on",
]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value
