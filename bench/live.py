"""Live decoding benchmark: sustained frames/s and added latency, lashscope vs a naive per-frame loop.

A generator process hosts a loopback CAN hub (:mod:`app.live.loopback`) and sends traffic of
the reference EV (``dbc/lashscope_ev.dbc``: its six messages plus 20 % IDs the DBC does not
define) at a fixed rate, in 1 ms bursts on absolute deadlines. In this process, one consumer at
a time receives the same traffic through python-can's Bus API:

* lashscope: :class:`app.live.session.LiveSession` -- bounded queue, BLF recording (flushed
  every 0.5 s), columnar vector decode + signal map, live event analysis;
* naive: the obvious loop -- ``bus.recv()``, ``can.BLFWriter.on_message_received``,
  ``cantools ... decode_message(..., decode_choices=False)`` per frame, values appended to lists.

Latency is per frame, from its receipt by the consumer (``bus.recv`` returned) to its decoded
values being available. A third phase sends as fast as the generator can (no pacing) to find
each consumer's ceiling.

A last phase measures replay pacing: the same traffic written to a BLF log at ``--replay-rate``
frames/s is replayed onto the loopback bus by :class:`app.live.replay.Replayer` and by the
obvious alternative, python-can's ``can.MessageSync`` loop with ``bus.send``; the pacing error
of each frame is its send time minus its deadline (start + log time). Usage::

    .venv/bin/python bench/live.py [--rate 20000] [--seconds 6] [--flood 150000] [--replay-rate 2000]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import can  # noqa: E402
import cantools  # noqa: E402

from app.ingest.readers import open_log  # noqa: E402
from app.live.bus import BusConfig, BusLink  # noqa: E402
from app.live.counters import LatencyRing  # noqa: E402
from app.live.decoding import source_for  # noqa: E402
from app.live.loopback import GREETING, LoopbackBus, LoopbackHub, decode_records, encode_message  # noqa: E402
from app.live.replay import PacingHistogram, Replayer  # noqa: E402
from app.live.session import LiveSession  # noqa: E402

DBC = REPO / "dbc" / "lashscope_ev.dbc"
MAP = REPO / "dbc" / "lashscope_ev.map.toml"


# -- generator process ------------------------------------------------------------------------
def traffic(n: int, seed: int = 1) -> list[bytes]:
    """``n`` frames of a drive: every DBC message with smooth, physically plausible values.

    Torque swings through zero (tip-ins and tip-outs) with a period that divides ``n``, so the
    generator can cycle through the frames without a jump.
    """
    db = cantools.database.load_file(str(DBC))
    rng = np.random.default_rng(seed)
    unknown = [0x7DF, 0x7E8, 0x18DAF110]
    out = []
    for i in range(n):
        phase = 2 * np.pi * 8 * i / n
        if rng.random() < 0.2:
            arb = unknown[i % 3]
            msg = can.Message(arbitration_id=arb, is_extended_id=arb > 0x7FF, data=rng.bytes(8))
        else:
            m = db.messages[i % len(db.messages)]
            values = {}
            for sig in m.signals:
                lo = sig.minimum if sig.minimum is not None else 0.0
                hi = sig.maximum if sig.maximum is not None else 1.0
                mid, amp = (lo + hi) / 2, (hi - lo) / 4
                if sig.name.startswith("MotorTorque"):
                    mid, amp = 40.0, 150.0
                values[sig.name] = sig.scale * round((mid + amp * np.sin(phase)) / sig.scale)
                if sig.choices or sig.length <= 4:
                    values[sig.name] = int(lo)
            msg = can.Message(arbitration_id=m.frame_id, is_extended_id=False, data=m.encode(values, strict=False))
        out.append(encode_message(msg, 0.0))
    return out


def generator(rate: int, seconds: float, flood: int) -> None:
    import socket

    hub = LoopbackHub().start()
    print(hub.port, flush=True)
    records = traffic(32000)
    sock = socket.create_connection(("127.0.0.1", hub.port))
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    sock.sendall(GREETING)
    sock.recv(4)
    for line in sys.stdin:
        cmd = line.split()
        if not cmd or cmd[0] == "quit":
            break
        if cmd[0] == "paced":
            per_ms = rate // 1000
            total = int(rate * seconds)
            start = time.perf_counter() + 0.05
            sent = 0
            while sent < total:
                due = start + sent / rate
                wait = due - time.perf_counter()
                if wait > 0:
                    time.sleep(wait)
                burst = b"".join(records[(sent + k) % len(records)] for k in range(per_ms))
                sock.sendall(burst)
                sent += per_ms
        elif cmd[0] == "flood":
            sent = 0
            while sent < flood:
                burst = b"".join(records[(sent + k) % len(records)] for k in range(1000))
                sock.sendall(burst)
                sent += 1000
        print("done", flush=True)
    sock.close()
    hub.stop()


# -- consumers --------------------------------------------------------------------------------
class Lashscope:
    name = "lashscope LiveSession"

    def __init__(self, channel: str, out: Path, ring: int) -> None:
        source, units = source_for(DBC, MAP)
        from app.live.analyzer import LiveAnalyzer

        self.session = LiveSession(BusConfig("tcp_loopback", channel), source, record_path=out,
                                   analyzer=LiveAnalyzer(units))
        self.session.latency = LatencyRing(ring)

    def start(self) -> None:
        self.session.start()

    def processed(self) -> int:
        return self.session.counters.frames_processed

    def stop(self) -> dict[str, float]:
        self.session.stop()
        p50, p99 = self.session.latency.percentiles_ms()
        return {"p50": p50 or float("nan"), "p99": p99 or float("nan"),
                "dropped": float(self.session.counters.frames_dropped)}


class Naive:
    name = "naive per-frame cantools loop"

    def __init__(self, channel: str, out: Path, ring: int) -> None:
        self.bus = LoopbackBus(channel)
        self.db = cantools.database.load_file(str(DBC))
        self.writer = can.BLFWriter(str(out))
        self.values: dict[str, list[float]] = {}
        self.times: list[float] = []
        self.latency = LatencyRing(ring)
        self.n = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        lat = np.empty(256, np.int64)
        k = 0
        while not self._stop.is_set():
            msg = self.bus.recv(0.05)
            if msg is None:
                continue
            t_recv = time.perf_counter_ns()
            self.writer.on_message_received(msg)
            try:
                decoded = self.db.decode_message(msg.arbitration_id, msg.data, decode_choices=False)
            except (KeyError, ValueError, cantools.database.errors.DecodeError):
                decoded = None
            if decoded:
                self.times.append(msg.timestamp)
                for key, v in decoded.items():
                    self.values.setdefault(key, []).append(float(v))
            lat[k] = time.perf_counter_ns() - t_recv
            k += 1
            self.n += 1
            if k == lat.size:
                self.latency.add(lat)
                k = 0
        self.latency.add(lat[:k])

    def start(self) -> None:
        self._thread.start()

    def processed(self) -> int:
        return self.n

    def stop(self) -> dict[str, float]:
        self._stop.set()
        self._thread.join()
        self.writer.stop()
        self.bus.shutdown()
        p50, p99 = self.latency.percentiles_ms()
        return {"p50": p50 or float("nan"), "p99": p99 or float("nan"), "dropped": 0.0}


def decode_cost(sizes: tuple[int, ...] = (1, 5, 20, 64, 1000), frames: int = 8000) -> list[str]:
    """Per-call cost of the live decode path against cantools per frame, by batch size (best of 5 passes).

    lashscope: ``DecodingSource.feed`` (vector decode of the mapped signals, "not available"
    masking, unknown-ID counting, signal map); cantools: ``decode_message(..., decode_choices=False)``
    on every frame of a mapped message (no masking, no map: a lower bound of the per-frame way).
    """
    from app.live.convert import messages_to_chunk
    from app.live.loopback import decode_records

    msgs, _ = decode_records(bytearray(b"".join(traffic(frames))))
    for i, m in enumerate(msgs):
        m.timestamp = i * 5e-5
    source, _units = source_for(DBC, MAP)
    db = cantools.database.load_file(str(DBC))
    mapped = {m.frame_id for m in source.decoder.db.messages}

    def per_frame(batch: list[can.Message]) -> None:
        for m in batch:
            if m.arbitration_id in mapped:
                db.decode_message(m.arbitration_id, m.data, decode_choices=False)

    lines = [f"{'batch':>6} {'lashscope us/call':>18} {'cantools us/call':>17} {'lashscope us/frame':>19} {'ratio':>6}"]
    for size in sizes:
        groups = [msgs[i:i + size] for i in range(0, len(msgs) - size + 1, size)]
        chunks = [messages_to_chunk(g, 0.0) for g in groups]
        best = [np.inf, np.inf]
        for _ in range(5):
            t0 = time.perf_counter()
            for c in chunks:
                source.feed(c)
            best[0] = min(best[0], (time.perf_counter() - t0) / len(chunks))
            t0 = time.perf_counter()
            for g in groups:
                per_frame(g)
            best[1] = min(best[1], (time.perf_counter() - t0) / len(groups))
        lines.append(f"{size:6d} {best[0] * 1e6:18.1f} {best[1] * 1e6:17.1f} {best[0] * 1e6 / size:19.2f} "
                     f"{best[1] / best[0]:5.2f}x")
    return lines


def replay_pacing(tmp: Path, rate: int, seconds: float) -> dict[str, dict[str, float]]:
    """Pacing error (send time minus deadline, ms) of lashscope's Replayer and of can.MessageSync, both in the
    replayer's histogram (10 us bins, early frames at 0)."""
    n = int(rate * seconds)
    msgs, _ = decode_records(bytearray(b"".join(traffic(n))))
    log = tmp / "replay.blf"
    with can.BLFWriter(str(log)) as writer:
        for i, m in enumerate(msgs):
            m.timestamp = 1000.0 + i / rate
            writer.on_message_received(m)
    out: dict[str, dict[str, float]] = {}
    with LoopbackHub() as hub:
        link = BusLink(BusConfig("tcp_loopback", hub.channel))
        link.open()
        try:
            summary = Replayer(link, lambda: open_log(log).chunks()).run().summary()
        finally:
            link.close()
        out["lashscope Replayer"] = {"frames": float(summary["frames_sent"]), "p50": float(summary["pacing_p50_ms"]),
                                     "p99": float(summary["pacing_p99_ms"]), "max": float(summary["pacing_max_ms"])}
        hist = PacingHistogram()
        with LoopbackBus(hub.channel) as bus, can.LogReader(str(log)) as reader:
            t_first = None
            start = time.perf_counter()
            for m in can.MessageSync(reader):
                if t_first is None:
                    t_first = m.timestamp
                bus.send(m)
                hist.add(int((time.perf_counter() - (start + m.timestamp - t_first)) * 1e9))
        out["python-can MessageSync"] = {"frames": float(hist.n), "p50": hist.percentile_ms(50),
                                         "p99": hist.percentile_ms(99), "max": hist.max_ns / 1e6}
    return out


