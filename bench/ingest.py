"""Ingest benchmark: every lashscope user path against python-can + per-frame cantools (and asammdf for MF4).

Generates, with a fixed seed, a drive on the reference DBC (``dbc/lashscope_ev.dbc``): the
1 ms message MCU_Fast plus five 10 ms messages (1500 frames/s), 300k frames by default
(``--seconds 200``), written once as BLF (python-can ``BLFWriter``) and ASC (``ASCWriter``).
Then, in the same run, each path runs in its own child process (peak memory = that process's
VmHWM; time in-process after the imports, and the whole process with interpreter start-up):

* decoder: ``open_log`` chunks -> ``VectorDecoder.decode`` -> per-message arrays (checksums
  must agree with the baseline);
* decode report: ``lashscope decode`` without a map (every message, the bus report);
* load_signals: the log -> canonical signals path ``analyze`` runs, with the 10 ms and the
  1 kHz signal maps (the baseline then decodes only the mapped messages);
* decode --map --format parquet: load_signals + the report + ``signals.parquet`` (the
  baseline writes one Parquet file per message);
* MF4: the decoder on a real CANedge J1939 file concatenated ``--mf4-copies`` times, against
  asammdf's ``extract_bus_logging`` with the same DBC;
* ``lashscope --help`` start-up (best of 7).

The baseline is python-can ``BLFReader``/``ASCReader`` -> ``db.decode_message(id, data,
decode_choices=False)`` per frame -> per-signal lists -> float64 arrays. Usage::

    .venv/bin/python bench/ingest.py [--seconds 200] [--workdir DIR] [--formats blf,asc] [--mf4-copies 100]
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
MF4_SAMPLE = Path("css-electronics-mf4/examples/data-processing/LOG/FCBF0606/00003482/00000001-60B621D9.MF4")
MF4_DBC = Path("css-electronics-mf4/examples/data-processing/dbc_files/CSS-Electronics-SAE-J1939-DEMO.dbc")
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
    from app.ingest.readers import open_log, reader_class

    reader_class(log.suffix[1:])
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


def child_baseline(log: Path, only: set[str] | None = None) -> dict[str, float]:
    """python-can + cantools; ``only``: decode just these messages; ``{"parquet"}``: all, written as Parquet."""
    import can
    import cantools

    t0 = time.perf_counter()
    parquet = only == {"parquet"}
    only = None if parquet else only or None
    db = cantools.database.load_file(str(DBC))
    reader_cls = can.BLFReader if log.suffix == ".blf" else can.ASCReader
    columns: dict[str, dict[str, list[float]]] = {m.name: {s.name: [] for s in m.signals} for m in db.messages}
    times: dict[str, list[float]] = {m.name: [] for m in db.messages}
    names = {m.frame_id: m.name for m in db.messages if only is None or m.name in only}
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
    stamps = {n: np.asarray(v) for n, v in times.items()}
    if parquet:
        import pyarrow as pa
        import pyarrow.parquet as pq

        with tempfile.TemporaryDirectory() as out:
            for name, cols in series.items():
                pq.write_table(pa.table({"t_s": stamps[name], **cols}), f"{out}/{name}.parquet")
    elapsed = time.perf_counter() - t0
    checksum = sum(float(np.sum(v)) for cols in series.values() for v in cols.values())
    return {"frames": frames, "seconds": elapsed, "checksum": checksum}


def _signal_map(name: str):  # type: ignore[no-untyped-def]
    from app.ingest.signalmap import load_signal_map

    return load_signal_map(REPO / "dbc" / name)


def child_path(path: str, log: Path, extra: str) -> dict[str, float]:
    """One lashscope user path, timed in-process from loading the database to the result."""
    from app.cli.decode import decode_log, format_report, write_signals
    from app.ingest.database import load_database
    from app.ingest.decode import VectorDecoder
    from app.ingest.pipeline_signals import load_signals
    from app.ingest.readers import open_log, reader_class

    reader_class("mf4" if path == "mf4" else log.suffix[1:])  # the reader's module: an import, before the clock
    t0 = time.perf_counter()
    loaded = load_database(DBC if path != "mf4" else Path(extra))
    frames = 0
    if path == "signals":  # the documented log -> signals path (what analyze runs)
        signals, report = load_signals(log, loaded, _signal_map(extra))
        frames = report.frames_read
    elif path == "report":  # lashscope decode: every message, the bus report
        report = decode_log(log, loaded)
        format_report(report)
        frames = report.frames_read
    elif path == "parquet":  # lashscope decode --map M --out D --format parquet
        signals, report = load_signals(log, loaded, _signal_map(extra))
        format_report(report)
        with tempfile.TemporaryDirectory() as out:
            write_signals(signals, Path(out), ["parquet"])
        frames = report.frames_read
    elif path == "mf4":
        decoder = VectorDecoder(loaded.db)
        with open_log(log) as reader:
            for chunk in reader.chunks():
                frames += len(chunk)
                decoder.decode(chunk)
    return {"frames": frames, "seconds": time.perf_counter() - t0, "checksum": 0.0}


def child_asammdf(log: Path, dbc: str) -> dict[str, float]:
    from asammdf import MDF

    t0 = time.perf_counter()
    out = MDF(str(log)).extract_bus_logging({"CAN": [(dbc, 0)]})
    frames = sum(len(ch.samples) for ch in out.iter_channels())
    return {"frames": frames, "seconds": time.perf_counter() - t0, "checksum": 0.0}


def peak_rss_mb() -> float:
    """Peak resident memory of this process (MiB): VmHWM of its own address space.

    ``ru_maxrss`` would do on a fresh process, but Linux keeps it across fork and exec, so a
    child started by a parent holding the generated log would report the parent's size.
    """
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def run_child(side: str, log: Path, extra: str = "") -> dict[str, float]:
    """Run one side in its own process; ``wall_s`` is the whole process (interpreter start-up included)."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # as installed: compiled modules cached
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, __file__, "--child", side, "--log", str(log), "--extra", extra],
                         capture_output=True, text=True, env=env, check=False)
    wall = time.perf_counter() - t0
    if out.returncode != 0:
        raise SystemExit(f"{side} child failed on {log}:\n{out.stderr}")
    result: dict[str, float] = json.loads(out.stdout.strip().splitlines()[-1])
    result["wall_s"] = wall
    return result


