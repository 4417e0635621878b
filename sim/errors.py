"""Simulator exception tree (the simulator imports nothing from ``app``)::

    SimError
     +-- ParameterError (ValueError)     a vehicle description field is invalid; names field + value
     +-- InputSignalError (ValueError)   torque input unusable (empty, non-finite, non-monotonic time)
     +-- InstabilityError (ArithmeticError)  the integration produced non-finite or diverging states
"""

from __future__ import annotations


class SimError(Exception):
    """Base of all simulator errors."""

    code = "sim_error"


class ParameterError(SimError, ValueError):
    code = "invalid_parameter"

    def __init__(self, field: str, value: object, reason: str) -> None:
        super().__init__(f"{field} = {value!r}: {reason}")
        self.field = field
        self.value = value
        self.reason = reason


class InputSignalError(SimError, ValueError):
    code = "invalid_sim_input"


class InstabilityError(SimError, ArithmeticError):
    code = "sim_unstable"
