"""What the logger sees: the inverter's speed estimate and CAN frames written as a BLF file.

Speed sensor: the inverter estimates rotor-minus-housing speed as a moving average over
``sensor_window`` (nominal 2 ms) and reports it ``sensor_delay`` later. CAN: every message
(``MCU_Torque``, ``MCU_Speed``, ``ESP_WheelSpeeds``, ``ESP_Vehicle``, ``VCU_Pedal`` of
``dbc/lashscope_ev.dbc``) is sent every 10 ms with its own phase (torque and speed every
``period_s``: 1 ms for a fast logger, 20-50 ms for a slow one); the torque is sampled
``offset`` s away from the speed (drawn within +-15 ms, i.e. under two CAN periods); values get
sensor noise and the DBC's quantisation (raw integers, encoded with cantools); about 0.1 % of the
torque and speed frames carry the not-available raw value; 1 % of frames are dropped plus a few
runs of 2-8 consecutive frames; log timestamps jitter (0.15 ms s.d.) and in a few bursty periods
(``burst_s``, 50-200 ms) frames are held back and logged back-to-back at the end. Alive counters count in the
sender's sequence.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import can
import cantools
import numpy as np

from bench.indep.car import Car

REPO = Path(__file__).resolve().parents[2]
DBC = REPO / "dbc" / "lashscope_ev.dbc"
MAP = REPO / "dbc" / "lashscope_ev.map.toml"
PERIOD = 0.01  # s
RPM = 60 / (2 * np.pi)


@dataclass(frozen=True)
class Recording:
    """How one drive is recorded (noise in signal units, times in s)."""

    speed_noise_rpm: float = 0.5
    torque_noise_nm: float = 0.3
    wheel_noise_rpm: float = 0.2
    jitter_s: float = 0.00015
    drop_fraction: float = 0.01
    sna_fraction: float = 0.001
    max_offset_s: float = 0.015
    drop_runs_per_min: float = 3.0
    bursts_per_min: float = 4.0
    burst_s: tuple[float, float] = (0.05, 0.2)  # s, range of a burst's length
    period_s: float = PERIOD  # s, period of the torque and speed messages


def sensor_speed(car: Car, t: np.ndarray, speed_rel: np.ndarray) -> np.ndarray:
    """Reported motor speed (rpm) on the grid ``t``: trailing moving average then delay."""
    h = float(t[1] - t[0])
    w = max(round(car.sensor_window / h), 1)
    c = np.concatenate([[0.0], np.cumsum(speed_rel)])
    ma = np.empty_like(speed_rel)
    ma[w - 1:] = (c[w:] - c[:-w]) / w
    ma[: w - 1] = ma[w - 1]
    return np.interp(t - car.sensor_delay, t, ma) * RPM


def _raw(sig: cantools.database.can.Signal, phys: np.ndarray) -> np.ndarray:
    """Physical values to raw integers with the DBC's scale, offset and raw range."""
    raw = np.round((phys - sig.offset) / sig.scale)
    bits = sig.length
    lo, hi = (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1) if sig.is_signed else (0, 2**bits - 1)
    return np.clip(raw, lo, hi).astype(np.int64)


def _times(rng: np.random.Generator, duration: float, rec: Recording,
           period: float = PERIOD) -> tuple[np.ndarray, np.ndarray]:
    """(sample times, sender sequence numbers) of one message sent every ``period`` s, with drops."""
    t = float(rng.uniform(0, period)) + np.arange(int(duration / period) - 1) * period
    seq = np.arange(t.size)
    keep = rng.random(t.size) >= rec.drop_fraction
    for start in rng.integers(0, t.size, size=int(rng.poisson(rec.drop_runs_per_min * duration / 60))):
        keep[start:start + int(rng.integers(2, 9))] = False
    return t[keep], seq[keep]


def _log_times(rng: np.random.Generator, t: np.ndarray, bursts: list[tuple[float, float]],
               rec: Recording) -> np.ndarray:
    out = t + np.abs(rng.normal(0, rec.jitter_s, t.size))
    for a, b in bursts:
        inside = (t >= a) & (t < b)
        out[inside] = b + 0.00015 * np.arange(int(inside.sum()))
    return out


