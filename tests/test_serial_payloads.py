"""The dicts of the payload dataclasses whose keys and rounding no other test pins (REST, stored JSON, reports)."""

from __future__ import annotations

import math

from app.analysis.accel import AccelCheck
from app.analysis.diagnosis.calibrate import FitResult
from app.analysis.diagnosis.decide import Decision, DecisionRules
from app.analysis.diagnosis.forward import Nuisance
from app.analysis.diagnosis.score import Interval
from app.analysis.diagnosis.split import Split
from app.analysis.diagnosis.structure import RemainderTest
from app.analysis.diagnosis.validate import Validation
from app.identify.fit import Param
from app.identify.rigid import RigidBody
from app.ingest.signalmap import SignalMap
from app.ingest.suggest import Candidate
from app.signal_proposal import ChannelEvidence, Proposal

NAN, INF = math.nan, math.inf


def test_accel_check() -> None:
    d = AccelCheck("ok", 0.98, -0.1, ((1.0, 1.5), (3.0, 3.25))).to_dict()
    assert d == {"verdict": "ok", "slope": 0.98, "offset_ms2": -0.1, "saturated_s": [[1.0, 1.5], [3.0, 3.25]]}
    assert AccelCheck("unchecked").to_dict()["saturated_s"] == []


def test_interval_four_digits_nan_when_not_finite() -> None:
    d = Interval(0.123456, -INF, 2).to_dict()
    assert d["value"] == 0.1235 and math.isnan(d["lo"]) and d["hi"] == 2.0 and type(d["hi"]) is float


def test_nuisance_and_fit_result() -> None:
    assert Nuisance(0.01, 1.1, -2.0).to_dict() == {"offset_s": 0.01, "gain": 1.1, "road_load_grade_pct": -2.0}
    fit = FitResult(("lag", "drag"), Nuisance(0.0123456789, 1.0, 0.5), {"lag": {"tau": 0.0123456789}}, 100.0, 30,
                    12, ("lag.tau",), "converged", (("lag.tau", "drag.c", -0.987654),))
    d = fit.to_dict()
    assert d == {"effects": ["lag", "drag"],
                 "nuisance": {"offset_s": 0.012346, "gain": 1.0, "road_load_grade_pct": 0.5},
                 "params": {"lag": {"tau": 0.012346}}, "calibration_chi2_per_sample": 3.3333,
                 "simulator_passes": 12, "at_bound": ["lag.tau"],
                 "trade_offs": [{"params": ["lag.tau", "drag.c"], "correlation": -0.9877}]}
    assert list(d) == ["effects", "nuisance", "params", "calibration_chi2_per_sample", "simulator_passes", "at_bound",
                       "trade_offs"]
    assert FitResult((), Nuisance(), {}, 5.0, 0, 1).to_dict()["calibration_chi2_per_sample"] == 5.0  # n of 0: 1


def test_decision() -> None:
    rules = DecisionRules().to_dict()
    assert list(rules)[:2] == ["min_events_per_side", "min_gap_ratio"] and rules["max_event_share"] == 0.5
    d = Decision("undecided", ("lag",), (), "too few events", Interval(1.5, 1.2, 1.9), None, {"events": 4}).to_dict()
    assert d == {"status": "undecided", "top": ["lag"], "confusable": None, "reason": "too few events",
                 "residual_to_noise_before": {"value": 1.5, "lo": 1.2, "hi": 1.9}, "events": 4}
    d = Decision("decided", confusable=("a", "b"), details={"reason": "replaced in place"}).to_dict()
    assert list(d.items()) == [("status", "decided"), ("top", []), ("confusable", ["a", "b"]),
                               ("reason", "replaced in place"), ("residual_to_noise_before", None)]


def test_split() -> None:
    d = Split(7, (0, 2), (1,), "ab" * 32, {"tip_in": 2}).to_dict()
    assert d == {"seed": 7, "calibration": [0, 2], "heldout": [1], "sha256": "ab" * 32, "strata": {"tip_in": 2}}


