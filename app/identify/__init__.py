"""Vehicle identification: what the logs say the driveline is, before anything is blamed on missing physics.

Public entry points::

    ident = identify_events(events, noise, vehicle, FitOptions(), progress, modal)   # prepared events
    ident = identify_staged(events, noise, vehicle, FitOptions(), progress)          # ... in stages on a long drive
    res = identify_logs([log], vehicle, IdentifyOptions(dbc=..., signal_map=...), validate=[other])

Modules: :mod:`.base` (the identifiable base parameters and their physical figures), :mod:`.modal`
(the model-free first mode), :mod:`.fit` (the grey-box fit, intervals, identifiability),
:mod:`.form` (the contact law the log chooses), :mod:`.logs` (logs in, identified vehicle version out,
validation on a withheld drive).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from app.identify.base import BASE_NAMES, Physical, physical, with_base
from app.identify.fit import FitOptions, Identification, Param, identify_events, identify_staged

if TYPE_CHECKING:
    from app.identify.logs import IdentifyOptions, IdentifyResult, identify_logs

__all__ = ["BASE_NAMES", "FitOptions", "Identification", "IdentifyOptions", "IdentifyResult", "Param", "Physical",
           "identify_events", "identify_logs", "identify_staged", "physical", "with_base"]
_LOGS = ("IdentifyOptions", "IdentifyResult", "identify_logs")


def __getattr__(name: str) -> Any:
    # the log-level entry decodes and analyses through app.pipeline, a layer above the diagnosis that uses
    # this package's fit: it loads on first use, so that importing the fit never imports the pipeline
    if name not in _LOGS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module("app.identify.logs"), name)
    globals()[name] = value
    return value
