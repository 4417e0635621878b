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

__all__ = [
    "SCHEMA_VERSION",
    "STATUSES",
    "Decision",
    "DecisionRules",
    "DiagnosisOptions",
    "DiagnosisResult",
    "Progress",
    "Validation",
    "augmented_vehicle",
    "chosen_effects",
    "diagnose_checked",
    "diagnose_signals",
    "report_dict",
    "run_diagnosis",
    "validate_effects",
    "validate_on",
]
