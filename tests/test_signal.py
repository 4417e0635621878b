from __future__ import annotations

import numpy as np
import pytest

from app.signals import Interp, Signal, SignalSet


def test_from_samples_sorts_and_drops_duplicate_times() -> None:
    s = Signal.from_samples("x", [0.2, 0.0, 0.1, 0.1], [3.0, 1.0, 2.0, 2.5])
    assert s.t.tolist() == [0.0, 0.1, 0.2]
    assert s.values.tolist() == [1.0, 2.5, 3.0]


@pytest.mark.parametrize(
    ("interp", "expected"),
    [(Interp.LINEAR, [np.nan, 0.5, 1.5, np.nan]), (Interp.PREVIOUS, [np.nan, 0.0, 1.0, 2.0])],
)
def test_at_respects_interpolation_mode(interp: Interp, expected: list[float]) -> None:
    s = Signal.from_samples("x", [0.0, 1.0, 2.0], [0.0, 1.0, 2.0], interp=interp)
    np.testing.assert_array_equal(s.at([-1.0, 0.5, 1.5, 3.0]), expected)


def test_shape_mismatch_is_an_error() -> None:
    with pytest.raises(ValueError, match="3 times but 2 values"):
        Signal.from_samples("x", [0, 1, 2], [1, 2])


def test_signal_set_span() -> None:
    ss = SignalSet()
    ss.add(Signal.from_samples("a", [0.5, 1.0], [0, 0]))
    ss.add(Signal.from_samples("b", [0.1, 2.0], [0, 0]))
    assert ss.span() == (0.1, 2.0)
    assert set(ss) == {"a", "b"}
