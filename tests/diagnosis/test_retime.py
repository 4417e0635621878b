"""Frames a buffering logger held and wrote back-to-back get their sampling times back."""

from __future__ import annotations

import numpy as np

from app.analysis.diagnosis.retime import Retimed, retime_bursts


def _periodic(n: int = 400, period: float = 0.01, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return 0.003 + period * np.arange(n) + rng.normal(0.0, 0.00015, n)


def test_a_held_run_is_spread_back_over_its_hole() -> None:
    truth = _periodic()
    logged = truth.copy()
    logged[101:113] = truth[112] + 0.0001 * np.arange(-11, 1)  # 12 frames held 110 ms, written 0.1 ms apart
    out, fix = retime_bursts(logged, 0.01)
    assert fix == Retimed(bursts=1, frames=11, unresolved=0)
    assert np.max(np.abs(out - truth)) < 0.002  # back within the jitter of where they were sampled
    assert np.all(np.diff(out) > 0)


def test_clean_stamps_and_single_drops_are_left_alone() -> None:
    t = np.delete(_periodic(seed=1), [50, 51, 200])  # dropped frames make holes without a run after them
    out, fix = retime_bursts(t, 0.01)
    assert fix == Retimed()
    assert np.array_equal(out, t)


def test_a_run_with_more_frames_than_its_hole_is_left_as_logged() -> None:
    truth = _periodic(seed=2)
    logged = truth.copy()
    logged[101:113] = truth[103] + 0.0001 * np.arange(12)  # a 20 ms hole cannot have held 12 frames
    logged[113:] += logged[112] - truth[112] + 0.01
    out, fix = retime_bursts(logged, 0.01)
    assert fix.unresolved == 1 and fix.bursts == 0
    assert np.array_equal(out, logged)
