"""The identification and the diagnosis on drives of the independent generator (bench/indep), recorded afresh: what
a spent benchmark set found wrong, kept right."""

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


def _lash_and_mass_found(tmp_path, set_name: str, case_name: str) -> None:  # type: ignore[no-untyped-def]
    """The generator's drive ``case_name`` of ``set_name`` recorded afresh and identified: lash within 15 % and mass
    within 5 % of the truth, both named beside stiffness and damping."""
    from app.identify import IdentifyOptions, identify_logs
    from bench.indep.car import vehicle_source
    from bench.indep.record import DBC, MAP
    from bench.modal_recording import record
    from sim import load_vehicle

    case = next(c for c in plan(set_name, False) if c.name == case_name)
    path = tmp_path / "drive.blf"
    record(case, recording(case), 0, path)
    res = identify_logs([path], load_vehicle(vehicle_source(case.car)),
                        IdentifyOptions(dbc=DBC, signal_map=MAP, seed=case.seed))
    lash, mass = res.params["lash"], res.params["mass"]
    assert abs(lash.ratio / case.base["gap_scale"] - 1.0) < 0.15, res.identification.fit_log
    assert abs(mass.ratio / case.base["mass_scale"] - 1.0) < 0.05, res.identification.fit_log
    assert {"lash", "mass", "stiffness", "damping"} <= set(res.identification.named)


def test_a_lash_far_from_the_files_is_found_from_a_start_near_it(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """``ifinal17``'s paper car at 100 Hz with 0.75x the file's lash, 0.92x its mass, 1.15x its stiffness and 0.32x
    its damping. From the file's lash the grey box stopped at 57 chi2 per sample with the lash and the mass at the
    file's (both unnamed); refined again with the lash started at 0.7x and 1.4x, it reaches the truth's basin."""
    from app.identify.fit import LASH_STARTS, lash_starts

    # the second refinement's starts: each start with the lash at each further ratio, the rest as it was
    guess = {"base_lash": {"scale": 1.0}, "base_mass": {"scale": 1.2}}
    nominal = {"base_lash": {"scale": 1.0}, "base_mass": {"scale": 1.0}}
    out = lash_starts(["lash", "mass"], [guess, nominal])
    assert len(out) == 2 * len(LASH_STARTS)
    assert sorted(v["base_lash"]["scale"] for v in out) == sorted(2 * list(LASH_STARTS))
    assert [v["base_mass"] for v in out] == [guess["base_mass"]] * len(LASH_STARTS) + [nominal["base_mass"]] * len(
        LASH_STARTS)
    assert lash_starts(["mass"], [nominal]) == []

    _lash_and_mass_found(tmp_path, "ifinal17", "base_damping_ratio+lash+stiffness+mass_730014")


def test_a_refinement_in_the_files_lash_basin_is_sent_to_the_others_by_its_screen(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """``ifinal19``'s paper car at 1 kHz with 0.71x the file's lash, 0.94x its mass, 1.14x its stiffness and 0.46x its
    damping. The refinement took 83 % of the file's residual and stopped at 298 chi2 per sample with the lash at 1.01x
    and the mass at 1.02x, too large a share taken to be refined again by that rule; its own point with the lash at
    0.7x leaves less, and refined from the lash's other starts it reaches the truth's basin, both named."""
    _lash_and_mass_found(tmp_path, "ifinal19", "base_damping_ratio+lash+stiffness+mass_770017")
