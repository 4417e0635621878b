"""Vehicle identification: what the logs say the driveline is, before anything is blamed on missing physics.

Public entry points::

    ident = identify_events(events, noise, vehicle, FitOptions(), progress, modal)   # prepared events
    res = identify_logs([log], vehicle, IdentifyOptions(dbc=..., signal_map=...), validate=[other])

Modules: :mod:`.base` (the identifiable base parameters and their physical figures), :mod:`.modal`
(the model-free first mode), :mod:`.fit` (the grey-box fit, intervals, identifiability),
:mod:`.logs` (logs in, identified vehicle version out, validation on a withheld drive).
"""

from __future__ import annotations

from app.identify.base import BASE_NAMES, Physical, physical, with_base
from app.identify.fit import FitOptions, Identification, Param, identify_events

__all__ = ["BASE_NAMES", "FitOptions", "Identification", "Param", "Physical", "identify_events", "physical",
           "with_base"]
