"""Fixed-decimal JSON numbers written by the compiled formatter agree with Python's formatting."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.api.numbers import json_numbers

NUMBERS = st.one_of(st.floats(min_value=-1e12, max_value=1e12), st.sampled_from([np.nan, np.inf, -np.inf]))


@settings(max_examples=60, deadline=None)
@given(st.lists(NUMBERS, max_size=50), st.sampled_from([0, 1, 3, 6]))
def test_parses_back_to_the_rounded_values(values: list[float], decimals: int) -> None:
    a = np.array(values, dtype=np.float64)
    out = json.loads(json_numbers(a, decimals))
    assert len(out) == a.size
    for got, x in zip(out, values, strict=True):
        if not np.isfinite(x):
            assert got is None
        else:  # the last digit may differ from "%.*f" by one unit when x sits on a rounding tie
            assert abs(got - x) <= 0.5 * 10.0**-decimals * (1 + 1e-9) + abs(x) * 1e-15


def test_text_matches_percent_format_and_no_negative_zero() -> None:
    a = np.array([0.0, -0.0, 1.5, -2.25, 1234.5678, -0.0004, 99999.9999, 1e-7])
    assert json_numbers(a, 3).decode() == "[" + ",".join(
        "0.000" if abs(x) < 0.0005 else f"{x:.3f}" for x in a) + "]"
    assert json_numbers(np.array([]), 3) == b"[]"
    assert json_numbers(np.array([7.0, np.nan, -np.inf]), 0) == b"[7,null,null]"


@pytest.mark.parametrize("big", [1e17, -3e20])
def test_values_beyond_the_integer_path_fall_back(big: float) -> None:
    out = json.loads(json_numbers(np.array([1.0, big]), 3))
    assert out == [1.0, pytest.approx(big)]
