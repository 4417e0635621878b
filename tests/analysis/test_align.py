from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.analysis.align import common_time_base, downsample_minmax, estimate_lag, overlap, shift
from app.analysis.compare import speed_error
from app.errors import InputError, InsufficientDataError
from app.signals import Signal
from tests.analysis.synthetic import damped_response


def test_common_time_base_is_uniform_and_inclusive() -> None:
    t = common_time_base(1.0, 2.0, 0.1)
    assert t.size == 11 and t[-1] == pytest.approx(2.0)
    with pytest.raises(InputError):
        common_time_base(0.0, 1.0, 0.0)
    with pytest.raises(InsufficientDataError):
        common_time_base(2.0, 1.0, 0.1)


def test_overlap_of_signals() -> None:
    a = Signal.from_samples("a", [0.0, 1.0, 5.0], [0, 0, 0])
    b = Signal.from_samples("b", [0.5, 4.0], [0, 0])
    assert overlap([a, b]) == (0.5, 4.0)


@pytest.mark.parametrize("lag", [0.0, 0.0123, -0.0071, 0.03])
def test_estimate_lag_recovers_a_known_delay(lag: float) -> None:
    dt = 0.001
    t = np.arange(0, 6, dt)
    ref = sum(damped_response(t, 7.0, 0.1, 100.0, t0) for t0 in (1.0, 3.0, 4.5)) + 20 * t
    target = sum(damped_response(t, 7.0, 0.1, 100.0, t0 + lag) for t0 in (1.0, 3.0, 4.5)) + 20 * t + 300
    est = estimate_lag(ref, target, dt, max_lag_s=0.05)
    assert est.lag_s == pytest.approx(lag, abs=0.5 * dt)
    assert est.correlation > 0.95
    # shifting the reference by the estimate lines the two up
    moved = shift(Signal("r", t, ref), est.lag_s).at(t)
    ok = np.isfinite(moved)
    assert np.max(np.abs(np.diff(moved[ok]) - np.diff(target[ok]))) < 1.0


def test_estimate_lag_uses_only_masked_samples() -> None:
    dt = 0.001
    t = np.arange(0, 4, dt)
    ref = damped_response(t, 7.0, 0.1, 100.0, 1.0) + damped_response(t, 7.0, 0.1, 100.0, 3.0)
    # the second event is delayed by 20 ms in the target; the first by 5 ms
    target = damped_response(t, 7.0, 0.1, 100.0, 1.005) + damped_response(t, 7.0, 0.1, 100.0, 3.02)
    assert estimate_lag(ref, target, dt, 0.05, mask=(t > 2.5)).lag_s == pytest.approx(0.02, abs=0.001)
    assert estimate_lag(ref, target, dt, 0.05, mask=(t < 2.5)).lag_s == pytest.approx(0.005, abs=0.001)


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(min_value=1, max_value=5000),
    max_points=st.integers(min_value=6, max_value=600),
    seed=st.integers(min_value=0, max_value=2**16),
)
def test_downsample_keeps_extremes_and_respects_max_points(n: int, max_points: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=float)
    a = rng.normal(size=n).cumsum()
    b = rng.normal(size=n)
    b[rng.random(n) < 0.1] = np.nan
    td, cols = downsample_minmax(t, {"a": a, "b": b}, max_points)
    assert td.size <= max(max_points, n if n <= max_points else 0) and td.size <= n
    assert np.all(np.diff(td) > 0)
    assert cols["a"].max() == a.max() and cols["a"].min() == a.min()
    if np.isfinite(b).any():
        assert np.nanmax(cols["b"]) == np.nanmax(b) and np.nanmin(cols["b"]) == np.nanmin(b)
    assert td[0] == t[0] and td[-1] == t[-1]


def test_downsample_rejects_absurd_max_points() -> None:
    with pytest.raises(InputError, match="max_points"):
        downsample_minmax(np.arange(10.0), {"a": np.arange(10.0)}, 3)


def test_speed_error_rms_and_nrmse() -> None:
    meas = np.array([0.0, 10.0, 20.0, np.nan])
    sim = np.array([1.0, 9.0, 21.0, 5.0])
    err = speed_error(meas, sim)
    assert err.rms_rpm == pytest.approx(1.0) and err.nrmse == pytest.approx(0.05)
    assert err.bias_rpm == pytest.approx(1.0 / 3) and err.samples == 3
