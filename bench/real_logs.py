"""Run the analysis on real driving logs listed in a manifest and print one block per log.

The logs themselves are not part of the repository (public captures without a licence); a manifest
TOML next to them says what each one is::

    [defaults]                       # optional; every key may also be given per log
    vehicle = "chain_drive"          # preset name or driveline TOML (relative to the manifest)
    dbc = "uwfe/2024CAR.dbc"
    map = "uwfe_invert.map.toml"

    [[log]]
    name = "oct26-6"                 # short label (default: the file name)
    path = "uwfe/Oct26Testing__LOGS6.TXT"
    car = "uwfe-2024"                # drives of one car identify and validate each other
    date = "2024-10-26"
    season = "2024"
    note = "..."                     # free text, printed

Relative paths are taken from the manifest's folder. Per log it prints the measured span of the
motor speed, the events found and the ones analysed, the tracking verdict with the median aligned
NRMSE over events, and the median measured (and simulated) ripple -- the figures ``lashscope
analyze`` prints, through the same pipeline (:func:`app.pipeline.run_analysis`, the payload the
command formats).

Two further estimates per drive:

- a reference first mode that does not use the project's simulator: a least-squares ARX model of
  the motor-speed increments driven by the motor torque, fitted on the analysed event windows
  (orders 2-4, the order chosen by BIC); its lowest complex pole pair gives frequency and damping
  ratio. Increments remove the rigid-body integrator, so the remaining poles are the driveline's.
  The CAN samples are put on a uniform grid at their mean spacing (bursty loggers hold samples
  back; the mean is the real rate), so this is a plain cross-check, not an identification;
- ``--identify``: the project's identification (``app.identify.identify_logs``) on each drive,
  validated on the next drive of the same car in the manifest (same database and signal map). It
  prints the identified parameters with their intervals, the model-free mode and the withheld
  drive's NRMSE before and after. On a checkout without ``app.identify`` it says so and goes on;
- ``--pool``: per car with three drives or more, the identification on all its drives together, each
  drive's own identification checked against it (a drive is consistent when each of its identified
  parameters' intervals holds the pooled value), and leave-one-drive-out: identified on the others,
  tracked on the one left out (verdict and NRMSE with the file's vehicle and with the identified one).

    .venv/bin/python bench/real_logs.py /work/fsdata/manifest.toml
    .venv/bin/python bench/real_logs.py /work/fsdata/manifest.toml --only oct26-6 --identify
    .venv/bin/python bench/real_logs.py /work/fsdata/manifest.toml --pool
"""

from __future__ import annotations

import argparse
import importlib
import math
import sys
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.analysis.events import Event
from app.payload import result_payload
from app.pipeline import AnalysisOptions, AnalysisResult, VehicleInputs, run_analysis
from app.signals import SignalSet
from sim import load_vehicle

FloatArray = npt.NDArray[np.float64]
ARX_ORDERS = (2, 3, 4)
PARAM_ORDER = ("stiffness", "damping_ratio", "damping", "mass", "lash")


@dataclass(frozen=True)
class LogEntry:
    """One manifest row with its paths resolved."""

    name: str
    path: Path
    dbc: Path
    signal_map: Path
    vehicle: str
    car: str
    date: str
    season: str
    note: str


def read_manifest(path: Path) -> list[LogEntry]:
    """The manifest's logs; relative paths (and a vehicle given as a file) resolve against its folder."""
    doc = tomllib.loads(path.read_text(encoding="utf-8"))
    base, defaults = path.parent, doc.get("defaults", {})
    out: list[LogEntry] = []
    for row in doc.get("log", []):
        get = {**defaults, **row}.get
        missing = [k for k in ("path", "dbc", "map", "vehicle") if not get(k)]
        if missing:
            raise SystemExit(f"{path}: log {row.get('name') or row.get('path')!r} lacks {', '.join(missing)}")
        vehicle = str(get("vehicle"))
        if vehicle.endswith(".toml"):
            vehicle = str(base / vehicle)
        log = base / str(get("path"))
        out.append(LogEntry(name=str(get("name") or log.name), path=log, dbc=base / str(get("dbc")),
                            signal_map=base / str(get("map")), vehicle=vehicle, car=str(get("car") or "-"),
                            date=str(get("date") or "-"), season=str(get("season") or "-"),
                            note=str(get("note") or "")))
    return out


