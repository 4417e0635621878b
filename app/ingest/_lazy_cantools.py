"""Import cantools without its bus tester: ``cantools.tester`` is loaded on first use.

``import cantools`` (which every ``cantools.database`` import runs first) imports
``cantools.tester``, which imports python-can, which imports asammdf and with it pandas and
pyarrow: about a second of start-up that decoding a log never uses (the readers are our own).
A placeholder registered as ``cantools.tester`` beforehand satisfies cantools' ``from . import
tester``; the first attribute anyone reads from it imports the real module, so cantools stays
complete and only code that uses the tester pays for it.
"""

from __future__ import annotations

import importlib
import importlib.machinery
import importlib.util
import sys
import types
from typing import Any

_DEFERRED = "cantools.tester"


class _OnFirstUse(types.ModuleType):
    """Stands in for a module; the first missing attribute imports the real one and reads from it."""

    def __getattr__(self, attr: str) -> Any:
        if attr.startswith("__"):
            raise AttributeError(attr)
        if sys.modules.get(self.__name__) is self:
            del sys.modules[self.__name__]
        return getattr(importlib.import_module(self.__name__), attr)


def defer_cantools_tester() -> None:
    """Register the placeholder, unless cantools is imported already or not installed."""
    if "cantools" in sys.modules or _DEFERRED in sys.modules:
        return
    if importlib.util.find_spec("cantools") is None:  # finds, does not execute, a top-level package
        return
    placeholder = _OnFirstUse(_DEFERRED)
    placeholder.__spec__ = importlib.machinery.ModuleSpec(_DEFERRED, None)
    sys.modules[_DEFERRED] = placeholder
