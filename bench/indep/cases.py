"""Benchmark cases of the independent generator and their manifest.

Kinds: ``none`` (nominal car), ``single`` (one library effect, drawn from the ranges below),
``faint`` (one library effect scaled toward off until the truth differs from the nominal car by
2-10 noise sigma), ``pair`` (two library effects at once), ``ool`` (out of the library: unequal
half-shafts, or a first-order torque ripple); for the vehicle identification sets (``idev``,
``ifinal``, :func:`plan_identify`) also ``base`` (a wrong data sheet: one or several base parameters
off, no effect) and ``base_effect`` (every base parameter off by up to 20 % plus one library effect).
Effect sizes are the generator's own parameters;
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
rule as changed after ``check`` had been scored once); ``idev`` from 210 000 (identification
development) and ``ifinal`` from 250 000 (scored once, with the rule fixed).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from bench.indep.car import (
    CHAIN_LOW,
    CHAIN_PRESET,
    PRESET,
    Car,
    car_named,
    is_chain,
    lash_at_motor_mrad,
    nominal_car,
    stiffness_at_motor,
    with_base,
    with_effect,
)
from bench.indep.drive import BANDS, Band, Drive, make_drive
from bench.indep.dynamics import first_mode, simulate
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
SEED_BASE = {"dev": 10_000, "final": 50_000, "holdout": 90_000, "check": 130_000, "check2": 170_000,
             "idev": 210_000, "ifinal": 250_000, "idev2": 290_000, "ifinal2": 330_000, "ifinal3": 370_000,
             "ichain": 410_000, "ichain2": 430_000, "ifinal4": 450_000, "ifinal5": 470_000, "ichain3": 490_000,
             "ifinal6": 510_000, "ifinal7": 530_000, "ifinal8": 550_000, "ifinal9": 570_000,
             "ifinal10": 590_000, "ifinal11": 610_000, "ifinal12": 630_000,
             "ifinal13": 650_000, "ifinal14": 670_000, "ifinal15": 690_000, "ifinal16": 710_000,
             "ifinal17": 730_000, "ifinal18": 750_000,
             "ifinal19": 770_000, "ifinal20": 790_000}
# ifinal5 and ichain3: fresh sets for the contact law the log chooses (app/identify/form.py), scored once;
# ifinal6: the fresh set for the intervals as calibrated after them (app/identify/fit.py), scored once; ifinal7: the
# next, for the diagnosis' time-offset rule (app/analysis/diagnosis/decide.py:timing_unresolved), scored once;
# ifinal8: the next, for the joint refits from both sides of the effect-base ridge (app/analysis/diagnosis/rebase.py),
# scored once; ifinal9: the next, for the mode's pins giving way to the grey box (app/identify/fit.py:PIN_RECHECK),
# scored once; ifinal10: the next, for the model-form floor that grows with the identified car's move from its file
# (app/identify/fit.py:MOVE_FORM), scored once; ifinal11: the next, for an effect named beside a wrong data sheet only
# when it beats the base alone refitted from its joint fit (app/analysis/diagnosis/rebase.py:base_alone), scored once;
# ifinal12: the next, for the rules as they stand after the grey box's first-step screen (app/identify/fit.py:
# REACH_SKIP) and the partner screen, scored once; ifinal13: the next, for the same rules with the fits' simulator loop
# written out per layout (sim/unrolled.py, the same numbers bit for bit), scored once; ifinal14: the next, for pins
# within the noise floor rechecked where the grey box's first step promises much less (app/identify/fit.py:
# PIN_CLOSER), scored once; ifinal15: the next, for the other contact law also tried with the lash at the file's value
# (app/identify/form.py:law_change), scored once; ifinal16: the next, for the pins' uncertainty carried into the
# intervals, the model-form damping floor calibrated on ifinal10-15 (app/identify/fit.py:pin_spread, MODEL_FORM) and
# a slow logger's windows (app/analysis/diagnosis/prepare.py:enough_samples, app/analysis/events.py:gap_limit),
# scored once; ifinal17: the next, for a value whose interval reaches its prior's bound held by it (app/identify/fit.py:
# interval_reaches) and a fit stopped on the torque gain's bound refined again along the gain-mass ridge
# (app/identify/fit.py:off_the_gain_bound), scored once; ifinal18: the next, for the lash's other basins tried where
# the grey box leaves most of the baseline's residual (app/identify/fit.py:_joint, LASH_STARTS), scored once;
# ifinal19: the next, for the gain-bound refit only where that bound alone holds the fit, scored once; ifinal20: the
# next, for the lash's other basins also tried where the fit's own point with the lash moved fits better
# (app/identify/fit.py:lash_moved) and each window's mode kept for the next stage (app/identify/modal.py:window_mode)
IDENTIFY_SETS = ("idev", "ifinal", "idev2", "ifinal2", "ifinal3", "ichain", "ichain2", "ifinal4", "ifinal5",
                 "ichain3", "ifinal6", "ifinal7", "ifinal8", "ifinal9", "ifinal10",
                 "ifinal11", "ifinal12", "ifinal13", "ifinal14", "ifinal15", "ifinal16", "ifinal17", "ifinal18",
                 "ifinal19", "ifinal20")
# the chain car of each identification set: idev and ifinal kept the preset's ~16 Hz mode (above what a 20-33 Hz
# logger resolves); idev2 and ifinal2 drive the low-mode car the formula-student logs show (chain_low.toml)
CHAIN_CAR = {"idev": "chain_drive", "ifinal": "chain_drive", "idev2": "chain_low", "ifinal2": "chain_low",
             "ifinal3": "chain_low", "ichain": "chain_low", "ichain2": "chain_low", "ifinal4": "chain_low",
             "ifinal5": "chain_low", "ichain3": "chain_low", "ifinal6": "chain_low",
             "ifinal7": "chain_low", "ifinal8": "chain_low",
             "ifinal9": "chain_low", "ifinal10": "chain_low", "ifinal11": "chain_low", "ifinal12": "chain_low",
             "ifinal13": "chain_low", "ifinal14": "chain_low", "ifinal15": "chain_low",
             "ifinal16": "chain_low", "ifinal17": "chain_low",
             "ifinal18": "chain_low", "ifinal19": "chain_low", "ifinal20": "chain_low"}
# ichain (development; ichain2 its fresh set, scored once): the low-mode chain car with a real effect on top of its
# wrong damping, so that what the diagnosis can name at 20-50 Hz is measured, not assumed; lags and filters drawn
# long enough to matter
CHAIN_EFFECT_DRAWS: dict[str, Draw] = {
    "torque_lag": lambda r: {"tau_s": _u(r, 0.02, 0.06), "dead_s": _u(r, 0.0, 0.015)},
    "speed_sensor": lambda r: {"window_s": _u(r, 0.03, 0.08), "delay_s": _u(r, 0.0, 0.008)},
    "drag": lambda r: {"coulomb_nm": _u(r, 2.0, 6.0), "viscous_nms": _u(r, 0.005, 0.02)},
}


def _off_by(rng: np.random.Generator, down: tuple[float, float], up: tuple[float, float]) -> float:
    """A scale factor drawn below 1 (range ``down``) or above it (range ``up``), each half the time."""
    return _u(rng, *(down if rng.random() < 0.5 else up))


# Base-parameter errors (with_base's scales), each at least a third of its range away from 1 so that
# a moved parameter is one the data can show: half-shaft stiffness +-12..35 %, damping x0.3-0.66 or
# x1.5-3, body mass -10..-4 % or +6..+25 %, every clearance +-15..40 %.
BASE_DRAWS: dict[str, Callable[[np.random.Generator], float]] = {
    "k_scale": lambda r: _off_by(r, (0.65, 0.88), (1.12, 1.35)),
    "c_scale": lambda r: _off_by(r, (0.3, 0.66), (1.5, 3.0)),
    "mass_scale": lambda r: _off_by(r, (0.90, 0.96), (1.06, 1.25)),
    "gap_scale": lambda r: _off_by(r, (0.60, 0.85), (1.15, 1.40)),
}
BASE_NEAR = 0.2  # base_effect cases: every base scale within 1 +- 20 %
PARAM_OF = {"k_scale": "stiffness", "c_scale": "damping_ratio", "mass_scale": "mass", "gap_scale": "lash"}
CHAIN_ZETA = (0.2, 0.35)  # chain car: heavily damped first mode, the damping scale solved for it
CHAIN_LOW_ZETA = (0.3, 0.55)  # the low-mode chain car (file: 0.19): near the logs' 0.47-0.64
CHAIN_RATES_HZ = (20.0, 25.0, 33.3, 50.0)  # chain car: torque and speed message rates of its logger
MODE_KMH = 30.0  # vehicle speed of the linearisation (the tyre's damping depends on it)
REC = Recording()
NOISE_RPM = float(np.hypot(REC.speed_noise_rpm, 0.5 / np.sqrt(12)))


@dataclass
class Case:
    name: str
    kind: str  # none | single | faint | pair | ool | base | base_effect
    seed: int
    effects: dict[str, dict[str, float]]  # generator effect id -> its parameters
    expected: list[str]  # library ids, ["none"], ["out_of_library"] or ["base_parameters"]
    duration_s: float
    signal_sigma: float = 0.0
    drive_a: str = ""
    drive_b: str = ""
    recorded: dict[str, float] = field(default_factory=dict)
    car: str = "paper"  # lashscope preset of the nominal car (bench.indep.car.CARS)
    base: dict[str, float] = field(default_factory=dict)  # with_base scales: the data sheet's errors
    rate_hz: float = 100.0  # torque and speed message rate
    truth: dict[str, float] = field(default_factory=dict)  # see truth_values

    def moved(self) -> list[str]:
        """lashscope names of the base parameters this case moves on purpose (``base`` kind only)."""
        return sorted(PARAM_OF[k] for k in self.base) if self.kind == "base" else []


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


def truth_car(effects: dict[str, dict[str, float]], base: dict[str, float] | None = None,
              car_name: str = "paper") -> Car:
    """The car a case drives: the named nominal car, its data-sheet errors, then its effects."""
    car = with_base(car_named(car_name), base or {})
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
    return float(np.sqrt(window_ms(t, a, b, drive, shift_s))) / NOISE_RPM


def window_ms(t: np.ndarray, a: np.ndarray, b: np.ndarray, drive: Drive, shift_s: float = SHIFT_S) -> float:
    """Mean square of ``b - a`` (both on times ``t``) over the drive's event windows (0.2 s before to 1 s after each
    reversal, 10 ms apart), each window's level and slope removed, at the best shift of ``b`` within ``shift_s``."""
    grids = [g for r in drive.reversals
             if (g := np.arange(r - 0.2, r + 1.0, 0.01))[0] > shift_s and g[-1] < t[-1] - shift_s]
    # each window's stretch of the drive (the samples around it at every shift), taken once: np.interp reads its
    # whole table on every call, and on the drive's table a 30-minute drive took over half an hour; on a stretch
    # that brackets the window the interpolation is the same, number for number
    spans = [(int(max(np.searchsorted(t, g[0] - 2 * shift_s) - 1, 0)),
              int(min(np.searchsorted(t, g[-1] + 2 * shift_s) + 2, t.size))) for g in grids]
    windows = [(g, t[i:j], b[i:j], np.interp(g, t[i:j], a[i:j])) for g, (i, j) in zip(grids, spans, strict=True)]

    def ms(shift: float) -> float:
        parts = []
        for g, tw, bw, aw in windows:
            d = np.interp(g - shift, tw, bw) - aw
            parts.append(d - np.polyval(np.polyfit(g, d, 1), g))  # a window's level and slope are nuisance
        d = np.concatenate(parts)
        return float(np.mean(d * d))

    return min(ms(float(s)) for s in np.arange(-shift_s, shift_s + 1e-9, 0.0005))


