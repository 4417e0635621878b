"""The registry of driveline stage kinds: one module per kind, found by name.

Every module of this package except :mod:`sim.stagekinds.base` defines ``KIND``, an instance of a
:class:`~sim.stagekinds.base.StageKind` subclass. The registry imports them all when the package
is first imported and orders them by their ``order``; a new kind is one new module here plus its
test (docs/simulation.md, "Adding a stage kind"). :func:`kind_of` is the one lookup: an unknown
kind is a :class:`~sim.errors.ParameterError` naming the known ones.
"""

from __future__ import annotations

from sim.errors import ParameterError
from sim.modules import module_entries
from sim.stagekinds.base import DIFFERENTIAL, DRIVE, SHAFTS, KindDoc, StageKind

__all__ = ["ALIASES", "DIFFERENTIAL", "DRIVE", "KINDS", "SHAFTS", "KindDoc", "StageKind", "kind_names", "kind_of",
           "kinds_table"]


def _discover() -> dict[str, StageKind]:
    found = module_entries(__name__, __path__, "KIND", StageKind, lambda k: k.name, "a StageKind named {!r}")
    found.sort(key=lambda k: (k.order, k.name))
    return {k.name: k for k in found}


KINDS: dict[str, StageKind] = _discover()
ALIASES: dict[str, str] = {a: k.name for k in KINDS.values() for a in k.aliases}


def kind_names() -> list[str]:
    """The kinds in table order (what messages list)."""
    return list(KINDS)


def kind_of(name: str, path: str = "kind") -> StageKind:
    """The kind called ``name`` (or an alias of it); a ParameterError on ``path`` naming the known kinds otherwise."""
    kind = KINDS.get(ALIASES.get(name, name)) if isinstance(name, str) else None
    if kind is None:
        raise ParameterError(path, name, f"unknown stage kind; known: {kind_names()} (aliases {sorted(ALIASES)}; "
                             "'rotor' and 'wheel' only as first and last entry)")
    return kind


def kinds_table() -> str:
    """The stage table of docs/simulation.md, one row per registered kind."""
    head = ("| kind | what | ratio | direction | housing reaction (`e`) |\n"
            "|---|---|---|---|---|")
    return "\n".join([head, *(k.doc_row() for k in KINDS.values())])
