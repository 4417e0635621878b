"""Simulator exception tree (the simulator imports nothing from ``app``)::

    SimError
     +-- ParameterError (ValueError)     a vehicle description field is invalid; names field + value
     +-- InputSignalError (ValueError)   torque input unusable (empty, non-finite, non-monotonic time)
     +-- InstabilityError (ArithmeticError)  the integration produced non-finite or diverging states
"""

from __future__ import annotations

from typing import Any


class SimError(Exception):
    """Base of all simulator errors."""

    code = "sim_error"


def plain(value: Any) -> Any:
    """``value`` with numpy scalars (also inside lists, tuples and dicts) turned into Python numbers.

    Error messages show ``0.5``, not ``np.float64(0.5)``; sim imports numpy lazily here so the
    error module stays dependency-free.
    """
    if hasattr(value, "item") and getattr(value, "ndim", None) == 0:  # numpy scalar or 0-d array
        return value.item()
    if isinstance(value, list | tuple):
        return type(value)(plain(v) for v in value)
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    return value


def fmt(value: Any) -> str:
    """Plain text of a value for an error message: ``0.5``, ``1e+30``, ``'abc'``, ``[0.1, 0.2]``."""
    return repr(plain(value))


class ParameterError(SimError, ValueError):
    code = "invalid_parameter"

    def __init__(self, field: str, value: object, reason: str) -> None:
        value = plain(value)
        super().__init__(f"{field} = {value!r}: {reason}")
        self.field = field
        self.value = value
        self.reason = reason

    def __reduce__(self) -> tuple[type[ParameterError], tuple[str, object, str], dict[str, Any]]:
        """Rebuild from the three constructor arguments, so the error crosses a process or cluster boundary
        (pickle's default replays ``args``, which hold only the formatted message)."""
        return type(self), (self.field, self.value, self.reason), dict(self.__dict__)


class InputSignalError(SimError, ValueError):
    code = "invalid_sim_input"


class InstabilityError(SimError, ArithmeticError):
    code = "sim_unstable"
