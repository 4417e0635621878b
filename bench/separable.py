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
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from bench.indep.car import car_named
from bench.indep.cases import (
    BANDS,
    FAINT_SIGMA,
    Case,
    _band_drive,
    _reported,
    generator_version,
    signal_sigma,
    truth_car,
)

SEPARABLE_SIGMA = FAINT_SIGMA[1]  # an effect mimicked by a data sheet to under this is not attributable
KNOBS = ("k_scale", "c_scale", "mass_scale", "gap_scale")
MAX_EVALS = 80


def separable_sigma(case: Case) -> float:
    """The case's effect signature left after the best effect-free data sheet, in noise sigmas."""
    nominal = car_named(case.car)
    drive = _band_drive(BANDS[case.car][0], case.seed, case.duration_s, nominal)
    truth = truth_car(case.effects, case.base, case.car)
    x0 = np.log([float(case.base.get(k, 1.0)) for k in KNOBS])

    def cost(x: np.ndarray) -> float:
        sheet = truth_car({}, dict(zip(KNOBS, np.exp(np.clip(x, -1.5, 1.5)), strict=True)), case.car)
        return signal_sigma(truth, drive, _reported(sheet, drive))

    res = minimize(cost, x0, method="Nelder-Mead",
                   options={"maxfev": MAX_EVALS, "initial_simplex": x0 + np.vstack([np.zeros(4), 0.1 * np.eye(4)])})
    return float(min(res.fun, cost(x0)))


def separable(folder: Path, cases: list[Case]) -> dict[str, float]:
    """:func:`separable_sigma` of each ``base_effect`` case, computed once per generator version."""
    path = folder / "separable.json"
    version = generator_version()
    doc = json.loads(path.read_text(encoding="utf-8")) if path.exists() else {}
    if doc.get("generator") != version:
        doc = {"generator": version, "sigma": {}}
    todo = [c for c in cases if c.kind == "base_effect" and c.name not in doc["sigma"]]
    t0 = time.perf_counter()
    for i, c in enumerate(todo):
        doc["sigma"][c.name] = separable_sigma(c)
        path.write_text(json.dumps(doc, indent=1), encoding="utf-8")
        spent = time.perf_counter() - t0
        print(f"separable [{i + 1}/{len(todo)}] {c.name}: {doc['sigma'][c.name]:.1f} sigma beyond the best data "
              f"sheet ({spent:.0f} s, about {spent / (i + 1) * (len(todo) - i - 1):.0f} s left)",
              file=sys.stderr, flush=True)
    return {c.name: float(doc["sigma"][c.name]) for c in cases if c.name in doc["sigma"]}
