"""Small synthetic drives with known truth, built once per session (the simulator is the truth)."""

from __future__ import annotations

from collections.abc import Callable
from functools import cache

import numpy as np
import pytest

from app.signals import SignalSet
from sim import Vehicle, load_vehicle
from sim.effects import apply_effects
from tests.support.synthetic import CanSampling, DriveSpec, make_drive, measure, run_truth, to_signals

SHORT = DriveSpec(duration_s=30.0)


@cache
def paper() -> Vehicle:
    return load_vehicle("paper")


@cache
def drive_signals(effect: str | None, values: tuple[tuple[str, float], ...], seed: int,
                  duration_s: float = 30.0, offset_s: float = 0.006,
                 hold_s: tuple[float, float] = SHORT.hold_s) -> SignalSet:
    """A CAN-like measurement of the paper vehicle plus ``effect`` driven by a random tip-in/out drive
    (``hold_s``: how long each torque level is held between reversals, s)."""
    v = paper()
    truth = apply_effects(v, {effect: dict(values)}) if effect else v
    rng = np.random.default_rng(seed)
    drive = make_drive(v, rng, DriveSpec(duration_s=duration_s, hold_s=hold_s))
    return to_signals(measure(drive, run_truth(truth, drive), CanSampling(offset_s=offset_s), rng))


@pytest.fixture(scope="session")
def signals_for() -> Callable[..., SignalSet]:
    return drive_signals
