"""Benchmark cases of the independent generator and their manifest.

Kinds: ``none`` (nominal car), ``single`` (one library effect, drawn from the ranges below),
``faint`` (one library effect scaled toward off until the truth differs from the nominal car by
2-10 noise sigma), ``pair`` (two library effects at once), ``ool`` (out of the library: unequal
half-shafts, or a first-order torque ripple). Effect sizes are the generator's own parameters;
each maps to the library id it should be diagnosed as (``EFFECT_DRAWS``).

Signal size: RMS over event windows (-0.2..+1.0 s around each torque reversal, 100 Hz) of the
reported speed of the truth minus that of the nominal car, less each window's straight-line fit
(a speed level and slope are what the diagnosis' road-load and anchor nuisances absorb, and a
drag change otherwise shows as a drift over the whole drive) and at the best common time shift
within +-20 ms (the diagnosis' torque-speed offset: a sensor delay is indistinguishable from it),
over the noise sigma of the log's speed (sensor noise and 0.5 rpm quantisation). Seeds: ``dev`` from
10 000, ``final`` from 50 000, ``holdout`` from 90 000 (made after the final set had been scored once,
for the rule as fixed at the end), ``check`` from 130 000 (made after ``holdout`` had been scored once and
then used for tuning, to score the rule that came out of that once), ``check2`` from 170 000 (for the
rule as changed after ``check`` had been scored once).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from bench.indep.car import PRESET, Car, nominal_car, with_effect
from bench.indep.drive import BAND_A, BAND_B, Band, Drive, make_drive
from bench.indep.dynamics import simulate
from bench.indep.record import DBC, Recording, sensor_speed, write_drive

Draw = Callable[[np.random.Generator], dict[str, float]]


def _u(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi))


def _signed_log2(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(2.0 ** (rng.choice([-1.0, 1.0]) * rng.uniform(lo, hi)))


EFFECT_DRAWS: dict[str, Draw] = {
    # extra lash in differential + half-shafts (wear), second mesh within its tolerance
    "backlash": lambda r: {"diff_scale": _u(r, 1.5, 3.0), "shaft_scale": _u(r, 1.3, 2.0),
                           "mesh_scale": _u(r, 0.8, 1.5)},
    "housing_mount": lambda r: {"k_scale": _signed_log2(r, 0.8, 2.0), "c_scale": _signed_log2(r, 0.0, 1.5)},
    "torque_lag": lambda r: {"tau_s": _u(r, 0.008, 0.035), "dead_s": _u(r, 0.0, 0.015)},
    "speed_sensor": lambda r: {"window_s": _u(r, 0.005, 0.030), "delay_s": _u(r, 0.0, 0.008)},
    "drag": lambda r: {"coulomb_nm": _u(r, 1.0, 6.0), "viscous_nms": _u(r, 0.003, 0.02)},
    "progressive_stiffness": lambda r: {"shaft_rel": _u(r, 0.5, 2.0), "mount_rel": _u(r, 0.5, 2.0)},
    "tyre_slip": lambda r: {"c_n": _u(r, 2.5e4, 8e4), "sigma_m": _u(r, 0.2, 0.6)},
}
OFF = {"backlash": {"diff_scale": 1.0, "shaft_scale": 1.0, "mesh_scale": 1.0},
       "housing_mount": {"k_scale": 1.0, "c_scale": 1.0}, "torque_lag": {"tau_s": 0.0, "dead_s": 0.0},
       "speed_sensor": {"window_s": 0.002, "delay_s": 0.0}, "drag": {"coulomb_nm": 0.0, "viscous_nms": 0.0},
       "progressive_stiffness": {"shaft_rel": 0.0, "mount_rel": 0.0}, "tyre_slip": {"c_n": 2.0e7, "sigma_m": 0.05}}
OUT_OF_LIBRARY: dict[str, Draw] = {
    "unequal_shafts": lambda r: {"left_scale": _u(r, 0.4, 0.65), "right_scale": _u(r, 1.0, 1.3)},
    "torque_ripple": lambda r: {"amplitude_nm": _u(r, 4.0, 12.0)},
}
LIBRARY = tuple(EFFECT_DRAWS)
FAINT_SIGMA = (2.0, 10.0)
SEED_BASE = {"dev": 10_000, "final": 50_000, "holdout": 90_000, "check": 130_000, "check2": 170_000}
REC = Recording()
NOISE_RPM = float(np.hypot(REC.speed_noise_rpm, 0.5 / np.sqrt(12)))


@dataclass
class Case:
    name: str
    kind: str  # none | single | faint | pair | ool
    seed: int
    effects: dict[str, dict[str, float]]  # generator effect id -> its parameters
    expected: list[str]  # library ids, ["none"] or ["out_of_library"]
    duration_s: float
    signal_sigma: float = 0.0
    drive_a: str = ""
    drive_b: str = ""
    recorded: dict[str, float] = field(default_factory=dict)


def _scaled(effect: str, v: dict[str, float], lam: float) -> dict[str, float]:
    """Parameters a fraction ``lam`` of the way from off to ``v`` (log-scale for scale factors)."""
    off = OFF[effect]
    out = {}
    for k, x in v.items():
        if k.endswith("scale"):
            out[k] = float(x**lam)
        else:
            out[k] = float(off[k] + lam * (x - off[k]))
    return out


def truth_car(effects: dict[str, dict[str, float]]) -> Car:
    car = nominal_car()
    for eff, v in effects.items():
        car = with_effect(car, eff, v)
    return car


def _reported(car: Car, drive: Drive) -> tuple[np.ndarray, np.ndarray]:
    sim = simulate(car, drive.t, drive.torque, drive.speed0_kmh)
    return sim["t"], sensor_speed(car, sim["t"], sim["speed_rel"])


SHIFT_S = 0.02  # s: the diagnosis' torque-speed time offset spans +-2 periods of a 100 Hz speed channel


def signal_sigma(truth: Car, drive: Drive, nominal: tuple[np.ndarray, np.ndarray] | None = None,
                 shift_s: float = SHIFT_S) -> float:
    """Truth-vs-nominal RMS of the reported speed over event windows, in noise sigmas, after what the
    diagnosis' nuisances absorb: each window's level and slope, and one time shift of the whole drive
    within ``shift_s`` (a speed-sensor delay *is* a torque-speed time offset)."""
    t, a = nominal or _reported(nominal_car(), drive)
    _, b = _reported(truth, drive)
    grids = [g for r in drive.reversals
             if (g := np.arange(r - 0.2, r + 1.0, 0.01))[0] > shift_s and g[-1] < t[-1] - shift_s]

    def rms(shift: float) -> float:
        parts = []
        for g in grids:
            d = np.interp(g - shift, t, b) - np.interp(g, t, a)
            parts.append(d - np.polyval(np.polyfit(g, d, 1), g))  # a window's level and slope are nuisance
        d = np.concatenate(parts)
        return float(np.sqrt(np.mean(d * d)))

    best = min(rms(float(s)) for s in np.arange(-shift_s, shift_s + 1e-9, 0.0005))
    return best / NOISE_RPM


def plan(which: str, quick: bool) -> list[Case]:
    """The cases of a seed set (``dev`` or ``final``); ``quick`` keeps a smaller, fixed subset."""
    base = SEED_BASE[which]
    rng = np.random.default_rng(base)
    dur = 40.0 if quick else 60.0
    n_single, n_none, n_faint, n_pair, n_ool = (1, 2, 2, 2, 2) if quick else (3, 6, 7, 5, 5)
    out: list[Case] = []
    s = base
    for _ in range(n_none):
        out.append(Case(f"none_{s}", "none", s, {}, ["none"], dur))
        s += 1
    for _ in range(n_single):
        for eff in LIBRARY:
            r = np.random.default_rng(s)
            out.append(Case(f"single_{eff}_{s}", "single", s, {eff: EFFECT_DRAWS[eff](r)}, [eff], dur))
            s += 1
    faint_effects = [str(e) for e in rng.permutation(LIBRARY)][:n_faint] if quick else list(LIBRARY)[:n_faint]
    for eff in faint_effects:
        r = np.random.default_rng(s)
        out.append(Case(f"faint_{eff}_{s}", "faint", s, {eff: EFFECT_DRAWS[eff](r)}, [eff], dur,
                        recorded={"target_sigma": _u(r, *FAINT_SIGMA)}))
        s += 1
    for _ in range(n_pair):
        a, b = (str(x) for x in rng.choice(LIBRARY, size=2, replace=False))
        r = np.random.default_rng(s)
        out.append(Case(f"pair_{a}+{b}_{s}", "pair", s, {a: EFFECT_DRAWS[a](r), b: EFFECT_DRAWS[b](r)},
                        sorted([a, b]), dur))
        s += 1
    for k in range(n_ool):
        eff = ("unequal_shafts", "torque_ripple")[0 if k % 5 < 3 else 1] if not quick else \
            ("unequal_shafts", "torque_ripple")[k % 2]
        r = np.random.default_rng(s)
        out.append(Case(f"ool_{eff}_{s}", "ool", s, {eff: OUT_OF_LIBRARY[eff](r)}, ["out_of_library"], dur))
        s += 1
    return out


def _faint(case: Case, drive: Drive) -> None:
    """Scale the case's one effect toward off until its signal is the drawn target (bisection on the fraction)."""
    (eff, v), = case.effects.items()
    target = case.recorded["target_sigma"]
    nominal = _reported(nominal_car(), drive)
    lo, hi = 0.0, 1.0
    for _ in range(7):
        mid = 0.5 * (lo + hi)
        got = signal_sigma(truth_car({eff: _scaled(eff, v, mid)}), drive, nominal)
        lo, hi = (mid, hi) if got < target else (lo, mid)
    case.effects = {eff: _scaled(eff, v, 0.5 * (lo + hi))}


