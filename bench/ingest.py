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

    .venv/bin/python bench/ingest.py [--seconds 200] [--workdir DIR] [--formats blf,asc,trc] [--mf4-copies 100]
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
# the project first: run as a script, bench/ is sys.path[0], and its sim.py would stand in for the simulator package
# wherever a child imports it
sys.path.insert(0, str(REPO))
DBC = REPO / "dbc" / "lashscope_ev.dbc"
FOREIGN_DBC = REPO / "bench" / "data" / "foreign_ev.dbc"  # written by the project for this benchmark
FOREIGN_MAP = REPO / "bench" / "data" / "foreign_ev.map.toml"
FOREIGN_UNKNOWN_ID = 0x555  # another ECU's 10 ms message the database does not define
SEED = 20240611
MF4_SAMPLE = Path("css-electronics-mf4/examples/data-processing/LOG/FCBF0606/00003482/00000001-60B621D9.MF4")
MF4_DBC = Path("css-electronics-mf4/examples/data-processing/dbc_files/CSS-Electronics-SAE-J1939-DEMO.dbc")
START_EPOCH_S = 1_718_000_000.0


def _signal_raw(sig, phys):  # type: ignore[no-untyped-def]
    raw = np.round((phys - sig.offset) / sig.scale).astype(np.int64)
    lo, hi = (-(1 << (sig.length - 1)), (1 << (sig.length - 1)) - 1) if sig.is_signed else (0, (1 << sig.length) - 1)
    return np.clip(raw, lo, hi) & ((1 << sig.length) - 1)


