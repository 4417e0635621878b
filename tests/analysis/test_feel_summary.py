"""The summary of the drivability criteria over events: per event kind, and no median that mixes the signs of
tip-ins and tip-outs."""

from __future__ import annotations

import math

import pytest

from app.analysis.drivability import CRITERIA_NAMES, Drivability, difference
from app.analysis.feel import FeelComparison, summarize_feel
from app.cli.report import drivability_table


def _side(kick: float, settled: float) -> Drivability:
    return Drivability(0.1, kick, 2 * kick, 7.5, 0.06, 40.0, 0.05, 1.2, settled)


def _row(kick: float, settled: float, sim_offset: float = 0.0) -> FeelComparison:
    m, s = _side(kick, settled), _side(kick + sim_offset, settled + sim_offset)
    return FeelComparison("accelerometer", m, s, difference(m, s))


ROWS = [_row(0.8, 2.4), _row(0.9, 2.6, 0.1), _row(1.0, 2.5), _row(0.5, -1.2), _row(0.4, -1.0, -0.2)]
KINDS = ["tip_in", "tip_in", "tip_in", "tip_out", "tip_out"]


def test_signed_criteria_have_medians_per_event_kind_only() -> None:
    summ = summarize_feel(ROWS, KINDS)
    assert set(summ) == set(CRITERIA_NAMES)
    settled = summ["settled_accel_ms2"]
    # the median over all five (2.4) would be neither kind's level
    assert all(math.isnan(settled[k]) for k in ("measured_median", "simulated_median", "difference_median"))  # type: ignore[arg-type]
    assert settled["events"] == 5
    assert settled["tip_in"] == {"measured_median": 2.5, "simulated_median": pytest.approx(2.5),
                                 "difference_median": 0.0, "events": 3}
    tip_out = settled["tip_out"]
    assert isinstance(tip_out, dict)
    assert tip_out["measured_median"] == pytest.approx(-1.1) and tip_out["simulated_median"] == pytest.approx(-1.2)
    assert tip_out["difference_median"] == pytest.approx(-0.1) and tip_out["events"] == 2


def test_criteria_along_the_torque_change_keep_the_median_over_all_events() -> None:
    kick = summarize_feel(ROWS, KINDS)["kick_ms2"]
    assert kick["measured_median"] == pytest.approx(0.8) and kick["events"] == 5
    assert kick["tip_in"]["measured_median"] == pytest.approx(0.9)  # type: ignore[index]
    assert kick["tip_out"]["measured_median"] == pytest.approx(0.45)  # type: ignore[index]
    assert kick["tip_in"]["difference_median"] == pytest.approx(0.0)  # type: ignore[index]


def test_without_kinds_the_all_event_medians_only_and_mismatched_kinds_are_refused() -> None:
    summ = summarize_feel(ROWS)
    assert "tip_in" not in summ["kick_ms2"] and summ["kick_ms2"]["measured_median"] == pytest.approx(0.8)
    with pytest.raises(ValueError, match="4 event kinds for 5 rows"):
        summarize_feel(ROWS, KINDS[:4])


def test_one_kind_only_leaves_the_other_empty() -> None:
    summ = summarize_feel(ROWS[:3], KINDS[:3])
    tip_out = summ["settled_accel_ms2"]["tip_out"]
    assert isinstance(tip_out, dict) and tip_out["events"] == 0 and math.isnan(tip_out["measured_median"])


def test_cli_table_prints_the_settled_acceleration_per_kind() -> None:
    doc = {"summary": {"drivability": summarize_feel(ROWS, KINDS)}, "acceleration": {"kind": "accelerometer"}}
    lines = drivability_table(doc).splitlines()
    tip_in = next(line for line in lines if line.startswith("settled accel. (tip-in)"))
    tip_out = next(line for line in lines if line.startswith("settled accel. (tip-out)"))
    assert tip_in.split()[3:6] == ["2.50", "2.50", "0.00"]
    assert tip_out.split()[3:6] == ["-1.10", "-1.20", "-0.10"]
    assert any(line.startswith("kick (1st peak over settled)") and "0.80" in line for line in lines)