def run_phase(gen: subprocess.Popen[str], consumer: Lashscope | Naive, cmd: str, expected: int,
              timeout: float) -> dict[str, float]:
    assert gen.stdin is not None and gen.stdout is not None
    consumer.start()
    time.sleep(0.3)
    cpu0, wall0 = time.process_time(), time.perf_counter()
    gen.stdin.write(cmd + "\n")
    gen.stdin.flush()
    gen.stdout.readline()  # "done": the generator has sent everything
    sent_at = time.perf_counter()
    deadline = sent_at + timeout
    while consumer.processed() < expected and time.perf_counter() < deadline:
        time.sleep(0.005)
    wall = time.perf_counter() - wall0
    backlog_s = time.perf_counter() - sent_at
    cpu = time.process_time() - cpu0
    n = consumer.processed()
    res = consumer.stop()
    res.update({"frames": n, "wall_s": wall, "fps": n / wall, "cpu_us_per_frame": 1e6 * cpu / max(n, 1),
                "catch_up_s": backlog_s})
    return res


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rate", type=int, default=20000, help="paced traffic, frames/s (multiple of 1000)")
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--flood", type=int, default=150000, help="frames sent unpaced in the ceiling phase")
    ap.add_argument("--load", type=int, default=0,
                    help="busy-loop processes competing for the CPUs during the phases (a loaded machine)")
    ap.add_argument("--replay-rate", type=int, default=2000, help="frames/s of the log replayed in the pacing phase")
    ap.add_argument("--generator", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.generator:
        generator(args.rate, args.seconds, args.flood)
        return 0
    cost = decode_cost()
    load0 = os.getloadavg()[0]
    gen = subprocess.Popen([sys.executable, __file__, "--generator", "--rate", str(args.rate), "--seconds",
                            str(args.seconds), "--flood", str(args.flood)], stdin=subprocess.PIPE,
                           stdout=subprocess.PIPE, text=True, cwd=REPO)
    assert gen.stdout is not None
    channel = f"127.0.0.1:{int(gen.stdout.readline())}"
    paced_n = int(args.rate * args.seconds) // (args.rate // 1000) * (args.rate // 1000)
    rows = []
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.load)]
    with tempfile.TemporaryDirectory() as tmp:
        for phase, cmd, n in (("paced", "paced", paced_n), ("flood", "flood", args.flood)):
            for cls in (Lashscope, Naive):
                consumer = cls(channel, Path(tmp) / f"{cls.__name__}-{phase}.blf", max(n, 1024))
                rows.append((phase, cls.name, run_phase(gen, consumer, cmd, n, timeout=60.0)))
        pacing = replay_pacing(Path(tmp), args.replay_rate, args.seconds)
    for hog in hogs:
        hog.kill()
        hog.wait()
    assert gen.stdin is not None
    gen.stdin.write("quit\n")
    gen.stdin.close()
    gen.wait(10)
    print(f"live decoding benchmark: reference EV traffic (dbc/lashscope_ev.dbc + 20 % unknown IDs), "
          f"paced {args.rate} frames/s for {args.seconds:g} s, then {args.flood} frames unpaced; "
          f"{os.cpu_count()} CPUs, load average before {load0:.2f}, after {os.getloadavg()[0]:.2f}"
          + (f"; {args.load} busy-loop processes competing" if args.load else ""))
    print("decode path per call (same traffic; ratio = cantools per frame / lashscope):")
    print("\n".join(cost))
    print(f"{'phase':6} {'consumer':30} {'frames':>8} {'frames/s':>9} {'lat p50 ms':>10} {'lat p99 ms':>10} "
          f"{'CPU us/frame':>12} {'dropped':>7}")
    for phase, name, r in rows:
        print(f"{phase:6} {name:30} {r['frames']:8.0f} {r['fps']:9.0f} {r['p50']:10.3f} {r['p99']:10.3f} "
              f"{r['cpu_us_per_frame']:12.1f} {r['dropped']:7.0f}")
    by = {(p, n): r for p, n, r in rows}
    ls, nv = by[("paced", Lashscope.name)], by[("paced", Naive.name)]
    fl, fn = by[("flood", Lashscope.name)], by[("flood", Naive.name)]
    print(f"paced: lashscope kept {ls['frames'] / paced_n:.1%} of {paced_n} frames at {args.rate} frames/s, "
          f"median added latency {ls['p50']:.3f} ms (target <= 1 ms); naive {nv['frames'] / paced_n:.1%}, "
          f"{nv['p50']:.3f} ms")
    print(f"CPU per frame: naive / lashscope = {nv['cpu_us_per_frame'] / ls['cpu_us_per_frame']:.2f}x (paced), "
          f"{fn['cpu_us_per_frame'] / fl['cpu_us_per_frame']:.2f}x (flood); "
          f"ceiling: lashscope {fl['fps']:.0f} frames/s vs naive {fn['fps']:.0f} frames/s "
          f"= {fl['fps'] / fn['fps']:.2f}x")
    print(f"replay pacing, {args.replay_rate} frames/s for {args.seconds:g} s onto the loopback bus "
          f"(send time minus deadline):")
    print(f"{'replayer':24} {'frames':>7} {'p50 ms':>7} {'p99 ms':>7} {'max ms':>7}")
    for name, r in pacing.items():
        print(f"{name:24} {r['frames']:7.0f} {r['p50']:7.3f} {r['p99']:7.3f} {r['max']:7.3f}")
    rp, ms = pacing["lashscope Replayer"], pacing["python-can MessageSync"]
    print(f"replay pacing p99: lashscope {rp['p99']:.3f} ms (target < 2 ms), MessageSync {ms['p99']:.3f} ms "
          f"= {ms['p99'] / max(rp['p99'], 1e-3):.1f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