def plan(which: str, quick: bool) -> list[Case]:
    """The cases of a seed set (``dev`` or ``final``); ``quick`` keeps a smaller, fixed subset."""
    if which in IDENTIFY_SETS:
        return plan_identify(which, quick)
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


def _chain_damping(base: dict[str, float], zeta: float, car: str = "chain_drive") -> float:
    """Damping scale that gives the chain car (with ``base``'s other errors) a first mode damped at ``zeta``."""
    lo, hi = 0.0, np.log(20.0)  # zeta rises with the scale over this range
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        got = first_mode(with_base(car_named(car), base | {"c_scale": float(np.exp(mid))}), MODE_KMH)[1]
        lo, hi = (mid, hi) if got < zeta else (lo, mid)
    return float(np.exp(0.5 * (lo + hi)))


def plan_identify(which: str, quick: bool) -> list[Case]:
    """The cases of an identification set (:data:`IDENTIFY_SETS`); ``quick`` keeps a smaller subset.

    Paper car: ``none``; ``base`` with each base parameter moved alone (two each) and 2-4 moved together,
    alternately logged at 100 Hz and 1 kHz; ``base_effect`` (one per library effect). Chain car (slow,
    bursty logger: every other case at 50 Hz, the others at a rate drawn from the slower
    :data:`CHAIN_RATES_HZ`): ``base`` with its damping raised until the first mode's
    damping ratio is a drawn value in :data:`CHAIN_ZETA` (the preset's is ~0.04; :data:`CHAIN_LOW_ZETA` for the
    low-mode car, whose file says 0.19), alone or with other errors, and ``none`` (the file's car). The chain car
    is the set's :data:`CHAIN_CAR`.
    """
    if which in ("ichain", "ichain2", "ichain3"):
        return _plan_chain_effects(which, quick)
    base = SEED_BASE[which]
    dur = 40.0 if quick else 60.0
    knobs = list(BASE_DRAWS)
    chain = CHAIN_CAR[which]
    n_each, n_combo, effects, n_chain, n_chain_none, n_none = \
        (1, 0, LIBRARY[:2], 2, 0, 1) if quick else (2, 6, LIBRARY, 8, 2, 4)
    out: list[Case] = []
    s = base
    for _ in range(n_none):
        out.append(Case(f"none_{s}", "none", s, {}, ["none"], dur, rate_hz=100.0 if s % 2 else 1000.0))
        s += 1
    moves = [[k] for _ in range(n_each) for k in knobs]
    moves += [sorted(str(k) for k in np.random.default_rng(s + i).choice(knobs, size=2 + i % 3, replace=False))
              for i in range(n_combo)]
    for i, ks in enumerate(moves):
        r = np.random.default_rng(s)
        v = {k: BASE_DRAWS[k](r) for k in ks}
        out.append(Case(f"base_{'+'.join(PARAM_OF[k] for k in ks)}_{s}", "base", s, {}, ["base_parameters"], dur,
                        base=v, rate_hz=100.0 if i % 2 == 0 else 1000.0))
        s += 1
    for eff in effects:
        r = np.random.default_rng(s)
        v = {k: _u(r, 1 - BASE_NEAR, 1 + BASE_NEAR) for k in knobs}
        out.append(Case(f"base_effect_{eff}_{s}", "base_effect", s, {eff: EFFECT_DRAWS[eff](r)}, [eff], dur, base=v))
        s += 1
    for i in range(n_chain + n_chain_none):
        r = np.random.default_rng(s)
        rate = CHAIN_RATES_HZ[-1] if i % 2 == 0 else float(r.choice(CHAIN_RATES_HZ[:-1]))  # half at 50 Hz
        if i >= n_chain:
            out.append(Case(f"chain_none_{s}", "none", s, {}, ["none"], dur, car=chain, rate_hz=rate))
        else:
            combined = i % 4 in (1, 2)  # damping alone or with 1-2 other errors, at 50 Hz and slower alike
            others = [str(k) for k in r.choice(knobs[:1] + knobs[2:], size=1 + i // 4 % 2, replace=False)] \
                if combined else []
            v = {k: BASE_DRAWS[k](r) for k in others}
            zeta = _u(r, *(CHAIN_ZETA if chain == "chain_drive" else CHAIN_LOW_ZETA))
            v["c_scale"] = _chain_damping(v, zeta, chain)
            names = "+".join(PARAM_OF[k] for k in sorted(v))
            out.append(Case(f"chain_base_{names}_{s}", "base", s, {}, ["base_parameters"], dur, car=chain,
                            base=v, rate_hz=rate, recorded={"target_zeta": zeta}))
        s += 1
    return out


def _plan_chain_effects(which: str, quick: bool) -> list[Case]:
    """``ichain`` and its fresh ``ichain2`` and ``ichain3``: the low-mode chain car, its damping off as in the chain
    ``base`` cases, with one effect of :data:`CHAIN_EFFECT_DRAWS` (four each; two with ``quick``), every other case
    at 50 Hz, the rest slower."""
    s = SEED_BASE[which]
    chain = CHAIN_CAR[which]
    out: list[Case] = []
    for i in range(2 if quick else 4):
        for eff, draw in CHAIN_EFFECT_DRAWS.items():
            r = np.random.default_rng(s)
            rate = CHAIN_RATES_HZ[-1] if i % 2 == 0 else float(r.choice(CHAIN_RATES_HZ[:-1]))
            v = {"c_scale": _chain_damping({}, _u(r, *CHAIN_LOW_ZETA), chain)}
            out.append(Case(f"chain_effect_{eff}_{s}", "base_effect", s, {eff: draw(r)}, [eff], 40.0 if quick else 60.0,
                            car=chain, base=v, rate_hz=rate))
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


def _band_drive(band: Band, seed: int, duration: float, car: Car | None = None) -> Drive:
    return make_drive(car or nominal_car(), band, np.random.default_rng(seed), duration)


def recording(case: Case) -> Recording:
    """How the case's drives are logged: the paper car at 100 Hz (or 1 kHz), the chain car slow and bursty."""
    if is_chain(case.car):
        return Recording(period_s=1.0 / case.rate_hz, bursts_per_min=20.0, burst_s=(0.1, 0.5))
    return REC if case.rate_hz == 100.0 else Recording(period_s=1.0 / case.rate_hz)


def truth_values(truth: Car, nominal: Car) -> dict[str, float]:
    """The case's base parameters in lashscope's terms, by this generator's equations, with the nominal car's.

    ``stiffness`` N m/rad at the motor, ``freq_hz`` natural frequency and ``zeta`` damping ratio of
    the first mode (linearised at :data:`MODE_KMH`, contacts engaged), ``freq_damped_hz`` its damped
    frequency, ``mass`` kg, ``lash_mrad`` total lash at the rotor; ``*_nominal`` the same for ``nominal``.
    """
    out: dict[str, float] = {}
    for suffix, car in (("", truth), ("_nominal", nominal)):
        fn, zeta, fd = first_mode(car, MODE_KMH)
        out |= {f"stiffness{suffix}": stiffness_at_motor(car), f"freq_hz{suffix}": fn, f"zeta{suffix}": zeta,
                f"freq_damped_hz{suffix}": fd, f"mass{suffix}": car.mass, f"lash_mrad{suffix}": lash_at_motor_mrad(car)}
    return out


def build(case: Case, folder: Path) -> Case:
    """Simulate and record the case's drives A and B into ``folder``; fills paths, signal size and truth."""
    nominal = car_named(case.car)
    band_a, band_b = BANDS[case.car]
    da = _band_drive(band_a, case.seed, case.duration_s, nominal)
    db = _band_drive(band_b, case.seed + 500_000, case.duration_s, nominal)
    if case.kind == "faint":
        _faint(case, da)
    car = truth_car(case.effects, case.base, case.car)
    case.truth = truth_values(car, nominal)
    moved = bool(case.effects or case.base)
    case.signal_sigma = signal_sigma(car, da, _reported(nominal, da)) if moved else 0.0
    rec = recording(case)
    for tag, drive, extra in (("A", da, 0), ("B", db, 500_000)):
        sim = simulate(car, drive.t, drive.torque, drive.speed0_kmh)
        path = folder / f"{case.name}_{tag}.blf"
        info = write_drive(path, car, sim, drive.t, drive.torque, np.random.default_rng(case.seed + 1 + extra), rec,
                           epoch=1.7e9 + case.seed)
        case.recorded[f"offset_{tag}_s"] = info["offset_s"]
        case.recorded[f"reversals_{tag}"] = float(drive.reversals.size)
        setattr(case, f"drive_{tag.lower()}", path.name)
    return case


def generator_version() -> str:
    """Hash of the generator's sources and the data it reads: a cached set is reused only when equal."""
    h = hashlib.sha256()
    for f in [*sorted(Path(__file__).parent.glob("*.py")), PRESET, CHAIN_PRESET, CHAIN_LOW, DBC]:
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
