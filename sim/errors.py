"""Simulator exception tree (the simulator imports nothing from ``app``)::

    SimError
     +-- ParameterError (ValueError)     a vehicle description field is invalid; names field + value
     +-- InputSignalError (ValueError)   torque input unusable (empty, non-finite, non-monotonic time)
     +-- InstabilityError (ArithmeticError)  the integration produced non-finite or diverging states
"""

from __future__ import annotations

import reprlib
from typing import Any

#: How much of a value an error message quotes: a field given half a million keys, or a string of
#: megabytes, is named with its first few items or characters, not in full.
_SHORT = reprlib.Repr()
_SHORT.maxlevel, _SHORT.maxstring, _SHORT.maxother, _SHORT.maxlong = 3, 200, 200, 100
_SHORT.maxdict = _SHORT.maxlist = _SHORT.maxtuple = _SHORT.maxset = _SHORT.maxfrozenset = 12


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
    """Plain text of a value for an error message: ``0.5``, ``1e+30``, ``'abc'``, ``[0.1, 0.2]`` (a long
    one shortened, ``{'k0': 1, ..., ...}``)."""
    return _SHORT.repr(plain(value))


class ParameterError(SimError, ValueError):
    code = "invalid_parameter"

    def __init__(self, field: str, value: object, reason: str) -> None:
        value = plain(value)
        super().__init__(f"{field} = {fmt(value)}: {reason}")
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