def encode_message(msg, values: dict[str, np.ndarray], signals=None) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Payloads ``(n, 8)`` for one classic message from physical values, vectorized (``signals``: only these)."""
    n = len(next(iter(values.values())))
    le = np.zeros(n, np.uint64)
    be = np.zeros(n, np.uint64)
    for sig in msg.signals if signals is None else signals:
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


def foreign_drive(seconds: float, db) -> list[tuple[np.ndarray, int, np.ndarray]]:  # type: ignore[no-untyped-def]
    """Per message of ``bench/data/foreign_ev.dbc`` (and one unknown ID): times, frame id, payloads.

    The bus is not perfect: single frames are lost now and then (~3 in 10,000), the logger loses
    15 ms of everything once (t = 120 s), the inverter restarts its status counter once (t = 77 s),
    the VCU sends its counter value twice a few times, and the signals start as SNA for 0.2 s.
    """
    rng = np.random.default_rng(SEED + 1)
    out = []
    for msg in [*db.messages, None]:
        period = (msg.cycle_time if msg is not None else 10) / 1000.0
        t = np.arange(0.0, seconds, period) + rng.uniform(0, period, 1)[0]
        t = np.sort(t + rng.normal(0, period * 0.02, t.size))
        n = t.size
        i = np.arange(n)
        if msg is None:
            out.append((t, FOREIGN_UNKNOWN_ID, rng.integers(0, 256, (n, 8)).astype(np.uint8)))
            continue
        phase = 2 * np.pi * t / 8.0
        torque = 180 * np.sign(np.sin(phase)) * (1 - np.exp(-np.abs(np.sin(phase)) * 6))
        speed = 3000 + 1500 * np.sin(phase / 4) + 40 * np.sin(2 * np.pi * 9 * t) * np.exp(-((t % 4) / 0.3))
        init = t < 0.2  # the ECUs start with "signal not available"
        noise = rng.integers(0, 256, n).astype(np.float64)
        if msg.name == "INV_Fast":
            values = {"INV_RotorSpeed": np.where(init, -8192.0, speed),
                      "INV_TorqueAct": np.where(init, -1024.0, torque), "INV_FastMode": np.where(init, 0, 2),
                      "INV_FastCounter": i % 256,
                      "INV_TorqueCmd": torque * 1.02, "INV_FastChecksum": noise}
        elif msg.name == "INV_Status":
            start = int(np.searchsorted(t, 77.0))  # the inverter restarts: its counter begins at 0 again
            values = {"INV_DCVoltage": np.where(init, 1023.75, 380 - torque / 20), "INV_DCCurrent": torque / 2,
                      "INV_TempIGBT": 45 + t / 50, "INV_StatusCounter": np.where(i < start, i % 15, (i - start) % 15),
                      "INV_StatusChecksum": noise}
        elif msg.name == "VCU_Drive":
            counter = (15 - i) % 16
            again = rng.choice(np.arange(100, n - 100), 4, replace=False)
            counter[again] = counter[again - 1]  # the VCU sends the same value twice (its task ran late)
            values = {"VCU_PedalPos": np.where(init, 102.0, 30 + 25 * np.sin(phase)),
                      "VCU_BrakeSwitch": (t % 30 > 27).astype(np.float64), "VCU_Gear": np.full(n, 3.0),
                      "VCU_DriveCounter": counter, "VCU_DriveChecksum": noise}
        elif msg.name == "CHS_Mux":
            values = {"CHS_MuxIndex": i % 3, "CHS_MuxAlive": i % 16, "CHS_Checksum": noise,
                      "CHS_VehSpeed": np.where(init, 655.35, speed / 9.0 * 0.12 * 3.6),
                      "CHS_BrakePress": np.where(t % 30 > 27, 20.0, 0.0)}
            for corner in ("FL", "FR", "RL", "RR"):
                values[f"CHS_Wheel{corner}"] = np.where(init, 6553.5, speed / 9.0 + rng.normal(0, 0.3, n))
        else:
            values = {"BMS_PackVoltage": 380 - torque / 20, "BMS_SOC": 80 - t / 100, "BMS_PackCurrent": torque / 2}
        if msg.is_multiplexed():
            data = np.zeros((n, 8), np.uint8)
            for page in range(3):
                rows = values["CHS_MuxIndex"] == page
                sigs = [s for s in msg.signals if s.multiplexer_ids is None or page in s.multiplexer_ids]
                data[rows] = encode_message(msg, {k: np.asarray(v)[rows] for k, v in values.items()}, sigs)
        else:
            data = encode_message(msg, values)
        out.append((t, msg.frame_id, data))
    return out


def assemble(kind: str, seconds: float, db) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    """Times (s), IDs and payloads of all frames in time order (foreign: with the lost frames left out)."""
    parts = drive(seconds, db) if kind == "own" else foreign_drive(seconds, db)
    t = np.concatenate([p[0] for p in parts])
    ids = np.concatenate([np.full(p[0].size, p[1]) for p in parts])
    data = np.concatenate([p[2] for p in parts])
    order = np.argsort(t, kind="stable")
    t, ids, data = t[order], ids[order], data[order]
    if kind == "foreign":
        rng = np.random.default_rng(SEED + 2)
        keep = (rng.random(t.size) >= 3e-4) & ~((t >= 120.0) & (t < 120.015))
        t, ids, data = t[keep], ids[keep], data[keep]
    return t, ids, data


def write_logs(workdir: Path, seconds: float, formats: list[str], kind: str = "own") -> tuple[dict[str, Path], int]:
    import can
    import cantools

    db = cantools.database.load_file(str(DBC if kind == "own" else FOREIGN_DBC))
    t, ids, data = assemble(kind, seconds, db)
    extended = {m.frame_id for m in db.messages if m.is_extended_frame}
    # sanity: the vectorized encoder agrees with cantools on a sample
    for i in range(0, t.size, max(1, t.size // 50)):
        if int(ids[i]) == FOREIGN_UNKNOWN_ID and kind == "foreign":
            continue
        msg = db.get_message_by_frame_id(int(ids[i]))
        assert msg.encode(msg.decode(bytes(data[i]), decode_choices=False), strict=False) == bytes(data[i])
    paths = {}
    for fmt in formats:
        path = workdir / f"{'drive' if kind == 'own' else 'foreign'}_{t.size}.{fmt}"
        paths[fmt] = path
        if path.exists():
            continue
        writer_cls = {"blf": can.BLFWriter, "asc": can.ASCWriter, "trc": can.TRCWriter}[fmt]
        tmp = path.with_suffix(".tmp")
        with writer_cls(str(tmp)) as w:
            for ts, arb, row in zip((t + START_EPOCH_S).tolist(), ids.tolist(), data, strict=True):
                w.on_message_received(can.Message(timestamp=ts, arbitration_id=arb, is_extended_id=arb in extended,
                                                  data=row.tobytes(), channel=0))
        tmp.replace(path)
    return paths, int(t.size)


def child_lashscope(log: Path, dbc: Path = DBC) -> dict[str, float]:
    from app.ingest.database import load_database
    from app.ingest.decode import DecodedMessage, VectorDecoder
    from app.ingest.readers import open_log, reader_class

    reader_class(log.suffix[1:])
    t0 = time.perf_counter()
    db = load_database(dbc).db
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
    checksum = sum(float(np.sum(v[m.is_present(k)])) for m in series.values() for k, v in m.signals.items())
    return {"frames": frames, "seconds": elapsed, "checksum": checksum}


def child_baseline(log: Path, only: set[str] | None = None, dbc: Path = DBC) -> dict[str, float]:
    """python-can + cantools; ``only``: decode just these messages; ``{"parquet"}``: all, written as Parquet."""
    import can
    import cantools

    t0 = time.perf_counter()
    parquet = only == {"parquet"}
    only = None if parquet else only or None
    db = cantools.database.load_file(str(dbc))
    reader_cls = {".blf": can.BLFReader, ".asc": can.ASCReader, ".trc": can.TRCReader}[log.suffix]
    columns: dict[str, dict[str, list[float]]] = {m.name: {s.name: [] for s in m.signals} for m in db.messages}
    times: dict[str, list[float]] = {m.name: [] for m in db.messages}
    names = {m.frame_id: m.name for m in db.messages if only is None or m.name in only}
    multiplexed = {m.name for m in db.messages if m.is_multiplexed()}
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
        if name in multiplexed:  # a signal of another page: NaN, so that the columns stay aligned
            for k, col in cols.items():
                col.append(decoded.get(k, np.nan))
        else:
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
    checksum = sum(float(np.nansum(v)) for cols in series.values() for v in cols.values())
    return {"frames": frames, "seconds": elapsed, "checksum": checksum}


def _signal_map(name: str):  # type: ignore[no-untyped-def]
    from app.ingest.signalmap import load_signal_map

    return load_signal_map(REPO / "dbc" / name if "/" not in name else Path(name))


def _time_stats() -> list[float]:
    """Time spent in the bus statistics and alive counters (:class:`StatsAccumulator`), summed into the list."""
    from app.ingest.stats import StatsAccumulator

    spent = [0.0]
    for name in ("add_chunk", "add_decoded", "fill"):
        def timed(self, *args, _f=getattr(StatsAccumulator, name)):  # type: ignore[no-untyped-def]
            t0 = time.perf_counter()
            try:
                return _f(self, *args)
            finally:
                spent[0] += time.perf_counter() - t0
        setattr(StatsAccumulator, name, timed)
    return spent


def child_path(path: str, log: Path, extra: str, dbc: Path = DBC) -> dict[str, float]:
    """One lashscope user path, timed in-process from loading the database to the result."""
    from app.cli.decode import decode_log, format_report, write_signals
    from app.ingest.database import load_database
    from app.ingest.decode import VectorDecoder
    from app.ingest.pipeline_signals import load_signals
    from app.ingest.readers import open_log, reader_class

    reader_class("mf4" if path == "mf4" else log.suffix[1:])  # the reader's module: an import, before the clock
    stats_s = _time_stats()
    t0 = time.perf_counter()
    loaded = load_database(dbc if path != "mf4" else Path(extra))
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
    return {"frames": frames, "seconds": time.perf_counter() - t0, "checksum": 0.0, "stats_s": stats_s[0]}


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


REPEAT = [3]  # runs per side and path (--repeat)


def run_child(side: str, log: Path, extra: str = "", dbc: Path = DBC) -> dict[str, float]:
    """Best of ``REPEAT`` runs of one side, each in its own process: the shortest in-process time and whole
    process (``wall_s``, interpreter start-up included), the largest peak memory; ``stats_s`` of the fastest run."""
    runs = [_run_child_once(side, log, extra, dbc) for _ in range(REPEAT[0])]
    best = dict(min(runs, key=lambda r: r["seconds"]))
    best["wall_s"] = min(r["wall_s"] for r in runs)
    best["peak_rss_mb"] = max(r["peak_rss_mb"] for r in runs)
    return best


def _run_child_once(side: str, log: Path, extra: str, dbc: Path) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # as installed: compiled modules cached
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, __file__, "--child", side, "--log", str(log), "--extra", extra,
                          "--dbc", str(dbc)],
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
    if not src.exists() or copies < 1:
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
            f"{mine['peak_rss_mb'] / base['peak_rss_mb']:>6.2f}"
            + (f" {100 * mine['stats_s'] / mine['seconds']:>6.0f}" if "stats_s" in mine and "signals" in label else ""))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=200.0, help="drive length (1500 frames/s; 200 s: 300k frames)")
    ap.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "lashscope-bench")
    ap.add_argument("--formats", default="blf,asc")
    ap.add_argument("--mf4-copies", type=int, default=100, help="copies of the CANedge sample in the MF4 log")
    ap.add_argument("--child", choices=["lashscope", "baseline", "signals", "report", "parquet", "mf4", "asammdf"])
    ap.add_argument("--log", type=Path)
    ap.add_argument("--extra", default="")
    ap.add_argument("--dbc", type=Path, default=DBC)
    ap.add_argument("--repeat", type=int, default=3, help="runs per side and path; the best one counts")
    ap.add_argument("--logs", default="own,foreign",
                    help="own: dbc/lashscope_ev.dbc; foreign: bench/data/foreign_ev.dbc")
    args = ap.parse_args()
    if args.child:
        if args.child == "lashscope":
            result = child_lashscope(args.log, args.dbc)
        elif args.child == "baseline":
            result = child_baseline(args.log, set(filter(None, args.extra.split(","))), args.dbc)
        elif args.child == "asammdf":
            result = child_asammdf(args.log, args.extra)
        else:
            result = child_path(args.child, args.log, args.extra, args.dbc)
        result["peak_rss_mb"] = peak_rss_mb()
        print(json.dumps(result))
        return
    args.workdir.mkdir(parents=True, exist_ok=True)
    REPEAT[0] = max(1, args.repeat)
    print(f"lashscope --help: {help_seconds():.3f} s (best of 7)")
    header = (f"{'path (lashscope vs baseline)':<34} {'frames':>9} | {'in s':>6} {'proc s':>6} {'MB':>6} | "
              f"{'in s':>6} {'proc s':>6} {'MB':>6} | {'in x':>6} {'proc x':>6} {'mem x':>6} {'stat %':>6}")
    for kind in filter(None, args.logs.split(",")):
        dbc = DBC if kind == "own" else FOREIGN_DBC
        maps = ["lashscope_ev.map.toml", "lashscope_ev_1khz.map.toml"] if kind == "own" else [str(FOREIGN_MAP)]
        t0 = time.perf_counter()
        paths, n = write_logs(args.workdir, args.seconds, [f.strip() for f in args.formats.split(",")], kind)
        what = ("1 ms + 10 ms messages of dbc/lashscope_ev.dbc" if kind == "own" else
                "1, 5, 10, 20 ms messages of bench/data/foreign_ev.dbc (Motorola, SNA, 29-bit IDs, multiplexed, "
                "4 alive counters) and an unknown ID, lost frames, a counter reset, repeats")
        print(f"{kind} log: {n} frames, {args.seconds:g} s, {what} "
              f"(generated/cached in {time.perf_counter() - t0:.1f} s, seed {SEED})")
        print(header)
        for fmt, path in paths.items():
            base_all = run_child("baseline", path, dbc=dbc)
            mine = run_child("lashscope", path, dbc=dbc)
            if mine["frames"] != base_all["frames"] or not np.isclose(mine["checksum"], base_all["checksum"],
                                                                      rtol=1e-12):
                raise SystemExit(f"{fmt}: results differ: lashscope {mine}, baseline {base_all}")
            print(_row(f"{fmt} decoder (open_log+decode)", mine, base_all))
            print(_row(f"{fmt} decode report", run_child("report", path, dbc=dbc), base_all))
            for smap in maps:
                wanted = ",".join(sorted({spec.message for spec in _signal_map(smap).channels.values()}))
                base = run_child("baseline", path, wanted, dbc)
                label = f"{fmt} load_signals {Path(smap).name.split('.')[0]}"
                print(_row(label, run_child("signals", path, smap, dbc), base))
            print(_row(f"{fmt} decode --map --format parquet", run_child("parquet", path, maps[0], dbc),
                       run_child("baseline", path, "parquet", dbc)))
    mf4 = mf4_log(args.workdir, args.mf4_copies)
    if mf4 is not None:
        j1939 = str(mf4.parent / "j1939.dbc")
        Path(j1939).write_bytes((Path(os.environ.get("LASHSCOPE_SHARED", REPO.parent / "shared")) / "data"
                               / MF4_DBC).read_bytes())
        print(_row("mf4 decoder vs asammdf bus logging", run_child("mf4", mf4, j1939),
                   run_child("asammdf", mf4, j1939)))
    print("in = in-process seconds after the imports; proc = the whole process (interpreter start-up "
          "included); MB = peak RSS; x = baseline / lashscope (time), lashscope / baseline (memory); stat % = share of "
          f"the bus statistics and alive counters in load_signals (in-process); best of {REPEAT[0]} runs per side "
          "(time: the shortest; memory: the largest). Baseline: "
          "python-can reader + cantools decode_message per frame (only the mapped messages for load_signals; "
          "plus a Parquet file per message for the parquet row); MF4: asammdf extract_bus_logging.")


if __name__ == "__main__":
    main()