def help_seconds() -> float:
    """Best of 7 runs of ``lashscope --help`` (start-up of the command line)."""
    exe = Path(sys.executable).with_name("lashscope")
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    times = []
    for _ in range(7):
        t0 = time.perf_counter()
        subprocess.run([str(exe), "--help"], stdout=subprocess.DEVNULL, env=env, check=True)
        times.append(time.perf_counter() - t0)
    return min(times)


def mf4_log(workdir: Path, copies: int) -> Path | None:
    """A real CANedge J1939 MF4 (public sample data) concatenated ``copies`` times with asammdf."""
    src = Path(os.environ.get("LASHSCOPE_SHARED", REPO.parent / "shared")) / "data" / MF4_SAMPLE
    if not src.exists():
        return None
    path = workdir / f"canedge_x{copies}.mf4"
    if not path.exists():
        from asammdf import MDF

        MDF.concatenate([str(src)] * copies).save(str(path), overwrite=True)
    return path


def _row(label: str, mine: dict[str, float], base: dict[str, float]) -> str:
    return (f"{label:<34} {mine['frames']:>9,.0f} | {mine['seconds']:>6.2f} {mine['wall_s']:>6.2f} "
            f"{mine['peak_rss_mb']:>6.0f} | {base['seconds']:>6.2f} {base['wall_s']:>6.2f} "
            f"{base['peak_rss_mb']:>6.0f} | "
            f"{base['seconds'] / mine['seconds']:>6.1f} {base['wall_s'] / mine['wall_s']:>6.1f} "
            f"{mine['peak_rss_mb'] / base['peak_rss_mb']:>6.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=200.0, help="drive length (1500 frames/s; 200 s: 300k frames)")
    ap.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "lashscope-bench")
    ap.add_argument("--formats", default="blf,asc")
    ap.add_argument("--mf4-copies", type=int, default=100, help="copies of the CANedge sample in the MF4 log")
    ap.add_argument("--child", choices=["lashscope", "baseline", "signals", "report", "parquet", "mf4", "asammdf"])
    ap.add_argument("--log", type=Path)
    ap.add_argument("--extra", default="")
    args = ap.parse_args()
    if args.child:
        if args.child == "lashscope":
            result = child_lashscope(args.log)
        elif args.child == "baseline":
            result = child_baseline(args.log, set(filter(None, args.extra.split(","))))
        elif args.child == "asammdf":
            result = child_asammdf(args.log, args.extra)
        else:
            result = child_path(args.child, args.log, args.extra)
        result["peak_rss_mb"] = peak_rss_mb()
        print(json.dumps(result))
        return
    args.workdir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    paths, n = write_logs(args.workdir, args.seconds, [f.strip() for f in args.formats.split(",")])
    print(f"log: {n} frames, {args.seconds:g} s, 1 ms + 10 ms messages of {DBC.name} "
          f"(generated/cached in {time.perf_counter() - t0:.1f} s, seed {SEED})")
    print(f"lashscope --help: {help_seconds():.3f} s (best of 7)")
    print(f"{'path (lashscope vs baseline)':<34} {'frames':>9} | {'in s':>6} {'proc s':>6} {'MB':>6} | "
          f"{'in s':>6} {'proc s':>6} {'MB':>6} | {'in x':>6} {'proc x':>6} {'mem x':>6}")
    for fmt, path in paths.items():
        base_all = run_child("baseline", path)
        mine = run_child("lashscope", path)
        if mine["frames"] != base_all["frames"] or not np.isclose(mine["checksum"], base_all["checksum"], rtol=1e-12):
            raise SystemExit(f"{fmt}: results differ: lashscope {mine}, baseline {base_all}")
        print(_row(f"{fmt} decoder (open_log+decode)", mine, base_all))
        print(_row(f"{fmt} decode report", run_child("report", path), base_all))
        for smap in ("lashscope_ev.map.toml", "lashscope_ev_1khz.map.toml"):
            wanted = ",".join(sorted({spec.message for spec in _signal_map(smap).channels.values()}))
            base = run_child("baseline", path, wanted)
            print(_row(f"{fmt} load_signals {smap.split('.')[0]}", run_child("signals", path, smap), base))
        print(_row(f"{fmt} decode --map --format parquet", run_child("parquet", path, "lashscope_ev.map.toml"),
                   run_child("baseline", path, "parquet")))
    mf4 = mf4_log(args.workdir, args.mf4_copies)
    if mf4 is not None:
        dbc = str(mf4.parent / "j1939.dbc")
        Path(dbc).write_bytes((Path(os.environ.get("LASHSCOPE_SHARED", REPO.parent / "shared")) / "data"
                               / MF4_DBC).read_bytes())
        print(_row("mf4 decoder vs asammdf bus logging", run_child("mf4", mf4, dbc), run_child("asammdf", mf4, dbc)))
    print("in = in-process seconds after the imports; proc = the whole process (interpreter start-up "
          "included); MB = peak RSS; x = baseline / lashscope (time), lashscope / baseline (memory). Baseline: "
          "python-can reader + cantools decode_message per frame (only the mapped messages for load_signals; "
          "plus a Parquet file per message for the parquet row); MF4: asammdf extract_bus_logging.")


if __name__ == "__main__":
    main()
