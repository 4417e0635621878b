"""Calibration / held-out split of events, frozen before any fitting.

The split is made *by event* and stratified: events are grouped by kind (tip-in, tip-out), sorted
within a group by speed and torque step, and taken in consecutive pairs of which a seeded coin
puts one in calibration and the other in held-out. Like events therefore land on both sides.
The split carries a SHA-256 over the seed, the event table and the assignment, so a report
states exactly which events were fitted and which only scored.

:class:`Split` is the only way to obtain the calibration events (:meth:`Split.calibration_events`);
the fitting code accepts nothing else, and every fit checks the events it is given against the
split (see :func:`require_calibration`).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol, TypeVar

import numpy as np

from app.errors import AnalysisError, InsufficientDataError
from app.serial import Serial, lists, rule


class SplitEvent(Protocol):
    """What the split needs to know about an event."""

    @property
    def index(self) -> int: ...

    @property
    def kind(self) -> str: ...

    @property
    def t_event(self) -> float: ...

    @property
    def speed_rpm(self) -> float: ...

    @property
    def torque_step_nm(self) -> float: ...


E = TypeVar("E", bound=SplitEvent)

CALIBRATION = "calibration"
HELDOUT = "heldout"


@dataclass(frozen=True)
class Split(Serial):
    """A frozen event split.

    Attributes
    ----------
    seed : RNG seed the split was drawn with.
    calibration, heldout : event indices on each side (sorted, disjoint).
    digest : SHA-256 hex digest of seed, event table and assignment.
    """

    seed: int
    calibration: tuple[int, ...] = field(metadata=rule(convert=lists))
    heldout: tuple[int, ...] = field(metadata=rule(convert=lists))
    digest: str = field(metadata=rule(key="sha256"))
    strata: dict[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        overlap = set(self.calibration) & set(self.heldout)
        if overlap:
            raise AnalysisError(f"split is not disjoint: events {sorted(overlap)} are on both sides")

    def role(self, index: int) -> str:
        if index in self.calibration:
            return CALIBRATION
        if index in self.heldout:
            return HELDOUT
        raise AnalysisError(f"event {index} is not part of split {self.digest[:12]}")

    def calibration_events(self, events: Sequence[E]) -> tuple[E, ...]:
        cal = set(self.calibration)
        return tuple(e for e in events if e.index in cal)

    def heldout_events(self, events: Sequence[E]) -> tuple[E, ...]:
        ho = set(self.heldout)
        return tuple(e for e in events if e.index in ho)


def require_calibration(split: Split, events: Sequence[SplitEvent]) -> None:
    """Raise unless every event is a calibration event of ``split`` (the fit-side guard)."""
    bad = [e.index for e in events if e.index not in split.calibration]
    if bad:
        raise AnalysisError(f"refusing to fit on events {bad}: they are not calibration events of the frozen split")
    if not events:
        raise InsufficientDataError("no calibration events to fit on")


def _digest(seed: int, events: Sequence[SplitEvent], cal: Sequence[int], ho: Sequence[int]) -> str:
    table = [
        [e.index, e.kind, round(float(e.t_event), 6), round(float(e.speed_rpm), 3), round(float(e.torque_step_nm), 3)]
        for e in events
    ]
    payload = json.dumps({"seed": seed, "events": table, "calibration": list(cal), "heldout": list(ho)},
                         sort_keys=True)
    return hashlib.sha256(payload.encode()).hexdigest()


def make_split(events: Sequence[SplitEvent], seed: int = 0) -> Split:
    """Stratified by-event split, half for calibration, half held out.

    Parameters
    ----------
    events : the events, each with a unique ``index``.
    seed : RNG seed; the same events and seed give the same split and digest.

    Returns
    -------
    Split
    """
    indices = [e.index for e in events]
    if len(set(indices)) != len(indices):
        raise AnalysisError(f"event indices are not unique: {indices}")
    rng = np.random.default_rng(seed)
    cal: list[int] = []
    ho: list[int] = []
    strata: dict[str, int] = {}
    for kind in sorted({e.kind for e in events}):
        group = sorted((e for e in events if e.kind == kind),
                       key=lambda e: (float(e.speed_rpm), abs(float(e.torque_step_nm)), e.index))
        strata[kind] = len(group)
        for i in range(0, len(group), 2):
            pair = group[i:i + 2]
            if len(pair) == 2:
                first_cal = bool(rng.integers(2))
                cal.append(pair[0 if first_cal else 1].index)
                ho.append(pair[1 if first_cal else 0].index)
            else:
                # an odd one out goes to the smaller side so the sides stay balanced
                (cal if len(cal) <= len(ho) else ho).append(pair[0].index)
    cal.sort()
    ho.sort()
    return Split(seed, tuple(cal), tuple(ho), _digest(seed, events, cal, ho), strata)


def _radical_inverse(i: int) -> float:
    """Van der Corput radical inverse of ``i`` in base 2 (0, 0.5, 0.25, 0.75, 0.125, ...)."""
    out, f = 0.0, 0.5
    while i:
        out += f * (i & 1)
        i >>= 1
        f *= 0.5
    return out


def spread_order(m: int) -> list[int]:
    """Positions ``0..m-1`` in an order whose every prefix spreads over the whole range (van der Corput)."""
    seen: set[int] = set()
    out: list[int] = []
    i = 0
    while len(out) < m:
        p = min(int(_radical_inverse(i) * m), m - 1)
        i += 1
        if p not in seen:
            seen.add(p)
            out.append(p)
    return out


def stratified_order(events: Sequence[E]) -> list[E]:
    """``events`` in the order a sequential design takes them: every prefix covers each kind in proportion and
    spans its speeds and torque steps.

    Within a kind the events are sorted by speed and torque step (as the split pairs them) and taken in the
    van der Corput order of their ranks; the kinds are merged by each event's place in its own order as a share
    of the kind's size, so a prefix of ``n`` events holds about ``n`` times each kind's share."""
    keyed: list[tuple[float, str, int, E]] = []
    for kind in sorted({e.kind for e in events}):
        group = sorted((e for e in events if e.kind == kind),
                       key=lambda e: (float(e.speed_rpm), abs(float(e.torque_step_nm)), e.index))
        for j, p in enumerate(spread_order(len(group))):
            keyed.append(((j + 0.5) / len(group), kind, group[p].index, group[p]))
    return [k[3] for k in sorted(keyed, key=lambda k: k[:3])]


def restricted(split: Split, events: Sequence[SplitEvent]) -> Split:
    """``split`` on a subset of its events (each keeps its side), with the digest of that subset."""
    keep = {e.index for e in events}
    cal = tuple(i for i in split.calibration if i in keep)
    ho = tuple(i for i in split.heldout if i in keep)
    strata = {k: sum(1 for e in events if e.kind == k) for k in sorted({e.kind for e in events})}
    return Split(split.seed, cal, ho, _digest(split.seed, events, cal, ho), strata)


STAGE_EVENTS = 24  # events per side in the sequential design's first stage (the calibration side of a 60 s drive)
STAGE_COVER = 0.75  # a stage that would take this share of a side or more takes all of it


def stage_sizes(n_side: int, first: int = STAGE_EVENTS) -> list[int]:
    """Events per side of each stage of the sequential design for a side of ``n_side`` events: ``first``, twice
    that, ... (24, 48, 96, ...) while a stage takes under :data:`STAGE_COVER` of the side, then all of it."""
    out: list[int] = []
    n = first
    while n < STAGE_COVER * n_side:
        out.append(n)
        n *= 2
    return [*out, n_side]
