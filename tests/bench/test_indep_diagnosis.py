"""The diagnosis on a drive of the independent generator (bench/indep), recorded afresh: what a spent benchmark set
found wrong, kept right."""

from __future__ import annotations

from bench.indep.cases import plan, recording


def test_a_lag_on_a_heavier_car_than_its_file_is_named_with_the_cars_mass(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """``ifinal16``'s paper car 15 % heavier than its file (lash 14 % over, damping 10 % over) whose motor torque lags
    the CAN value by 13 ms with 14 ms of dead time. Fitted jointly with the base parameters, the lag stopped with the
    torque gain on its 0.85 bound and the mass at 0.99x, and the speed filter beat it: `partial speed_sensor`, the one
    wrong-confident answer of that set. Refined again along the rigid body's gain-mass ridge, the lag is named, with
    the car's mass and lash."""
    from app.analysis.diagnosis import DiagnosisOptions, diagnose_signals
    from bench.indep.car import vehicle_source
    from bench.indep.record import DBC, MAP
    from bench.modal_recording import record
    from sim import load_vehicle
    from tests.support.truthlog import read_log

    case = next(c for c in plan("ifinal16", False) if c.name == "base_effect_torque_lag_710020")
    path = tmp_path / "drive.blf"
    record(case, recording(case), 0, path)
    res = diagnose_signals(read_log(path, DBC, MAP), load_vehicle(vehicle_source(case.car)),
                           DiagnosisOptions(seed=case.seed))
    d = res.decision
    assert d.status in ("explained", "partial") and d.top == ("torque_lag",), d.reason
    lag = res.candidates["torque_lag"].fit
    base = {item["name"]: item for item in d.details.get("base_parameters", [])}
    assert "mass" in base, d.details.get("base_parameters")
    assert abs(base["mass"]["ratio"] - case.base["mass_scale"]) < 0.03
    assert abs(lag.values["torque_lag"]["tau_s"] - case.effects["torque_lag"]["tau_s"]) < 0.003, lag.values
