"""Ingest benchmark: lashscope (open_log + VectorDecoder) against python-can + per-frame cantools.

Generates, with a fixed seed, a drive on the reference DBC (``dbc/lashscope_ev.dbc``): the
1 ms message MCU_Fast plus five 10 ms messages (1500 frames/s), 1.56 M frames by default,
written once as BLF (python-can ``BLFWriter``) and ASC (``ASCWriter``). Then, in the same
run, each side decodes every frame of every message into per-signal series, each in its own
child process so peak memory (``ru_maxrss`` of that process) is its own:

* lashscope: ``open_log`` chunks -> ``VectorDecoder.decode`` -> per-message float64 arrays;
* baseline: python-can ``BLFReader``/``ASCReader`` -> ``db.decode_message(id, data,
  decode_choices=False)`` per frame -> per-signal lists -> float64 arrays.

Both sides report a checksum of the decoded values; they must agree. Usage::

    .venv/bin/python bench/ingest.py [--seconds 1040] [--workdir DIR] [--formats blf,asc]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DBC = REPO / "dbc" / "lashscope_ev.dbc"
SEED = 20240611
START_EPOCH_S = 1_718_000_000.0


def _signal_raw(sig, phys):  # type: ignore[no-untyped-def]
    raw = np.round((phys - sig.offset) / sig.scale).astype(np.int64)
    lo, hi = (-(1 << (sig.length - 1)), (1 << (sig.length - 1)) - 1) if sig.is_signed else (0, (1 << sig.length) - 1)
    return np.clip(raw, lo, hi) & ((1 << sig.length) - 1)


def encode_message(msg, values: dict[str, np.ndarray]) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Payloads ``(n, 8)`` for one classic message from physical values, vectorized."""
    n = len(next(iter(values.values())))
    le = np.zeros(n, np.uint64)
    be = np.zeros(n, np.uint64)
    for sig in msg.signals:
        raw = _signal_raw(sig, values.get(sig.name, np.zeros(n))).astype(np.uint64)
        if sig.byte_order == "little_endian":
            le |= raw << np.uint64(sig.start)
        else:
            first = 8 * (sig.start // 8) + 7 - sig.start % 8
            be |= raw << np.uint64(64 - first - sig.length)
    return le.astype("<u8").view(np.uint8).reshape(n, 8) | be.astype(">u8").view(np.uint8).reshape(n, 8)


def drive(seconds: float, db) -> list[tuple[np.ndarray, int, np.ndarray]]:  # type: ignore[no-untyped-def]
    """Per message: (times s, frame id, payloads) of a tip-in/tip-out drive with bus jitter."""
    rng = np.random.default_rng(SEED)
    out = []
    for msg in db.messages:
        period = msg.cycle_time / 1000.0
        t = np.arange(0.0, seconds, period) + rng.uniform(0, period, 1)[0]
        t = t + rng.normal(0, period * 0.02, t.size)  # transmit jitter
        t.sort()
        phase = 2 * np.pi * t / 8.0  # an 8 s tip-in / tip-out cycle
        torque = 180 * np.sign(np.sin(phase)) * (1 - np.exp(-np.abs(np.sin(phase)) * 6))
        speed = 3000 + 1500 * np.sin(phase / 4) + 40 * np.sin(2 * np.pi * 9 * t) * np.exp(-((t % 4) / 0.3))
        counter = np.arange(t.size) % 15
        values = {
            "MotorSpeedFast": speed, "MotorTorqueFast": torque, "FastAlive": np.arange(t.size) % 256,
            "MotorTorqueActual": torque, "MotorTorqueRequest": torque * 1.02, "MotorTorqueState": np.full(t.size, 2),
            "MCU_TorqueAlive": counter, "MotorSpeed": speed, "InverterTemp": 60 + t / 100, "MotorTemp": 70 + t / 80,
            "MCU_SpeedAlive": counter, "AccelPedalPos": 30 + 25 * np.sin(phase), "BrakePedalPressed": t % 30 > 27,
            "DriveMode": np.full(t.size, 3), "VCU_PedalAlive": counter, "VehicleSpeed": speed / 9.0 * 0.12 * 3.6,
            "BrakePressure": np.where(t % 30 > 27, 20.0, 0.0), "ESP_VehicleAlive": counter,
        }
        for corner in ("FL", "FR", "RL", "RR"):
            values[f"WheelSpeed{corner}"] = speed / 9.0 + rng.normal(0, 0.3, t.size)
        for sig in msg.signals:
            if sig.name.endswith("CRC"):  # stands in for a checksum: any byte
                values[sig.name] = rng.integers(0, 256, t.size).astype(np.float64)
        out.append((t, msg.frame_id, encode_message(msg, values)))
    return out


def write_logs(workdir: Path, seconds: float, formats: list[str]) -> tuple[dict[str, Path], int]:
    import can
    import cantools

    db = cantools.database.load_file(str(DBC))
    parts = drive(seconds, db)
    t = np.concatenate([p[0] for p in parts])
    ids = np.concatenate([np.full(p[0].size, p[1]) for p in parts])
    data = np.concatenate([p[2] for p in parts])
    order = np.argsort(t, kind="stable")
    t, ids, data = t[order], ids[order], data[order]
    # sanity: the vectorized encoder agrees with cantools on a sample
    for i in range(0, t.size, max(1, t.size // 50)):
        msg = db.get_message_by_frame_id(int(ids[i]))
        assert msg.encode(msg.decode(bytes(data[i]), decode_choices=False), strict=False) == bytes(data[i])
    paths = {}
    for fmt in formats:
        path = workdir / f"drive_{t.size}.{fmt}"
        paths[fmt] = path
        if path.exists():
            continue
        writer_cls = can.BLFWriter if fmt == "blf" else can.ASCWriter
        tmp = path.with_suffix(".tmp")
        with writer_cls(str(tmp)) as w:
            for ts, arb, row in zip((t + START_EPOCH_S).tolist(), ids.tolist(), data, strict=True):
                w.on_message_received(can.Message(timestamp=ts, arbitration_id=arb, is_extended_id=False,
                                                  data=row.tobytes(), channel=0))
        tmp.replace(path)
    return paths, int(t.size)


def child_lashscope(log: Path) -> dict[str, float]:
    from app.ingest.database import load_database
    from app.ingest.decode import DecodedMessage, VectorDecoder
    from app.ingest.readers import open_log

    t0 = time.perf_counter()
    db = load_database(DBC).db
    decoder = VectorDecoder(db, na_to_nan=False)
    parts: dict[str, list[DecodedMessage]] = {}
    frames = 0
    with open_log(log) as reader:
        for chunk in reader.chunks():
            frames += len(chunk)
            for name, dm in decoder.decode(chunk).items():
                parts.setdefault(name, []).append(dm)
    series = {name: DecodedMessage.concat(p) for name, p in parts.items()}
    elapsed = time.perf_counter() - t0
    checksum = sum(float(np.sum(v)) for m in series.values() for v in m.signals.values())
    return {"frames": frames, "seconds": elapsed, "checksum": checksum}


def child_baseline(log: Path) -> dict[str, float]:
    import can
    import cantools

    t0 = time.perf_counter()
    db = cantools.database.load_file(str(DBC))
    reader_cls = can.BLFReader if log.suffix == ".blf" else can.ASCReader
    columns: dict[str, dict[str, list[float]]] = {m.name: {s.name: [] for s in m.signals} for m in db.messages}
    times: dict[str, list[float]] = {m.name: [] for m in db.messages}
    names = {m.frame_id: m.name for m in db.messages}
    frames = 0
    for msg in reader_cls(str(log)):
        frames += 1
        name = names.get(msg.arbitration_id)
        if name is None or msg.is_error_frame or msg.is_remote_frame:
            continue
        try:
            decoded = db.decode_message(msg.arbitration_id, msg.data, decode_choices=False)
        except Exception:
            continue
        times[name].append(msg.timestamp)
        cols = columns[name]
        for k, v in decoded.items():
            cols[k].append(v)
    series = {n: {k: np.asarray(v, np.float64) for k, v in cols.items()} for n, cols in columns.items()}
    _ = {n: np.asarray(v) for n, v in times.items()}
    elapsed = time.perf_counter() - t0
    checksum = sum(float(np.sum(v)) for cols in series.values() for v in cols.values())
    return {"frames": frames, "seconds": elapsed, "checksum": checksum}


def run_child(side: str, log: Path) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    out = subprocess.run([sys.executable, __file__, "--child", side, "--log", str(log)], capture_output=True,
                         text=True, env=env, check=False)
    if out.returncode != 0:
        raise SystemExit(f"{side} child failed on {log}:\n{out.stderr}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=1040.0, help="drive length (1500 frames/s)")
    ap.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "lashscope-bench")
    ap.add_argument("--formats", default="blf,asc")
    ap.add_argument("--child", choices=["lashscope", "baseline"])
    ap.add_argument("--log", type=Path)
    args = ap.parse_args()
    if args.child:
        result = child_lashscope(args.log) if args.child == "lashscope" else child_baseline(args.log)
        result["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        print(json.dumps(result))
        return
    args.workdir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    paths, n = write_logs(args.workdir, args.seconds, [f.strip() for f in args.formats.split(",")])
    print(f"log: {n} frames, {args.seconds:g} s, 1 ms + 10 ms messages of {DBC.name} "
          f"(generated/cached in {time.perf_counter() - t0:.1f} s, seed {SEED})")
    rows = []
    for fmt, path in paths.items():
        mine, base = run_child("lashscope", path), run_child("baseline", path)
        if mine["frames"] != base["frames"] or not np.isclose(mine["checksum"], base["checksum"], rtol=1e-12):
            raise SystemExit(f"{fmt}: results differ: lashscope {mine}, baseline {base}")
        rows.append((fmt, path.stat().st_size, mine, base))
    print(f"{'format':<6} {'size MB':>8} | {'lashscope fr/s':>14} {'s':>6} {'peak MB':>8} | "
          f"{'baseline fr/s':>14} {'s':>6} {'peak MB':>8} | {'speed x':>7} {'memory x':>8}")
    for fmt, size, mine, base in rows:
        fm, fb = mine["frames"] / mine["seconds"], base["frames"] / base["seconds"]
        print(f"{fmt:<6} {size / 1e6:>8.1f} | {fm:>14,.0f} {mine['seconds']:>6.2f} {mine['peak_rss_mb']:>8.0f} | "
              f"{fb:>14,.0f} {base['seconds']:>6.2f} {base['peak_rss_mb']:>8.0f} | {fm / fb:>7.1f} "
              f"{mine['peak_rss_mb'] / base['peak_rss_mb']:>8.2f}")
    print("speed x = lashscope frames/s / baseline frames/s (end to end, file -> decoded series); "
          "memory x = peak RSS lashscope / baseline (each in its own process). Results agree (frames, checksum).")


if __name__ == "__main__":
    main()