def _f(v: Any, digits: int = 1) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.{digits}f}"


def _g(v: Any) -> str:
    """A parameter value to four significant digits ("-" when not finite)."""
    return "-" if v is None or not math.isfinite(float(v)) else f"{float(v):.4g}"


def _ci(pair: Any, digits: int) -> str:
    """An interval ``(lo, hi)`` as text ("[-]" when there is none)."""
    if pair is None:
        return "[-]"
    lo, hi = pair
    return f"[{_f(lo, digits)}, {_f(hi, digits)}]"


def analysis_lines(entry: LogEntry, res: AnalysisResult) -> list[str]:
    """The per-log figures, read from the same payload ``lashscope analyze`` formats."""
    doc, _ = result_payload(res)
    s = doc["summary"]
    m = s.get("metrics") or {}
    speed = res.signals.signals.get("motor_speed_rpm")
    span = float(speed.t[-1] - speed.t[0]) if speed is not None and len(speed) > 1 else float("nan")
    ripple, nrmse = m.get("fluctuation_rpm") or {}, m.get("nrmse") or {}
    tr = s.get("tracking") or {}
    lines = [f"  duration {_f(span)} s (motor speed); events {s['events']} found ({s['tip_in']} tip-in, "
             f"{s['tip_out']} tip-out), {s['with_metrics']} used",
             f"  tracking {tr.get('verdict', '-')}, median NRMSE {_f(nrmse.get('difference_median'), 3)}; "
             f"median ripple (peak-valley) measured {_f(ripple.get('measured_median'))} rpm, "
             f"simulated {_f(ripple.get('simulated_median'))} rpm"]
    shuffle = m.get("shuffle_freq_hz") or {}
    if shuffle:
        lines.append(f"  shuffle frequency median measured {_f(shuffle.get('measured_median'), 2)} Hz, "
                     f"simulated {_f(shuffle.get('simulated_median'), 2)} Hz")
    return lines


def used_events(res: AnalysisResult) -> list[Event]:
    """The events the analysis compared (included and with metrics)."""
    return [er.event for er in res.event_results if er.comparison is not None]


def arx_first_mode(signals: SignalSet, events: list[Event]) -> dict[str, float] | None:
    """Lowest complex mode of an ARX model of motor-speed increments from torque, on the event windows.

    y[k] = w[k] - w[k-1] = -sum a_i y[k-i] + sum b_i u[k-i] + c_event, least squares over all windows;
    the order in ``ARX_ORDERS`` with the lowest BIC is kept. None when there is too little data.
    """
    w_sig, u_sig = signals["motor_speed_rpm"], signals["motor_torque_nm"]
    dt = float(np.mean(np.diff(w_sig.t)))
    windows: list[tuple[FloatArray, FloatArray]] = []
    for ev in events:
        t = np.arange(ev.t_start_s, ev.t_end_s, dt)
        if t.size > 12:
            windows.append((np.diff(np.interp(t, w_sig.t, w_sig.values)), np.interp(t, u_sig.t, u_sig.values)[1:]))
    best: dict[str, float] | None = None
    for n in ARX_ORDERS:
        rows, ys = [], []
        for j, (y, u) in enumerate(windows):
            for k in range(n, y.size):
                bias = np.zeros(len(windows))
                bias[j] = 1.0
                rows.append(np.concatenate([-y[k - n:k][::-1], u[k - n:k][::-1], bias]))
                ys.append(y[k])
        if len(ys) < 4 * (2 * n + len(windows)):
            continue
        phi, yv = np.asarray(rows), np.asarray(ys)
        theta, *_ = np.linalg.lstsq(phi, yv, rcond=None)
        rss = float(np.sum((yv - phi @ theta) ** 2))
        bic = yv.size * math.log(max(rss, 1e-12) / yv.size) + phi.shape[1] * math.log(yv.size)
        s = np.log(np.roots(np.concatenate([[1.0], theta[:n]])).astype(complex)) / dt
        pairs = sorted((abs(p) / (2 * math.pi), -p.real / abs(p)) for p in s if p.imag > 1e-9)
        if pairs and (best is None or bic < best["bic"]):
            best = {"order": n, "freq_hz": float(pairs[0][0]), "zeta": float(pairs[0][1]), "bic": bic,
                    "windows": len(windows), "dt_ms": dt * 1e3}
    return best


