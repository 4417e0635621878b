from __future__ import annotations

from dataclasses import dataclass

import pytest

from app.analysis.diagnosis.split import Split, make_split, require_calibration
from app.errors import AnalysisError


@dataclass(frozen=True)
class Ev:
    index: int
    kind: str
    t_event: float
    speed_rpm: float
    torque_step_nm: float


def events(n: int) -> list[Ev]:
    return [Ev(i, "tip_in" if i % 2 == 0 else "tip_out", 3.0 * i, 2000 + 37 * ((i * 7) % 11), 100 + 10 * (i % 4))
            for i in range(n)]


@pytest.mark.parametrize("n", [6, 7, 12, 13])
def test_split_is_disjoint_balanced_and_stratified(n: int) -> None:
    s = make_split(events(n), seed=3)
    assert set(s.calibration).isdisjoint(s.heldout)
    assert sorted(s.calibration + s.heldout) == list(range(n))
    assert abs(len(s.calibration) - len(s.heldout)) <= 1
    evs = {e.index: e for e in events(n)}
    for kind in ("tip_in", "tip_out"):
        cal = sum(evs[i].kind == kind for i in s.calibration)
        ho = sum(evs[i].kind == kind for i in s.heldout)
        assert abs(cal - ho) <= 1, kind


def test_split_is_reproducible_and_recorded() -> None:
    a, b = make_split(events(12), seed=5), make_split(events(12), seed=5)
    assert a == b and len(a.digest) == 64
    c = make_split(events(12), seed=6)
    assert (c.calibration, c.digest) != (a.calibration, a.digest)
    d = a.to_dict()
    assert d["seed"] == 5 and d["sha256"] == a.digest and d["calibration"] == list(a.calibration)


def test_fit_guard_refuses_heldout_events() -> None:
    evs = events(8)
    s = make_split(evs, seed=1)
    require_calibration(s, s.calibration_events(evs))
    with pytest.raises(AnalysisError, match="not calibration events"):
        require_calibration(s, s.heldout_events(evs)[:1])


def test_overlapping_split_is_rejected() -> None:
    with pytest.raises(AnalysisError, match="not disjoint"):
        Split(0, (1, 2), (2, 3), "x")