def _band_drive(band: Band, seed: int, duration: float) -> Drive:
    return make_drive(nominal_car(), band, np.random.default_rng(seed), duration)


def build(case: Case, folder: Path) -> Case:
    """Simulate and record the case's drives A and B into ``folder``; fills paths and signal size."""
    da = _band_drive(BAND_A, case.seed, case.duration_s)
    db = _band_drive(BAND_B, case.seed + 500_000, case.duration_s)
    if case.kind == "faint":
        _faint(case, da)
    car = truth_car(case.effects)
    case.signal_sigma = signal_sigma(car, da) if case.effects else 0.0
    for tag, drive, extra in (("A", da, 0), ("B", db, 500_000)):
        sim = simulate(car, drive.t, drive.torque, drive.speed0_kmh)
        path = folder / f"{case.name}_{tag}.blf"
        info = write_drive(path, car, sim, drive.t, drive.torque, np.random.default_rng(case.seed + 1 + extra), REC,
                           epoch=1.7e9 + case.seed)
        case.recorded[f"offset_{tag}_s"] = info["offset_s"]
        case.recorded[f"reversals_{tag}"] = float(drive.reversals.size)
        setattr(case, f"drive_{tag.lower()}", path.name)
    return case


def generator_version() -> str:
    """Hash of the generator's sources and the data it reads: a cached set is reused only when equal."""
    h = hashlib.sha256()
    for f in [*sorted(Path(__file__).parent.glob("*.py")), PRESET, DBC]:
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def write_manifest(path: Path, cases: list[Case]) -> None:
    doc = {"generator": generator_version(), "cases": [asdict(c) for c in cases]}
    path.write_text(json.dumps(doc, indent=1), encoding="utf-8")


def read_manifest(path: Path) -> list[Case]:
    """Cases of a cached set; empty when it was made by another version of the generator."""
    doc = json.loads(path.read_text(encoding="utf-8"))
    if not isinstance(doc, dict) or doc.get("generator") != generator_version():
        return []
    return [Case(**c) for c in doc["cases"]]
