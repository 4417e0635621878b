"""How far an effect drawn over a wrong data sheet stands out from a data-sheet error, by the generator's own
equations.

A ``base_effect`` case of ``bench/indep`` drives a car whose base parameters are off by up to 20 % *and* that
carries one library effect. Part of an effect's signature can be the signature of a different data sheet: a
15 ms speed-sensor window at 100 Hz changes the log the way a little more damping does, a delay is a
torque-speed time offset, a backlash whose gaps grow is a larger total lash. What no data sheet of the car
can produce is what a diagnosis can attribute to the effect, whatever tool makes it.

:func:`separable_sigma` measures that in the generator's world, not lashscope's: the best effect-free car of
the generator's family (its four data-sheet scales -- half-shaft stiffness, damping, body mass, every
clearance -- fitted by Nelder-Mead, from the case's true scales) is compared with the case's car on drive A,
with :func:`bench.indep.cases.signal_sigma` (RMS over event windows after each window's level and slope and
one time shift, in noise sigmas). An effect under :data:`SEPARABLE_SIGMA` is one a data-sheet change
mimics to within the faint band (:data:`bench.indep.cases.FAINT_SIGMA`); the benchmark reports the
attribution target on all drives and on the separable ones.

Results are cached beside the set's manifest, keyed by the generator's version.

**A second channel** (``--wheels``, :func:`separable_sigma` with ``wheels=True``): the recorded driven-wheel
speeds (``ESP_WheelSpeeds``, the mean of the two driven wheels, at the generator's wheel-speed noise and the DBC's
0.1 rpm step) are added to the signature, each channel after its own window level and slope and its own time
shift, and the best effect-free data sheet is fitted to both. The question it answers: would a tool that also
read the wheel speeds tell these effects from a data sheet? On ``ifinal13``'s effect drives it does not change
the answer (docs/identify.md, "A second channel does not separate them").

Run alone::

    .venv/bin/python bench/separable.py --set ifinal12 [--wheels]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: the repository's packages

from bench.indep.car import Car, car_named
from bench.indep.cases import (
    BANDS,
    FAINT_SIGMA,
    IDENTIFY_SETS,
    NOISE_RPM,
    REC,
    SHIFT_S,
    Case,
    Drive,
    _band_drive,
    _reported,
    generator_version,
    plan,
    signal_sigma,
    truth_car,
    window_ms,
)
from bench.indep.dynamics import simulate
from bench.indep.record import RPM, sensor_speed

SEPARABLE_SIGMA = FAINT_SIGMA[1]  # an effect mimicked by a data sheet to under this is not attributable
KNOBS = ("k_scale", "c_scale", "mass_scale", "gap_scale")
MAX_EVALS = 80


WHEEL_NOISE_RPM = float(np.hypot(REC.wheel_noise_rpm, 0.1 / np.sqrt(12)))  # noise and the DBC's 0.1 rpm step
Channels = tuple[np.ndarray, np.ndarray, np.ndarray]  # t, reported motor speed, mean driven-wheel speed (rpm)


def channels(car: Car, drive: Drive) -> Channels:
    """What the logger records of ``car`` on ``drive``: the inverter's speed and the driven wheels' mean speed."""
    sim = simulate(car, drive.t, drive.torque, drive.speed0_kmh)
    return sim["t"], sensor_speed(car, sim["t"], sim["speed_rel"]), 0.5 * (sim["wheel_l"] + sim["wheel_r"]) * RPM


def two_channel_sigma(truth: Channels, sheet: Channels, drive: Drive, shift_s: float = SHIFT_S) -> float:
    """Truth-vs-sheet signature over motor and wheel speed, in noise sigmas: the root of the sum of each channel's
    mean square in its own noise variance (each channel with its own shift; the ESP has its own clock)."""
    t = truth[0]
    motor = window_ms(t, sheet[1], truth[1], drive, shift_s) / NOISE_RPM ** 2
    wheel = window_ms(t, sheet[2], truth[2], drive, shift_s) / WHEEL_NOISE_RPM ** 2
    return float(np.sqrt(motor + wheel))


def separable_sigma(case: Case, wheels: bool = False) -> float:
    """The case's effect signature left after the best effect-free data sheet, in noise sigmas (motor speed
    alone, or with the driven wheels' speed too)."""
    nominal = car_named(case.car)
    drive = _band_drive(BANDS[case.car][0], case.seed, case.duration_s, nominal)
    truth = truth_car(case.effects, case.base, case.car)
    seen = channels(truth, drive) if wheels else None
    x0 = np.log([float(case.base.get(k, 1.0)) for k in KNOBS])

    def cost(x: np.ndarray) -> float:
        sheet = truth_car({}, dict(zip(KNOBS, np.exp(np.clip(x, -1.5, 1.5)), strict=True)), case.car)
        if seen is not None:
            return two_channel_sigma(seen, channels(sheet, drive), drive)
        return signal_sigma(truth, drive, _reported(sheet, drive))

    res = minimize(cost, x0, method="Nelder-Mead",
                   options={"maxfev": MAX_EVALS, "initial_simplex": x0 + np.vstack([np.zeros(4), 0.1 * np.eye(4)])})
    return float(min(res.fun, cost(x0)))


def separable(folder: Path, cases: list[Case], wheels: bool = False) -> dict[str, float]:
    """:func:`separable_sigma` of each ``base_effect`` case, computed once per generator version (motor speed
    alone under ``sigma``, with the wheels under ``sigma_wheels``)."""
    path = folder / "separable.json"
    key = "sigma_wheels" if wheels else "sigma"
    version = generator_version()
    doc = json.loads(path.read_text(encoding="utf-8")) if path.exists() else {}
    if doc.get("generator") != version:
        doc = {"generator": version}
    doc.setdefault(key, {})
    todo = [c for c in cases if c.kind == "base_effect" and c.name not in doc[key]]
    t0 = time.perf_counter()
    for i, c in enumerate(todo):
        doc[key][c.name] = separable_sigma(c, wheels)
        path.write_text(json.dumps(doc, indent=1), encoding="utf-8")
        spent = time.perf_counter() - t0
        print(f"separable{' with wheels' if wheels else ''} [{i + 1}/{len(todo)}] {c.name}: "
              f"{doc[key][c.name]:.1f} sigma beyond the best data sheet ({spent:.0f} s, "
              f"about {spent / (i + 1) * (len(todo) - i - 1):.0f} s left)", file=sys.stderr, flush=True)
    return {c.name: float(doc[key][c.name]) for c in cases if c.name in doc[key]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--set", default="ifinal12", choices=sorted(IDENTIFY_SETS))
    ap.add_argument("--wheels", action="store_true", help="also with the driven wheels' speed as a second channel")
    args = ap.parse_args()
    folder = Path(__file__).resolve().parent / "out" / "indep" / args.set / "full"
    folder.mkdir(parents=True, exist_ok=True)
    cases = [c for c in plan(args.set, False) if c.kind == "base_effect"]
    alone = separable(folder, cases)
    both = separable(folder, cases, wheels=True) if args.wheels else {}
    for c in cases:
        extra = f", with the driven wheels {both[c.name]:5.1f} sigma" if c.name in both else ""
        print(f"{c.name:40s} motor speed alone {alone[c.name]:5.1f} sigma{extra}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
