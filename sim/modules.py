"""Registries found module by module: the stage kinds (:mod:`sim.stagekinds`) and the effect library
(:mod:`sim.effects`) are one module per entry, each defining one named object."""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable, Iterable
from typing import TypeVar

T = TypeVar("T")


def module_entries(package: str, path: Iterable[str], attr: str, kind: type[T], name_of: Callable[[T], str],
                   what: str) -> list[T]:
    """The ``attr`` of every module of ``package`` (found on ``path``) but ``base`` and private ones, in file
    order. Each must be a ``kind`` whose ``name_of`` is the module's name; otherwise a ``TypeError`` naming the
    file says it must define ``attr``, ``what`` (formatted with the module's name): an entry is never skipped
    silently."""
    found: list[T] = []
    for info in pkgutil.iter_modules(list(path)):
        if info.name == "base" or info.name.startswith("_"):
            continue
        entry = getattr(importlib.import_module(f"{package}.{info.name}"), attr, None)
        if not isinstance(entry, kind) or name_of(entry) != info.name:
            raise TypeError(f"{package.replace('.', '/')}/{info.name}.py must define {attr}, {what.format(info.name)}")
        found.append(entry)
    return found
