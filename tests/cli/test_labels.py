"""Every printed figure says what it is: detrended or raw, median of differences, shares over 100 %, units, no nan."""

from __future__ import annotations

from typing import Any

from app.cli.analyze import tolerance_table
from app.cli.diagnose import OVER_FULL_NOTE, summary
from app.cli.live import _event_line, _status_line
from app.cli.report import metrics_table


def test_the_metrics_table_says_what_sim_meas_is() -> None:
    doc = {"summary": {"metrics": {"fluctuation_rpm": {"measured_median": 71.7, "simulated_median": 66.7,
                                                       "difference_median": 0.7}}}}
    out = metrics_table(doc)
    assert "sim-meas: median of the per-event differences (not the difference of the two medians)" in out
    assert "detrended from the rigid-body trend" in out


def test_the_tolerance_table_tells_raw_from_detrended() -> None:
    tol = {"n": 8, "seed": 0, "metric": "m", "events": [
        {"index": 0, "kind": "tip_in", "band_rpm": {"p5": 1.0, "p50": 2.0, "p95": 3.0}, "nominal_fluctuation_rpm": 2.0,
         "measured_fluctuation_rpm": 2.5, "measured_percentile": 60.0, "analysis_fluctuation_rpm": 3.5}]}
    out = tolerance_table(tol)
    assert "raw, rpm" in out and "meas., rpm" in out and "detrended" in out
    assert out.splitlines()[3].split()[-3:] == ["3.5", "-", "-"]  # detrended, then the felt band and measured p-p


def _diagnosis(share: float) -> dict[str, Any]:
    iv = {"value": share, "lo": share - 0.1, "hi": share + 0.05}
    return {"decision": {"status": "explained", "top": ["torque_lag"], "reason": "r"},
            "split": {"seed": 0, "calibration": [0, 1], "heldout": [2], "sha256": "0" * 64},
            "noise_floor": {"sigma_rpm": 1.0, "quant_step_rpm": 0.5, "jitter_s": 1e-4, "period_s": 0.01},
            "baseline": None, "pairs": [],
            "candidates": [{"id": "torque_lag", "effects": ["torque_lag"], "fit": {"params": {}},
                            "heldout": {"shrink": iv, "explained_share": iv, "improved_fraction": 1.0}}],
            "elapsed_s": 39.0}


def test_diagnose_stars_a_share_over_100_percent_and_labels_its_time() -> None:
    out = summary(_diagnosis(1.03))
    assert "103 %* [93, 108]" in out and OVER_FULL_NOTE in out
    assert "diagnosis took 39.0 s (wall time)" in out and "\n39.0 s" not in out
    plain = summary(_diagnosis(0.8))
    assert "80 % [70, 85]" in plain and OVER_FULL_NOTE not in plain


def test_live_lines_show_no_nan() -> None:
    line = _event_line({"index": 3, "kind": "tip_in", "t_cross_s": 1.5, "included": True,
                        "metrics": {"fluctuation_rpm": 120.0, "gap_open_time_s": float("nan")}})
    assert "nan" not in line and "gap-open - ms" in line and "fluctuation 120.0 rpm" in line
    assert "nan" not in _event_line({"index": 0, "kind": "tip_out", "t_cross_s": 0.2, "included": True,
                                     "metrics": {"gap_open_time_s": None}})
    st = {"id": "s", "latency_ms": {"p50": None}, "bus": {"state": "active"}, "frames_received": 0,
          "frames_per_s": 0.0, "frames_dropped": 0, "bus_errors": 0, "decode_errors": 0, "unknown_id_frames": 0,
          "events": 0}
    assert "None" not in _status_line(st) and "latency p50 - ms" in _status_line(st)


def test_diagnose_says_why_the_identification_was_skipped() -> None:
    doc = _diagnosis(0.8)
    doc["identification"] = {"skipped": "not identified: identification needs at least 4 usable tip-in/tip-out "
                                        "events; the log gives 3"}
    out = summary(doc)
    assert "identification of the base parameters skipped: not identified: identification needs at least 4" in out
