"""Every error a user can meet survives a pickle round trip (process pools, Dask workers) with its code and message."""

from __future__ import annotations

import inspect
import pickle

import pytest

import app.errors
import sim.errors
from app.fleet.cluster import ClusterStartError, SchedulerUnreachableError

APP_ERRORS = [c for c in vars(app.errors).values() if inspect.isclass(c) and issubclass(c, app.errors.AppError)]
APP_ERRORS += [SchedulerUnreachableError, ClusterStartError]
SIM_ERRORS = [c for c in vars(sim.errors).values() if inspect.isclass(c) and issubclass(c, sim.errors.SimError)
              and c is not sim.errors.ParameterError]


@pytest.mark.parametrize("cls", APP_ERRORS, ids=lambda c: c.__name__)
def test_app_errors_round_trip(cls: type[app.errors.AppError]) -> None:
    err = cls("drive.blf: no CAN frames could be read")
    back = pickle.loads(pickle.dumps(err))
    assert type(back) is cls
    assert back.code == cls.code and back.status == cls.status
    assert str(back) == back.detail == "drive.blf: no CAN frames could be read"


def test_app_error_keeps_an_overridden_code() -> None:
    back = pickle.loads(pickle.dumps(app.errors.InputError("bad value", code="bad_threshold")))
    assert back.code == "bad_threshold" and str(back) == "bad value"


@pytest.mark.parametrize("cls", SIM_ERRORS, ids=lambda c: c.__name__)
def test_sim_errors_round_trip(cls: type[sim.errors.SimError]) -> None:
    back = pickle.loads(pickle.dumps(cls("torque has 1 sample")))
    assert type(back) is cls and back.code == cls.code and str(back) == "torque has 1 sample"


def test_parameter_error_round_trip_keeps_field_value_and_reason() -> None:
    import numpy as np

    err = sim.errors.ParameterError("gaps.halfshaft", np.float64(-0.5), "must be >= 0")
    back = pickle.loads(pickle.dumps(err))
    assert type(back) is sim.errors.ParameterError and back.code == "invalid_parameter"
    assert (back.field, back.value, back.reason) == ("gaps.halfshaft", -0.5, "must be >= 0")
    assert str(back) == str(err) == "gaps.halfshaft = -0.5: must be >= 0"
    assert isinstance(back, ValueError)