def write_drive(path: Path, car: Car, sim: dict[str, np.ndarray], torque_t: np.ndarray, torque: np.ndarray,
                rng: np.random.Generator, rec: Recording | None = None, epoch: float = 1.7e9) -> dict[str, float]:
    """Record a simulated drive (``dynamics.simulate`` output) into a BLF log; returns what was drawn."""
    rec = rec or Recording()
    db = cantools.database.load_file(str(DBC))
    assert isinstance(db, cantools.database.can.Database)  # a .dbc file is a CAN database
    t = sim["t"]
    duration = float(t[-1])
    speed = sensor_speed(car, t, sim["speed_rel"])
    offset = float(rng.uniform(-rec.max_offset_s, rec.max_offset_s))
    n_bursts = int(rng.poisson(rec.bursts_per_min * duration / 60))
    bursts = [(a, a + float(rng.uniform(*rec.burst_s))) for a in rng.uniform(1, duration - 1, size=n_bursts)]
    rows: list[tuple[float, int, bytes]] = []

    def emit(name: str, values: dict[str, np.ndarray], sna: tuple[str, ...] = ()) -> None:
        msg = db.get_message_by_name(name)
        ts, seq = values.pop("_t"), values.pop("_seq")
        raws: dict[str, np.ndarray] = {}
        for sig in msg.signals:
            if sig.name in values:
                raws[sig.name] = _raw(sig, values[sig.name])
                if sig.name in sna and sig.choices:
                    na = next(int(k) for k, v in sig.choices.items() if str(v) == "SNA")
                    raws[sig.name][rng.random(ts.size) < rec.sna_fraction] = na
            elif "Alive" in sig.name:
                raws[sig.name] = seq % 15
            elif "Temp" in sig.name:
                raws[sig.name] = _raw(sig, np.full(ts.size, 40.0))
            elif sig.name == "MotorTorqueState":
                raws[sig.name] = np.full(ts.size, 2)
            elif sig.name == "DriveMode":
                raws[sig.name] = np.full(ts.size, 3)
            else:
                raws[sig.name] = np.zeros(ts.size, np.int64)
        logged = _log_times(rng, ts, bursts, rec)
        names = list(raws)
        for k in range(ts.size):
            data = msg.encode({n: int(raws[n][k]) for n in names}, scaling=False, strict=False)
            rows.append((float(logged[k]), msg.frame_id, bytes(data)))

    tt, sq = _times(rng, duration, rec, rec.period_s)
    tq = np.interp(tt + offset, torque_t, torque) + rng.normal(0, rec.torque_noise_nm, tt.size)
    emit("MCU_Torque", {"_t": tt, "_seq": sq, "MotorTorqueActual": tq, "MotorTorqueRequest": tq},
         ("MotorTorqueActual",))
    ts, sq = _times(rng, duration, rec, rec.period_s)
    emit("MCU_Speed", {"_t": ts, "_seq": sq, "MotorSpeed": np.interp(ts, t, speed)
                       + rng.normal(0, rec.speed_noise_rpm, ts.size)}, ("MotorSpeed",))
    tw, sq = _times(rng, duration, rec)
    wl = np.interp(tw, t, sim["wheel_l"]) * RPM + rng.normal(0, rec.wheel_noise_rpm, tw.size)
    wr = np.interp(tw, t, sim["wheel_r"]) * RPM + rng.normal(0, rec.wheel_noise_rpm, tw.size)
    rear = np.interp(tw, t, sim["body_v"]) / car.radius * RPM
    emit("ESP_WheelSpeeds", {"_t": tw, "_seq": sq, "WheelSpeedFL": wl, "WheelSpeedFR": wr, "WheelSpeedRL": rear,
                             "WheelSpeedRR": rear})
    tv, sq = _times(rng, duration, rec)
    emit("ESP_Vehicle", {"_t": tv, "_seq": sq, "VehicleSpeed": np.interp(tv, t, sim["body_v"]) * 3.6})
    tp, sq = _times(rng, duration, rec)
    emit("VCU_Pedal", {"_t": tp, "_seq": sq, "AccelPedalPos": np.clip(np.interp(tp, torque_t, torque) / 2.5, 0, 100)})
    rows.sort(key=lambda r: (r[0], r[1]))
    path.parent.mkdir(parents=True, exist_ok=True)
    with can.BLFWriter(str(path)) as w:
        for ts_, arb, data in rows:
            w.on_message_received(can.Message(timestamp=epoch + ts_, arbitration_id=arb, is_extended_id=False,
                                              data=data, channel=0))
    return {"offset_s": offset, "frames": float(len(rows)), "bursts": float(len(bursts)), "first_s": rows[0][0]}
