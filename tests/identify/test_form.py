"""The contact law the log chooses (app/identify/form.py), on drives of the project's own simulator."""

from __future__ import annotations

import numpy as np
import pytest

from app.identify import FitOptions, identify_events
from app.identify.form import FORM_SHARE, alternative
from sim import Vehicle, load_vehicle
from tests.conftest import REPO
from tests.identify.drives import prepared
from tests.support.synthetic import CanSampling, DriveSpec, make_drive, measure, run_truth, to_signals

CHAIN = load_vehicle(str(REPO / "bench" / "indep" / "chain_low.toml"))
# the chain car with its shafts damped to a ratio near 0.5: where the two laws part
SOFT = CHAIN.with_changes({f"stage.{n}.damping": 3.0 * float(CHAIN.get(f"stage.{n}.damping"))
                           for n in ("motor_shaft", "chain", "differential", "halfshaft")})


def _identify(truth: Vehicle, file: Vehicle, seed: int):  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(seed)
    drive = make_drive(truth, rng, DriveSpec(duration_s=40.0))
    signals = to_signals(measure(drive, run_truth(truth, drive), CanSampling(period_s=0.01), rng))
    events, noise = prepared(signals)
    return identify_events(events, noise, file, FitOptions(seed=seed))


def test_no_choice_without_a_damped_clearance() -> None:
    tight = SOFT.with_changes({f"stage.{n}.lash_rad": 0.0 for n in ("motor_shaft", "chain", "differential",
                                                                       "halfshaft")})
    assert alternative(tight) is None
    assert alternative(SOFT).contact_damping == "full"  # type: ignore[union-attr]
    assert alternative(SOFT.with_changes({"contact_damping": "full"})).contact_damping == "limited"  # type: ignore[union-attr]


@pytest.fixture(scope="module")
def chosen_full():  # type: ignore[no-untyped-def]
    return _identify(SOFT.with_changes({"contact_damping": "full"}), SOFT, 11)


def test_a_car_whose_dampers_act_in_full_gets_the_full_law(chosen_full) -> None:  # type: ignore[no-untyped-def]
    ident = chosen_full
    form = ident.form
    assert form["file"] == "limited" and form["contact_damping"] == "full" and form["changed"] is True
    res = form["residual_to_noise"]
    assert res["full"] <= FORM_SHARE * res["limited"]
    assert res["full"] < 2.0  # the right law reaches the noise floor's neighbourhood
    assert ident.vehicle.contact_damping == "full" and ident.on.contact_damping == "full"
    assert ident.written_vehicle.to_dict()["contact_damping"] == "full"
    assert ident.to_dict()["contact_damping"] == form
    assert any(line.startswith("contact damping: full (the file says limited)") for line in ident.fit_log)
    # model form, not a data sheet that is off: nothing is named on a file whose values are the truth's
    assert ident.named == []


def test_a_car_that_follows_the_files_law_keeps_it() -> None:
    ident = _identify(SOFT, SOFT, 12)
    assert ident.form["contact_damping"] == "limited" and ident.form["changed"] is False
    assert ident.vehicle.contact_damping == "limited"
    assert "contact_damping" not in ident.written_vehicle.to_dict()
    assert ident.named == []