def identify_lines(entry: LogEntry, withheld: LogEntry | None) -> list[str]:
    """The project's identification of one drive, validated on ``withheld`` (guarded: may be absent)."""
    identify_logs = options = None
    for where in ("app.identify", "app.identify.logs"):  # the package may or may not re-export them
        try:
            mod = importlib.import_module(where)
            identify_logs, options = mod.identify_logs, mod.IdentifyOptions
            break
        except (ImportError, AttributeError):
            continue
    if identify_logs is None or options is None:
        return ["  identify: unavailable (app.identify.identify_logs is not in this checkout yet)"]
    vehicle = load_vehicle(entry.vehicle)
    try:
        res = identify_logs([entry.path], vehicle,
                            options(dbc=entry.dbc, signal_map=entry.signal_map, seed=0),
                            validate=[withheld.path] if withheld else [])
    except Exception as exc:  # a drive too short to identify is a result to print, not a crash
        return [f"  identify: failed: {type(exc).__name__}: {exc}"]
    params = dict(res.params)
    names = [n for n in PARAM_ORDER if n in params] + [n for n in params if n not in PARAM_ORDER]
    lines = ["  identify (" + (f"withheld {withheld.name}" if withheld else "no withheld drive of this car") + "):"]
    for n in names:
        p = params[n]
        lines.append(f"    {n:<14} {_g(p.value)} [{_g(p.lo)}, {_g(p.hi)}] {getattr(p, 'unit', '')}"
                     f"{'' if p.identified else '  (not identified)'}")
    md = res.modal
    if md is not None:
        lines.append(f"    modal: {_f(md.freq_hz, 2)} Hz {_ci(md.freq_ci, 2)}, "
                     f"zeta {_f(md.zeta, 3)} {_ci(md.zeta_ci, 3)}")
    v = res.validation or {}
    if v:
        lines.append(f"    withheld NRMSE before {_f(v.get('nrmse_before'), 3)}, after {_f(v.get('nrmse_after'), 3)}")
    return lines


def _identify(paths: list[Path], like: LogEntry, validate: list[Path]) -> Any:
    """``identify_logs`` on ``paths`` (decoded like ``like``): its result, or the error's text."""
    from app.identify import IdentifyOptions, identify_logs

    try:
        return identify_logs(paths, load_vehicle(like.vehicle),
                             IdentifyOptions(dbc=like.dbc, signal_map=like.signal_map, seed=0), validate=validate)
    except Exception as exc:  # a drive too short to identify is a result to print
        return f"{type(exc).__name__}: {str(exc)[:120]}"


def pool_lines(car: str, drives: list[LogEntry]) -> list[str]:
    """One car's drives identified together, each drive against the pooled values, and leave-one-drive-out."""
    lines = [f"== car {car}: {len(drives)} drives pooled ({', '.join(d.name for d in drives)})"]
    pooled = _identify([d.path for d in drives], drives[0], [])
    if isinstance(pooled, str):
        return [*lines, f"  pooled identification failed: {pooled}"]
    ids = {k: p for k, p in pooled.params.items() if p.identified and k in PARAM_ORDER}
    lines.append("  pooled: " + "; ".join(f"{k} {_g(p.value)} [{_g(p.lo)}, {_g(p.hi)}] {p.unit}" for k, p in
                                          ids.items()) + (f"; modal {_f(pooled.modal.freq_hz, 2)} Hz, zeta "
                                                          f"{_f(pooled.modal.zeta, 3)}" if pooled.modal else ""))
    consistent = identified = 0
    improved = 0
    holds: dict[str, list[bool]] = {k: [] for k in ids}
    for d in drives:
        own = _identify([d.path], d, [])
        if isinstance(own, str):
            lines.append(f"  {d.name:24s} own: failed ({own})")
        else:
            held = {k: own.params[k] for k in ids if k in own.params and own.params[k].identified}
            ok = bool(held) and all(p.lo <= ids[k].value <= p.hi for k, p in held.items())
            for k, p in held.items():
                holds[k].append(bool(p.lo <= ids[k].value <= p.hi))
            identified += bool(held)
            consistent += ok
            lines.append(f"  {d.name:24s} own: " + ("; ".join(f"{k} {_g(p.value)} [{_g(p.lo)}, {_g(p.hi)}]"
                                                            for k, p in held.items()) or "nothing identified")
                         + (" -- holds the pooled values" if ok else ""))
        rest = [e.path for e in drives if e is not d]
        loo = _identify(rest, d, [d.path])
        if isinstance(loo, str):
            lines.append(f"  {'':24s} left out: identification of the others failed ({loo})")
            continue
        v = loo.validation
        better = (v.get("nrmse_after") or math.inf) < (v.get("nrmse_before") or math.inf)
        improved += better
        lines.append(f"  {'':24s} left out: tracking {v.get('verdict_before')} -> {v.get('verdict_after')}, "
                     f"NRMSE {_f(v.get('nrmse_before'), 3)} -> {_f(v.get('nrmse_after'), 3)}")
    lines.append("  per parameter, drives whose own interval holds the pooled value: " + ", ".join(
        f"{k} {sum(v)} of {len(v)}" for k, v in holds.items()))
    lines.append(f"  consistent with the pooled values: {consistent} of {identified} drives identified on their own "
                 f"({len(drives)} drives); left-out drive tracked better: {improved} of {len(drives)}")
    return lines


