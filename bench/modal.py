"""Modal estimate benchmark: the parametric estimator against FFT peak picking on the same windows.

Monte Carlo over logs of five event windows of the tests' two-mass torsional system
(``tests/identify/test_modal.py``: exact discretisation, CAN-like sampling, noise, 0.5 rpm
quantisation) at three modes -- 2.5 Hz / zeta 0.3, 5 Hz / 0.15, 8 Hz / 0.05 (not at 20 Hz: above
0.4 x the rate) -- sampled at 1 kHz, 50 Hz with frames written in bursts, and 20 Hz. Printed per
rate: the median and 90th percentile of the relative frequency and damping errors of single
windows and of the pooled estimate, the coverage of the 90 % intervals (per window and pooled),
this process's CPU milliseconds per window, and the same window errors of a plain FFT peak pick
(the obvious alternative) on the same lash-closed segments with the ratio of its median errors
to ours.

FFT peak pick: the segment less a straight line, Hann window, zero-padded to 16 times its length;
the frequency of the largest peak in the plausible band, the damping ratio from the half-power
width ``(f2 - f1) / (2 f)`` (interpolated between bins; 100 % error when no half-power point lies
in the band).

    .venv/bin/python bench/modal.py              # 20 logs per mode and rate
    .venv/bin/python bench/modal.py --logs 40
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from app.identify.modal import (  # noqa: E402
    F_MAX_SHARE,
    F_MIN_HZ,
    EventWindow,
    lash_closed_segment,
    pooled_mode,
    window_mode,
)
from tests.identify.test_modal import make_log  # noqa: E402

MODES = ((2.5, 0.3), (5.0, 0.15), (8.0, 0.05))
RATES = (("1 kHz", 1000.0, False), ("50 Hz bursty", 50.0, True), ("20 Hz", 20.0, False))
WINDOWS = 5
PAD = 16


def fft_peak(w: EventWindow) -> tuple[float, float] | None:
    """(f Hz, zeta) by peak picking on the lash-closed segment; None when the window has no segment."""
    seg = lash_closed_segment(w)
    if isinstance(seg, str):
        return None
    y = seg.speed_rpm[seg.start:]
    k = np.arange(y.size, dtype=np.float64)
    y = (y - np.polyval(np.polyfit(k, y, 1), k)) * np.hanning(y.size)
    spec = np.abs(np.fft.rfft(y, PAD * y.size))
    f = np.fft.rfftfreq(PAD * y.size, seg.dt)
    band = np.flatnonzero((f >= F_MIN_HZ) & (f <= F_MAX_SHARE / seg.dt))
    i = int(band[np.argmax(spec[band])])
    half = spec[i] / np.sqrt(2.0)
    lo, hi = i, i
    while lo > band[0] and spec[lo] > half:
        lo -= 1
    while hi < band[-1] and spec[hi] > half:
        hi += 1
    if spec[lo] > half or spec[hi] > half:
        return float(f[i]), float("nan")
    f1 = np.interp(half, [spec[lo], spec[lo + 1]], [f[lo], f[lo + 1]])
    f2 = np.interp(half, [spec[hi], spec[hi - 1]], [f[hi], f[hi - 1]])
    return float(f[i]), float((f2 - f1) / (2 * f[i]))


def rel_err(est: float, true: float) -> float:
    return 1.0 if not np.isfinite(est) else abs(est / true - 1.0)


def run_rate(fs: float, bursty: bool, logs: int) -> dict[str, float]:
    """Errors, coverage and CPU time over ``logs`` logs per mode at one sampling rate."""
    win_f, win_z, pool_f, pool_z, fft_f, fft_z = [], [], [], [], [], []
    cover_w, cover_p = [], []
    cpu = 0.0
    n_win = 0
    for f0, z0 in MODES:
        if f0 >= F_MAX_SHARE * fs:
            continue
        for seed in range(logs):
            windows = make_log(20_000 + seed, f0, z0, fs, bursty, WINDOWS)
            t0 = time.process_time()
            modes = [window_mode(w) for w in windows]
            cpu += time.process_time() - t0
            n_win += len(windows)
            found = [m for m in modes if not isinstance(m, str)]
            for m in found:
                win_f.append(rel_err(m.freq_hz, f0))
                win_z.append(rel_err(m.zeta, z0))
                cover_w.append((m.freq_ci[0] <= f0 <= m.freq_ci[1], m.zeta_ci[0] <= z0 <= m.zeta_ci[1]))
            est = pooled_mode(found)
            pool_f.append(rel_err(est.freq_hz, f0))
            pool_z.append(rel_err(est.zeta, z0))
            cover_p.append((est.freq_ci[0] <= f0 <= est.freq_ci[1], est.zeta_ci[0] <= z0 <= est.zeta_ci[1]))
            for w in windows:
                peak = fft_peak(w)
                fft_f.append(1.0 if peak is None else rel_err(peak[0], f0))
                fft_z.append(1.0 if peak is None else rel_err(peak[1], z0))
    cw, cp = np.mean(cover_w, axis=0), np.mean(cover_p, axis=0)
    return {
        "windows": n_win, "found": len(win_f),
        "win_f50": float(np.median(win_f)), "win_f90": float(np.percentile(win_f, 90)),
        "win_z50": float(np.median(win_z)), "win_z90": float(np.percentile(win_z, 90)),
        "pool_f50": float(np.median(pool_f)), "pool_f90": float(np.percentile(pool_f, 90)),
        "pool_z50": float(np.median(pool_z)), "pool_z90": float(np.percentile(pool_z, 90)),
        "cover_wf": float(cw[0]), "cover_wz": float(cw[1]), "cover_pf": float(cp[0]), "cover_pz": float(cp[1]),
        "cpu_ms": 1000.0 * cpu / n_win,
        "fft_f50": float(np.median(fft_f)), "fft_f90": float(np.percentile(fft_f, 90)),
        "fft_z50": float(np.median(fft_z)), "fft_z90": float(np.percentile(fft_z, 90)),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--logs", type=int, default=20, help="logs of five windows per mode and rate")
    args = ap.parse_args()
    print(f"{args.logs} logs x {WINDOWS} windows per mode; errors relative, median / p90; "
          "coverage of 90 % intervals")
    for name, fs, bursty in RATES:
        r = run_rate(fs, bursty, args.logs)
        print(f"\n{name}: {r['found']:.0f} of {r['windows']:.0f} windows gave a mode, "
              f"{r['cpu_ms']:.1f} ms CPU per window")
        print(f"  window  freq {r['win_f50']:.2%} / {r['win_f90']:.2%}   zeta {r['win_z50']:.2%} / {r['win_z90']:.2%}"
              f"   coverage freq {r['cover_wf']:.0%} zeta {r['cover_wz']:.0%}")
        print(f"  pooled  freq {r['pool_f50']:.2%} / {r['pool_f90']:.2%}   zeta {r['pool_z50']:.2%} / "
              f"{r['pool_z90']:.2%}   coverage freq {r['cover_pf']:.0%} zeta {r['cover_pz']:.0%}")
        print(f"  FFT peak (window)  freq {r['fft_f50']:.2%} / {r['fft_f90']:.2%}   zeta {r['fft_z50']:.2%} / "
              f"{r['fft_z90']:.2%}   FFT/ours median error: freq {r['fft_f50'] / r['win_f50']:.0f}x, "
              f"zeta {r['fft_z50'] / r['win_z50']:.0f}x")


if __name__ == "__main__":
    main()
