"""Ripple metrics on signals with known answers; what-if transforms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim import ParameterError, WhatIf, load_vehicle
from sim.metrics import (
    impact_induced_fluctuation,
    peak_to_peak,
    peak_to_valley,
    unloaded_intervals,
    unloaded_time,
)
from sim.whatif import antijerk


def test_peak_to_valley_ignores_trend_and_takes_adjacent_valley() -> None:
    t = np.linspace(0.0, 1.0, 2001)
    ramp = 500.0 * t  # a steady rise is not ripple
    assert peak_to_valley(t, ramp) == 0.0
    assert peak_to_peak(t, ramp) == pytest.approx(500.0)
    decaying = 100.0 * np.exp(-3 * t) * np.sin(2 * math.pi * 8 * t)
    # largest fall: first peak (w t = atan(w / 3)) to the next valley, half a period later
    w = 2 * math.pi * 8
    tp = math.atan(w / 3) / w
    expected = 100 * np.exp(-3 * tp) * math.sin(w * tp) * (1 + np.exp(-3 * math.pi / w))
    assert peak_to_valley(t, decaying) == pytest.approx(expected, rel=1e-3)
    assert peak_to_valley(t, decaying, t_start=0.5) < expected / 2


def test_impact_induced_is_difference_peak_to_peak() -> None:
    t = np.linspace(0.0, 1.0, 101)
    base = np.sin(t)
    assert impact_induced_fluctuation(t, base + 0.3 * (t > 0.5), base) == pytest.approx(0.3)
    with pytest.raises(ValueError):
        impact_induced_fluctuation(t, base, base[:-1])


def test_unloaded_time_merges_overlapping_gaps() -> None:
    events = [("spline", 0.100, 0.104), ("halfshaft", 0.101, 0.118), ("mesh1", 0.110, 0.121),
              ("spline", 0.300, math.nan)]
    assert unloaded_intervals(events, 0.5) == [(0.100, 0.121), (0.300, 0.5)]
    assert unloaded_time(events) == pytest.approx(0.021)
    assert unloaded_time(events, t_start=0.2, t_end=0.5) == pytest.approx(0.2)
    assert unloaded_time([], 0.0) == 0.0


def test_antijerk_limits_rate_only_near_zero() -> None:
    t = np.arange(0.0, 0.5, 1e-3)
    step = np.where(t < 0.1, -50.0, 150.0)
    y = antijerk(t, step, rate=500.0, band=20.0)
    rate = np.diff(y) / 1e-3
    near = np.abs(y[:-1]) < 20.0
    assert np.all(np.abs(rate[near]) <= 500.0 + 1e-6)
    assert np.abs(rate).max() <= 2500.0 + 1e-6  # never a step, catch-up at 5x the rate
    assert y[-1] == pytest.approx(150.0)


def test_whatif_vehicle_and_torque() -> None:
    v = load_vehicle("paper")
    w = WhatIf(gap_scale={"halfshaft": 0.0, "all": 0.5}, torque_scale=0.5).apply_vehicle(v)
    assert w.gaps.halfshaft.nominal == 0.0
    assert w.gaps.spline.nominal == pytest.approx(v.gaps.spline.nominal / 2)
    t = np.array([0.0, 0.1])
    _, q, resampled = WhatIf(torque_scale=0.5).apply_torque(t, np.array([10.0, 20.0]))
    assert list(q) == [5.0, 10.0] and not resampled
    with pytest.raises(ParameterError, match=r"gap_scale\.gearbox"):
        WhatIf(gap_scale={"gearbox": 0.5}).apply_vehicle(v)
    with pytest.raises(ParameterError):
        WhatIf(gap_scale={"spline": -1.0})
