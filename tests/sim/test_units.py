"""sim.units: the one definition of the rpm <-> rad/s conversion."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim.units import RAD_S_PER_RPM, RPM_PER_RAD_S, rad_s_to_rpm, rpm_to_rad_s


def test_one_revolution_per_minute() -> None:
    assert rpm_to_rad_s(60.0) == pytest.approx(2 * math.pi, rel=1e-15)
    assert rad_s_to_rpm(2 * math.pi) == pytest.approx(60.0, rel=1e-15)
    assert pytest.approx(1.0, rel=1e-15) == RPM_PER_RAD_S * RAD_S_PER_RPM
    assert 60.0 / (2.0 * math.pi) == RPM_PER_RAD_S  # the spelling signal maps used: the same double


def test_same_bits_as_the_expressions_they_replace() -> None:
    x = np.random.default_rng(3).normal(0.0, 300.0, 10_000)
    assert (rad_s_to_rpm(x) == x * 30.0 / np.pi).all()
    assert (rpm_to_rad_s(x) == x * np.pi / 30.0).all()
    assert isinstance(rad_s_to_rpm(1.5), float)
