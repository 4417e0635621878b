"""Text readers for loggers' own layouts: the USB-CAN analyser tab export, serial RXn/TXn dumps and a
format described in TOML, against what a user did before they existed.

Before, each of these files needed a hand-written converter to candump -L, then the candump reader.
This script writes the same frames (fixed seed, 10 ms ticks, two buses, 11- and 29-bit IDs) in each
layout, then in the same run times, best of ``--repeat``:

* the layout's own reader (``open_log``, every chunk read);
* the obvious alternative: a plain Python converter (split each line, write candump -L) plus the
  candump reader on its output;
* the candump reader alone on a candump copy (the floor: the shared line loop).

Usage::

    .venv/bin/python bench/text_readers.py [--frames 200000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from app.ingest.readers import open_log  # noqa: E402
from tests.ingest.test_readers_field_text import (  # noqa: E402
    REGEX_LAYOUT,
    _frames,
    analyser_tsv,
    candump,
    regex_logger,
    serial_dump,
)


def read_all(path: Path, **kw: object) -> int:
    with open_log(path, **kw) as log:  # type: ignore[arg-type]
        return sum(len(c) for c in log.chunks())


def tsv_to_candump(src: Path, dst: Path) -> None:
    with src.open(encoding="latin-1") as fin, dst.open("w") as out:
        next(fin)
        for line in fin:
            f = line.split("\t")
            ident = int(f[6], 16)
            data = f[8].replace("0x", "").split()
            ms = int(f[4])
            name = f"{ident:08X}" if ident > 0x7FF else f"{ident:03X}"
            out.write(f"({ms // 1000}.{ms % 1000:03d}000) can{f[1]} {name}#{''.join(data)}"
                      f"{' T' if f[3] == 'TX' else ''}\n")


def serial_to_candump(src: Path, dst: Path) -> None:
    with src.open(encoding="latin-1") as fin, dst.open("w") as out:
        for line in fin:
            if not line.startswith("("):
                continue
            t, rx, ident, _, *data = line.split()
            name = ident.zfill(8) if len(ident) > 3 else ident.zfill(3)
            out.write(f"{t} can{rx[2:]} {name}#{''.join(data)}{' T' if rx.startswith('TX') else ''}\n")


def bench_logger_to_candump(src: Path, dst: Path) -> None:
    with src.open(encoding="latin-1") as fin, dst.open("w") as out:
        for _ in range(2):
            next(fin)
        for line in fin:
            t, ch, d, ident, ext, _, data = line.rstrip("\n").split(";")
            whole, _, frac = t.partition(".")
            ms = int(whole)
            name = ident.zfill(8) if ext == "X" else ident.zfill(3)
            out.write(f"({ms // 1000}.{ms % 1000:03d}{frac[:3]}) can{int(ch) - 1} {name}#{data}"
                      f"{' T' if d == 'Tx' else ''}\n")


def best(fn: Callable[[], object], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n", 1)[0])
    ap.add_argument("--frames", type=int, default=200_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    frames = _frames(args.frames, seed=11)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        (d / "copy.log").write_text(candump(frames))
        (d / "leaf.log").write_text(analyser_tsv(frames))
        (d / "putty.log").write_text(serial_dump(frames))
        (d / "bench.txt").write_text(regex_logger(frames))
        (d / "bench.toml").write_text(REGEX_LAYOUT)
        floor = best(lambda: read_all(d / "copy.log"), args.repeat)
        print(f"{args.frames} frames; candump reader on a candump copy: {floor:.3f} s "
              f"({args.frames / floor / 1e3:.0f} k frames/s)")
        print(f"{'layout':<28} {'own reader (s)':>14} {'convert+candump (s)':>20} {'ratio':>6} {'vs floor':>8}")
        cases = [("analyser tab export", "leaf.log", {}, tsv_to_candump),
                 ("serial RXn dump", "putty.log", {}, serial_to_candump),
                 ("described (regex TOML)", "bench.txt", {"layout": d / "bench.toml"}, bench_logger_to_candump)]
        for label, name, kw, convert in cases:
            n = read_all(d / name, **kw)
            assert n == args.frames, (label, n)
            own = best(lambda name=name, kw=kw: read_all(d / name, **kw), args.repeat)  # type: ignore[misc]

            def alt(name: str = name, convert: Callable[[Path, Path], None] = convert) -> int:
                convert(d / name, d / "converted.log")
                return read_all(d / "converted.log")

            assert alt() == args.frames
            other = best(alt, args.repeat)
            print(f"{label:<28} {own:>14.3f} {other:>20.3f} {other / own:>5.2f}x {own / floor:>7.2f}x")


if __name__ == "__main__":
    main()
