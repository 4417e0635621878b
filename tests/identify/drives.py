"""Drives of a vehicle whose data sheet is off, for the identification tests.

These drives come from the project's own simulator (the identification's forward model): they test
the machinery -- the fit, its intervals, the CLI and the service -- on a known truth. Whether the
identification holds on data it did not make is bench/identify_indep.py's question (an independent
driveline model).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from app.analysis.diagnosis.forward import DiagEvent
from app.analysis.diagnosis.noise import NoiseFloor
from app.analysis.diagnosis.prepare import DIAGNOSIS_EVENTS, prepare
from app.analysis.events import detect_events
from app.identify.base import with_base
from app.ingest.database import load_database
from app.ingest.signalmap import load_signal_map
from app.signals import SignalSet
from sim import Vehicle, load_vehicle
from tests.conftest import REPO
from tests.support.synthetic import (
    CanSampling,
    DriveSpec,
    make_drive,
    measure,
    measure_frames,
    run_truth,
    to_signals,
)
from tests.support.truthlog import write_blf

OFF = {"stiffness": 0.75, "damping": 1.8, "mass": 1.15, "lash": 1.25}  # a data sheet off in every base parameter


def drive_signals(truth: Mapping[str, float], seed: int, duration_s: float = 40.0, vehicle: str = "paper",
                  sampling: CanSampling | None = None) -> SignalSet:
    """Torque and speed of a drive of ``vehicle`` with base parameters ``truth`` (ratios to its file's)."""
    nominal = load_vehicle(vehicle)
    rng = np.random.default_rng(seed)
    drive = make_drive(nominal, rng, DriveSpec(duration_s=duration_s))
    res = run_truth(with_base(nominal, truth), drive)
    return to_signals(measure(drive, res, sampling or CanSampling(period_s=0.01), rng))


def prepared(signals: SignalSet) -> tuple[list[DiagEvent], NoiseFloor]:
    events, noise, _ = prepare(signals, detect_events(signals, DIAGNOSIS_EVENTS))
    return events, noise


def write_drive_log(path: Path, truth: Mapping[str, float], seed: int, duration_s: float = 40.0,
                    vehicle: Vehicle | None = None, period_s: float = 0.01) -> Path:
    """A drive of the paper car with base parameters ``truth``, written as BLF through the reference DBC."""
    nominal = vehicle or load_vehicle("paper")
    rng = np.random.default_rng(seed)
    drive = make_drive(nominal, rng, DriveSpec(duration_s=duration_s))
    res = run_truth(with_base(nominal, truth), drive)
    frames = measure_frames(drive, res, CanSampling(period_s=period_s, offset_s=0.004), rng)
    write_blf(path, frames, load_database(REPO / "dbc" / "lashscope_ev.dbc"),
              load_signal_map(REPO / "dbc" / "lashscope_ev.map.toml"))
    return path
