"""A synthetic test drive as CAN frames: tip-ins and tip-outs with driveline ripple.

Frames are encoded with cantools from a small DBC written here; torque reverses every
``period_s`` with a steep ramp, the motor speed follows a rigid trend plus a damped
shuffle oscillation after each reversal, the pedal steps ahead of the torque. Extra
traffic the DBC does not define (an OBD request ID) and optional error frames make it
a realistic bus. Everything is seeded.
"""

from __future__ import annotations

from pathlib import Path

import can
import cantools
import numpy as np

from app.ingest.frames import FrameChunk, FrameFlag

DBC = """VERSION ""

NS_ :

BS_:

BU_: VCU INV

BO_ 264 Inverter: 8 INV
 SG_ MotorTorque : 0|16@1+ (0.1,-3276.8) [-3276.8|3276.7] "Nm" VCU
 SG_ MotorSpeed : 16|16@1- (0.5,0) [-16384|16383.5] "rpm" VCU
 SG_ InvCounter : 32|4@1+ (1,0) [0|15] "" VCU

BO_ 280 Pedal: 8 VCU
 SG_ PedalPos : 0|8@1+ (0.4,0) [0|100] "%" INV
 SG_ BrakeSwitch : 8|1@1+ (1,0) [0|1] "" INV

BO_ 2566844926 Extended_Status: 8 VCU
 SG_ Soc : 0|8@1+ (0.5,0) [0|100] "%" INV
"""

CHANNELS = {  # canonical channel -> (message, signal)
    "motor_torque_nm": ("Inverter", "MotorTorque"),
    "motor_speed_rpm": ("Inverter", "MotorSpeed"),
    "pedal_pct": ("Pedal", "PedalPos"),
}
UNKNOWN_ID = 0x7DF


def write_dbc(folder: Path) -> Path:
    """The DBC, and beside it ``drive.map.toml``, the signal map to the canonical channels."""
    path = folder / "drive.dbc"
    path.write_text(DBC, encoding="ascii")
    lines = ['[vehicle]', 'name = "synthetic test drive"', '']
    for channel, (message, signal) in CHANNELS.items():
        lines += [f"[channels.{channel}]", f'message = "{message}"', f'signal = "{signal}"', ""]
    (folder / "drive.map.toml").write_text("\n".join(lines), encoding="ascii")
    return path


def map_of(dbc: Path) -> Path:
    return dbc.parent / "drive.map.toml"


def profile(t: np.ndarray, period_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Torque (N m), speed (rpm), pedal (%) at times ``t`` (s)."""
    phase = np.floor(t / period_s).astype(int)
    since = t - phase * period_s
    drive = phase % 2 == 1  # odd periods: drive torque; even: regen
    ramp = np.clip((since - 0.5) / 0.12, 0.0, 1.0)  # reversal starts 0.5 s into the period
    lo, hi = -60.0, 140.0
    torque = np.where(drive, lo + (hi - lo) * ramp, hi + (lo - hi) * ramp)
    torque = np.where(phase == 0, lo, torque)
    direction = np.where(drive, 1.0, -1.0)
    t_rev = since - 0.56
    ripple = np.where((t_rev > 0) & (phase > 0),
                      direction * 25.0 * np.exp(-2.5 * t_rev) * np.sin(2 * np.pi * 7.0 * t_rev), 0.0)
    speed = 1500.0 + 20.0 * t + ripple
    # the pedal moves 50 ms ahead of the torque: pressed for drive, released for regen
    pedal = np.where(drive == (since > 0.45), 35.0, 4.0)
    pedal = np.where(phase == 0, 4.0, pedal)
    return torque, speed, pedal


def drive_messages(duration_s: float = 8.0, period_s: float = 2.0, seed: int = 5, error_frames: int = 0,
                   t_start: float = 0.0) -> list[can.Message]:
    """All frames of the drive in time order (``timestamp`` in s from ``t_start``)."""
    db = cantools.database.load_string(DBC, "dbc")
    inv, ped, ext = (db.get_message_by_name(n) for n in ("Inverter", "Pedal", "Extended_Status"))
    rng = np.random.default_rng(seed)
    msgs: list[can.Message] = []
    t10 = np.arange(0.0, duration_s, 0.01)
    torque, speed, pedal = profile(t10, period_s)
    speed = speed + rng.normal(0, 0.3, t10.size)
    for k, t in enumerate(t10):
        jitter = float(rng.uniform(0, 0.0004))
        data = inv.encode({"MotorTorque": round(float(torque[k]), 1), "MotorSpeed": round(float(speed[k]) * 2) / 2,
                           "InvCounter": k % 16})
        msgs.append(can.Message(timestamp=t_start + t + jitter, arbitration_id=inv.frame_id, data=data,
                                is_extended_id=False))
        data = ped.encode({"PedalPos": round(float(pedal[k]) / 0.4) * 0.4, "BrakeSwitch": 0})
        msgs.append(can.Message(timestamp=t_start + t + 0.003 + jitter, arbitration_id=ped.frame_id, data=data,
                                is_extended_id=False))
        if k % 10 == 0:
            msgs.append(can.Message(timestamp=t_start + t + 0.005, arbitration_id=ext.frame_id,
                                    data=ext.encode({"Soc": 80.0}), is_extended_id=True))
            msgs.append(can.Message(timestamp=t_start + t + 0.006, arbitration_id=UNKNOWN_ID,
                                    data=bytes([2, 1, 0, 0, 0, 0, 0, 0]), is_extended_id=False))
    for t in rng.uniform(0.1, duration_s - 0.1, error_frames):
        msgs.append(can.Message(timestamp=t_start + float(t), arbitration_id=0x20000004, is_error_frame=True,
                                data=bytes(8), is_extended_id=True))
    msgs.sort(key=lambda m: m.timestamp)
    return msgs


def write_blf(path: Path, msgs: list[can.Message]) -> Path:
    with can.BLFWriter(str(path)) as w:
        for m in msgs:
            w.on_message_received(m)
    return path


def frames_of(chunks: list[FrameChunk]) -> list[tuple[int, int, int, bytes]]:
    """(arb_id, flags without TX, dlc, payload) per frame, in order."""
    out = []
    for c in chunks:
        for i in range(len(c)):
            out.append((int(c.arb_id[i]), int(c.flags[i]) & ~FrameFlag.TX, int(c.dlc[i]),
                        bytes(c.data[i, : c.dlc[i]])))
    return out


def times_of(chunks: list[FrameChunk]) -> np.ndarray:
    return np.concatenate([c.t_ns for c in chunks]) if chunks else np.empty(0, np.int64)


def span_s(chunks: list[FrameChunk]) -> float:
    """Seconds from the first frame of ``chunks`` to the last."""
    t = times_of(chunks)
    return float(t[-1] - t[0]) / 1e9
