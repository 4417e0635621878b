"""Driveline simulator: the reference paper's two-inertia and multibody models.

Pure library: numpy, scipy and numba only; imports nothing from ``app``.

>>> from sim import load_vehicle, simulate
>>> vehicle = load_vehicle("paper")
>>> res = simulate(vehicle, t_s, torque_nm)          # doctest: +SKIP
"""

from sim.errors import InputSignalError, InstabilityError, ParameterError, SimError
from sim.params import GAP_NAMES, Vehicle
from sim.simulate import SimResult, simulate
from sim.vehicle_file import dump_toml, load_vehicle, load_vehicle_text, preset_names
from sim.whatif import WhatIf

__all__ = [
    "GAP_NAMES", "InputSignalError", "InstabilityError", "ParameterError", "SimError", "SimResult", "Vehicle",
    "WhatIf", "dump_toml", "load_vehicle", "load_vehicle_text", "preset_names", "simulate",
]
