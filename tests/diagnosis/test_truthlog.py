"""Truth drives written as BLF through the reference DBC and read back through the service's ingest."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.errors import InputError
from app.ingest.database import load_database
from app.ingest.pipeline_signals import load_signals
from app.ingest.signalmap import load_signal_map
from tests.conftest import REPO
from tests.diagnosis.conftest import paper
from tests.support.synthetic import CanSampling, DriveSpec, make_drive, measure_frames, run_truth
from tests.support.truthlog import read_log, write_blf

DBC = REPO / "dbc" / "lashscope_ev.dbc"


@pytest.mark.parametrize(("map_name", "period", "shared", "speed_step", "torque_step"), [
    ("lashscope_ev.map.toml", 0.01, False, 0.5, 0.1),
    ("lashscope_ev_1khz.map.toml", 0.001, True, 0.5, 0.1),
])
def test_round_trip_keeps_timing_and_applies_the_dbc_quantisation(tmp_path: Path, map_name: str, period: float,
                                                                  shared: bool, speed_step: float,
                                                                  torque_step: float) -> None:
    rng = np.random.default_rng(3)
    drive = make_drive(paper(), rng, DriveSpec(duration_s=8.0))
    sampling = CanSampling(period_s=period, speed_res_rpm=0.0, torque_res_nm=0.0, offset_s=0.0007,
                           shared_frame=shared, drop_fraction=0.02)
    frames = measure_frames(drive, run_truth(paper(), drive), sampling, rng)
    db, smap = load_database(DBC), load_signal_map(REPO / "dbc" / map_name)
    path = tmp_path / "drive.blf"
    n = write_blf(path, frames, db, smap, start_epoch_s=1.7e9)
    assert n == sum(f.t.size for f in frames.values()) // (2 if shared else 1)
    signals = read_log(path, db, smap)
    # the ingest counts from the file's start time (milliseconds in the BLF header): one offset for all channels
    t0 = float(frames["motor_speed_rpm"].t[0] - signals["motor_speed_rpm"].t[0])
    assert 0.0 <= min(float(f.t[0]) for f in frames.values()) - t0 < 1e-3
    for ch, step in (("motor_speed_rpm", speed_step), ("motor_torque_nm", torque_step)):
        got, want = signals[ch], frames[ch]
        assert len(got) == want.t.size
        np.testing.assert_allclose(got.t, want.t - t0, atol=2e-6)  # frame times kept to the microsecond
        assert np.max(np.abs(got.values - want.values)) <= step / 2 + 1e-9
        assert np.allclose(got.values / step, np.round(got.values / step))


def test_alive_counters_show_the_dropped_frames(tmp_path: Path) -> None:
    rng = np.random.default_rng(4)
    drive = make_drive(paper(), rng, DriveSpec(duration_s=6.0))
    frames = measure_frames(drive, run_truth(paper(), drive), CanSampling(drop_fraction=0.05), rng)
    db, smap = load_database(DBC), load_signal_map(REPO / "dbc" / "lashscope_ev.map.toml")
    path = tmp_path / "drive.blf"
    write_blf(path, frames, db, smap)
    _, report = load_signals(path, db, smap)
    gaps = {g.signal: g for g in report.counter_gaps}
    for ch, counter in (("motor_speed_rpm", "MCU_SpeedAlive"), ("motor_torque_nm", "MCU_TorqueAlive")):
        dropped = int(np.sum(np.diff(np.sort(frames[ch].seq)) - 1))
        assert dropped > 0
        assert gaps[counter].missed == dropped and gaps[counter].modulus == 15


def test_channels_of_one_message_must_share_frames(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    drive = make_drive(paper(), rng, DriveSpec(duration_s=4.0))
    frames = measure_frames(drive, run_truth(paper(), drive), CanSampling(period_s=0.001), rng)  # separate frames
    with pytest.raises(InputError, match="share message MCU_Fast"):
        write_blf(tmp_path / "x.blf", frames, load_database(DBC),
                  load_signal_map(REPO / "dbc" / "lashscope_ev_1khz.map.toml"))
