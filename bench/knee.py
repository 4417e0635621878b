"""The rise's knee fit of the ripple metrics: screened by running sums against every grid point in full.

Drives of the paper car from the project's simulator, logged at 1 kHz and at 100 Hz (60 s each), go
through ``analyze_signals``; every rise window its ripple metrics fit is kept, and the two fits
(``app.analysis.metrics._knee_fit`` and ``knee_fit_in_full``, the obvious alternative: the fit as first
written) are timed on the same windows in the same run. Printed per rate: windows, their median length,
CPU per window of each, the ratio, and whether every result is the same to the last bit; then the CPU of
``analyze_signals`` on the 1 kHz drive with each fit.

    .venv/bin/python bench/knee.py
    .venv/bin/python bench/knee.py --repeat 5
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import app.analysis.metrics as metrics  # noqa: E402
from app.pipeline import analyze_signals  # noqa: E402
from app.signals import SignalSet  # noqa: E402
from sim import load_vehicle  # noqa: E402
from tests.support.synthetic import CanSampling, DriveSpec, make_drive, measure, run_truth, to_signals  # noqa: E402


def drive(period_s: float, seed: int = 3) -> SignalSet:
    paper = load_vehicle("paper")
    rng = np.random.default_rng(seed)
    d = make_drive(paper, rng, DriveSpec(duration_s=60.0))
    return to_signals(measure(d, run_truth(paper, d), CanSampling(period_s=period_s), rng))


@contextmanager
def knee_fit(f: Callable[[np.ndarray, np.ndarray], tuple[float, float]]) -> Iterator[None]:
    """``analyze_signals`` with ``f`` as its knee fit while the block runs."""
    saved = metrics._knee_fit
    metrics._knee_fit = f
    try:
        yield
    finally:
        metrics._knee_fit = saved


def windows(signals: SignalSet) -> list[tuple[np.ndarray, np.ndarray]]:
    """The rise windows ``analyze_signals`` fits a knee to."""
    kept: list[tuple[np.ndarray, np.ndarray]] = []
    fit = metrics._knee_fit

    def keep(t: np.ndarray, y: np.ndarray) -> tuple[float, float]:
        kept.append((t.copy(), y.copy()))
        return fit(t, y)

    with knee_fit(keep):
        analyze_signals(signals, load_vehicle("paper"))
    return kept


def cpu(f, wins, repeat: int) -> tuple[float, list[tuple[float, float]]]:  # type: ignore[no-untyped-def]
    best = np.inf
    out: list[tuple[float, float]] = []
    for _ in range(repeat):
        t0 = time.process_time()
        out = [f(t, y) for t, y in wins]
        best = min(best, time.process_time() - t0)
    return best, out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="timings per fit (the best is printed)")
    args = ap.parse_args()
    fast = None
    for rate, period in (("1 kHz", 0.001), ("100 Hz", 0.01)):
        signals = drive(period)
        wins = windows(signals)
        if not wins:
            print(f"{rate}: no rise window")
            continue
        c_fast, r_fast = cpu(metrics._knee_fit, wins, args.repeat)
        c_full, r_full = cpu(metrics.knee_fit_in_full, wins, args.repeat)
        same = r_fast == r_full
        print(f"{rate:>6}: {len(wins)} windows, median {int(np.median([t.size for t, _ in wins]))} samples | screened "
              f"{1e3 * c_fast / len(wins):7.2f} ms CPU per window | in full {1e3 * c_full / len(wins):7.2f} ms | "
              f"ratio {c_full / max(c_fast, 1e-9):5.1f} | same to the last bit: {'yes' if same else 'NO'}")
        if period == 0.001:
            fast = signals
    if fast is not None:
        vehicle = load_vehicle("paper")
        spent = {}
        for name, f in (("screened", metrics._knee_fit), ("in full", metrics.knee_fit_in_full)):
            with knee_fit(f):
                spent[name] = min(_timed(lambda: analyze_signals(fast, vehicle)) for _ in range(args.repeat))
        print(f"analyze_signals on the 1 kHz drive: {spent['screened']:.2f} s CPU with the screened fit, "
              f"{spent['in full']:.2f} s in full, ratio {spent['in full'] / spent['screened']:.2f}")
    return 0


def _timed(f) -> float:  # type: ignore[no-untyped-def]
    t0 = time.process_time()
    f()
    return time.process_time() - t0


if __name__ == "__main__":
    raise SystemExit(main())