def withheld_for(entry: LogEntry, entries: list[LogEntry]) -> LogEntry | None:
    """The next drive of the same car (cyclically) that decodes with the same database and map."""
    same = [e for e in entries if e.car == entry.car and e.dbc == entry.dbc and e.signal_map == entry.signal_map
            and e.vehicle == entry.vehicle]
    if len(same) < 2 or entry.car == "-":
        return None
    return same[(same.index(entry) + 1) % len(same)]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("manifest", type=Path)
    ap.add_argument("--only", nargs="*", default=None, metavar="NAME", help="these logs of the manifest only")
    ap.add_argument("--identify", action="store_true", help="also run app.identify per drive (when present)")
    ap.add_argument("--pool", action="store_true", help="per car: pooled identification, per-drive consistency "
                    "and leave-one-drive-out tracking (instead of the per-log blocks)")
    ap.add_argument("--no-whole-log", action="store_true", help="skip the whole-log simulation (faster; the "
                    "tracking verdict then lacks the drift check)")
    a = ap.parse_args()
    entries = read_manifest(a.manifest)
    chosen = [e for e in entries if a.only is None or e.name in a.only]
    if a.pool:
        cars: dict[tuple[str, ...], list[LogEntry]] = {}
        for e in chosen:
            if e.car != "-":
                cars.setdefault((e.car, str(e.dbc), str(e.signal_map), e.vehicle), []).append(e)
        for key, drives in cars.items():
            if len(drives) >= 3:
                for line in pool_lines(key[0], drives):
                    print(line, flush=True)
        return 0
    for e in chosen:
        print(f"== {e.name}: {e.path.name}  car {e.car}, {e.date} (season {e.season}), vehicle {Path(e.vehicle).stem}, "
              f"map {e.signal_map.name}")
        if e.note:
            print(f"  note: {e.note}")
        t0 = time.perf_counter()
        try:
            res = run_analysis(e.path, VehicleInputs(load_vehicle(e.vehicle), e.dbc, e.signal_map),
                               AnalysisOptions(whole_log=not a.no_whole_log))
        except Exception as exc:  # one unreadable log should not stop the run
            print(f"  analysis failed: {type(exc).__name__}: {exc}")
            continue
        for line in analysis_lines(e, res):
            print(line)
        mode = arx_first_mode(res.signals, used_events(res))
        if mode is None:
            print("  reference ARX mode: too little event data")
        else:
            print(f"  reference ARX mode (order {mode['order']:.0f}, {mode['windows']:.0f} windows, "
                  f"grid {mode['dt_ms']:.1f} ms): {mode['freq_hz']:.2f} Hz, zeta {mode['zeta']:.3f}")
        if a.identify:
            for line in identify_lines(e, withheld_for(e, entries)):
                print(line)
        print(f"  ({time.perf_counter() - t0:.1f} s)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