def test_remainder_test_none_when_not_finite() -> None:
    t = RemainderTest(Interval(1.23456, 1.1, INF), Interval(NAN, NAN, NAN), 2.0, 0.012345, 1.55556, 0.9,
                      (("impact", Interval(3.0, 2.0, 4.44444)),))
    assert t.to_dict() == {"overall": {"value": 1.2346, "lo": 1.1, "hi": None},
                           "impact": {"value": None, "lo": None, "hi": None},
                           "locked": {"value": 2.0, "p_value": 0.0123, "null_95": 1.5556},
                           "phases": {"impact": {"value": 3.0, "lo": 2.0, "hi": 4.4444}}}


def test_validation() -> None:
    v = Validation({"lag": {"tau": 0.02}}, 9, Interval(0.5, 0.4, 0.6), Interval(0.7, 0.6, 0.8), 0.777777, 2.000049,
                   1.23456, {"gain": 1.0}, {"gain": 1.01})
    assert v.to_dict() == {"effects": {"lag": {"tau": 0.02}}, "events": 9,
                           "shrink": {"value": 0.5, "lo": 0.4, "hi": 0.6},
                           "explained_share": {"value": 0.7, "lo": 0.6, "hi": 0.8}, "improved_fraction": 0.7778,
                           "residual_to_noise_baseline": 2.0, "residual_to_noise_augmented": 1.2346,
                           "nuisance_baseline": {"gain": 1.0}, "nuisance_augmented": {"gain": 1.01}}


def test_param() -> None:
    p = Param("stiffness", "torsional stiffness", "N m/rad", 79.123456789, NAN, INF, 100, 0.79123456789, 0.7, 0.8,
              True, False, True)
    assert p.to_dict() == {"name": "stiffness", "label": "torsional stiffness", "unit": "N m/rad", "value": 79.123457,
                           "lo": None, "hi": None, "nominal": 100.0, "ratio": 0.791235, "ratio_lo": 0.7,
                           "ratio_hi": 0.8, "identified": True, "at_bound": False, "named": True, "note": ""}
    assert type(p.to_dict()["nominal"]) is float


def test_rigid_body() -> None:
    d = RigidBody(0.1234567, (0.11, 0.15), 0.1, 42.12345, 0.8765432).to_dict()
    assert list(d) == ["inertia_kgm2", "ci", "file_inertia_kgm2", "ratio", "off_the_file", "driving_s", "r2",
                       "reason", "summary"]
    assert {k: v for k, v in d.items() if k != "summary"} == {
        "inertia_kgm2": 0.123457, "ci": [0.11, 0.15], "file_inertia_kgm2": 0.1, "ratio": 1.234567,
        "off_the_file": True, "driving_s": 42.123, "r2": 0.876543, "reason": None}
    assert d["summary"].startswith("rigid body (model-free, 42 s of driving")
    none = RigidBody(None, None, 0.1, 0, None, "no driving").to_dict()
    assert none["ci"] is None and none["ratio"] is None and none["reason"] == "no driving"
    assert none["driving_s"] == 0 and type(none["driving_s"]) is int


def test_signal_proposal() -> None:
    ev = ChannelEvidence("motor_speed_rpm", "Motor.Speed", "rpm", "rpm", 1.0, False, "suggested", 0.9, ("name",), 100,
                         100.0, -10.0, 6000.0, None, "nothing", "positive")
    assert ev.to_dict() == {"channel": "motor_speed_rpm", "source": "Motor.Speed", "dbc_unit": "rpm", "unit": "rpm",
                            "factor": 1.0, "invert": False, "chosen_by": "suggested", "score": 0.9,
                            "reasons": ("name",), "samples": 100, "rate_hz": 100.0, "minimum": -10.0,
                            "maximum": 6000.0, "correlation": None, "correlation_with": "nothing",
                            "sign": "positive"}
    smap = SignalMap("v", {})
    cand = Candidate("motor_speed_rpm", "Motor", 0x100, "Speed", "rpm", 0.9, ())
    prop = Proposal(smap, {"motor_speed_rpm": ev}, {"motor_speed_rpm": [cand]}, "db.dbc", "asc", 10, 1.5,
                    ["torque_nm"])
    assert prop.to_dict() == {"database": "db.dbc", "log_format": "asc", "frames": 10, "duration_s": 1.5,
                              "missing": ["torque_nm"], "channels": [ev.to_dict()],
                              "candidates": {"motor_speed_rpm": ["Motor.Speed"]}, "signal_map_toml": smap.to_toml()}
