"""The identifiable base parameters of a driveline, and the physical figures they are reported as.

A vehicle file states every stiffness, damping, inertia and gap of the chain; a CAN log of motor
torque and motor speed pins down far fewer numbers. What the tip-in and tip-out windows see is:

``stiffness``
    the series torsional stiffness of the chain referred to the rotor (it sets the first mode with
    the rotor inertia); fitted as one scale (log2) on every stage's stiffness, reported as the effective
    stiffness at the motor (N m/rad) -- a half-shaft 0.7x softer than its data sheet and a chain
    0.7x softer give the same log;
``damping``
    the modal damping of that mode; fitted as a scale (log2, the data sheets are off by factors)
    on every stage's damping, reported as the first mode's damping ratio;
``mass``
    the vehicle mass (the wheel-side inertia: the slope of the speed under a torque step);
``lash``
    the total lash seen from the rotor (the free-rotor traverse time); fitted as one scale on every
    gap, reported in mrad at the rotor. Where the lash sits along the chain is the ``backlash``
    effect's question, not the base model's.

Torque gain and road load are the diagnosis' nuisance parameters and are fitted with these (see
:mod:`app.analysis.diagnosis.calibrate`). Each base parameter is expressed as an
:class:`~sim.effects.base.Effect` with one parameter, so the diagnosis' bounded joint fit serves
identification unchanged; ``off`` is the vehicle file's value.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from sim import Vehicle
from sim.effects.base import Effect, ParamSpec, Values
from sim.linear import coupling_rows, state_matrix

BASE_NAMES = ("stiffness", "damping", "mass", "lash")
MIN_MODE_HZ = 0.5  # lowest torsional mode looked for


def stage_paths(vehicle: Vehicle, attr: str) -> tuple[str, ...]:
    """Dotted fields of every stage's ``attr`` (``stiffness`` or ``damping``) in the file's own layout."""
    return tuple(vehicle.field_of(s.name, attr) for s in vehicle.chain
                 if s.kind not in ("rotor", "wheel") and s.has_coupling and float(getattr(s, attr)) > 0.0)


def _scaled(paths: Callable[[Vehicle], tuple[str, ...]], key: str, log2: bool = False
            ) -> Callable[[Vehicle, Values], dict[str, float]]:
    def change(vehicle: Vehicle, v: Values) -> dict[str, float]:
        f = 2.0 ** v[key] if log2 else v[key]
        return {p: float(vehicle.get(p)) * f for p in paths(vehicle)}
    return change


def _gaps(vehicle: Vehicle) -> tuple[str, ...]:
    return tuple(f"gaps.{g}" for g in vehicle.gap_names if vehicle.gap(g).nominal > 0.0)


STIFFNESS = Effect(
    id="base_stiffness", title="Torsional stiffness of the chain off its data sheet",
    params=(ParamSpec("log2_scale", "-", -3.3, 1.6, 0.0, "every stage's stiffness x 2^value (0.1x to 3x)"),),
    vehicle_change=_scaled(lambda v: stage_paths(v, "stiffness"), "log2_scale", log2=True),
)
DAMPING = Effect(
    id="base_damping", title="Damping of the chain off its data sheet",
    params=(ParamSpec("log2_scale", "-", -3.0, 3.0, 0.0, "every stage's damping x 2^value"),),
    vehicle_change=_scaled(lambda v: stage_paths(v, "damping"), "log2_scale", log2=True),
)
MASS = Effect(
    id="base_mass", title="Vehicle mass off the file's",
    params=(ParamSpec("scale", "-", 0.6, 1.7, 1.0, "body mass x the file's"),),
    vehicle_change=_scaled(lambda v: ("body.mass",), "scale"),
)
LASH = Effect(
    id="base_lash", title="Total lash off the file's",
    params=(ParamSpec("scale", "-", 0.3, 2.5, 1.0, "every gap x the file's nominal"),),
    vehicle_change=_scaled(_gaps, "scale"),
)
BASE_EFFECTS: dict[str, Effect] = {"stiffness": STIFFNESS, "damping": DAMPING, "mass": MASS, "lash": LASH}


LOG2 = ("stiffness", "damping")  # fitted as log2 of the scale: data sheets are off by factors, steps are relative


def ratio_of(name: str, value: float) -> float:
    """The fitted parameter as a ratio to the file's value (stiffness and damping are fitted as log2)."""
    return float(2.0 ** value) if name in LOG2 else float(value)


def value_of(name: str, ratio: float) -> float:
    """The fitted parameter's value for a ratio to the file's (inverse of :func:`ratio_of`)."""
    return float(np.log2(ratio)) if name in LOG2 else float(ratio)


def with_base(vehicle: Vehicle, ratios: Mapping[str, float]) -> Vehicle:
    """``vehicle`` with base parameters scaled by ``ratios`` (name -> ratio to the file's value), one rebuild."""
    changes: dict[str, float] = {}
    for name, r in ratios.items():
        eff = BASE_EFFECTS[name]
        key = eff.params[0].name
        changes.update(eff.vehicle_change(vehicle, {key: value_of(name, r)}) if eff.vehicle_change is not None else {})
    return vehicle.with_changes(changes)


@dataclass(frozen=True)
class Physical:
    """What the base parameters mean on a vehicle, in engineering units."""

    stiffness_nm_rad: float  # series torsional stiffness referred to the rotor, wheels held
    freq_hz: float  # first torsional mode (damped), rotor free, vehicle free
    damping_ratio: float  # of that mode
    mass_kg: float
    lash_mrad: float  # total lash referred to the rotor

    def value(self, name: str) -> float:
        return {"stiffness": self.stiffness_nm_rad, "damping": self.damping_ratio, "mass": self.mass_kg,
                "lash": self.lash_mrad}[name]


UNITS = {"stiffness": "N m/rad", "damping": "-", "mass": "kg", "lash": "mrad"}
LABELS = {"stiffness": "torsional stiffness at the motor", "damping": "first-mode damping ratio",
          "mass": "vehicle mass", "lash": "total lash at the motor"}


def effective_stiffness(vehicle: Vehicle) -> float:
    """Torque at the rotor per radian of rotor twist with the wheels (and the housing) held (N m/rad)."""
    m = vehicle.compiled
    g = coupling_rows(m)  # the housing's column drops out with the housing held
    k = g.T @ (m.ck[:, None] * g)
    held = {m.wheel, m.wheel2, m.vehicle, m.housing} - {-1}
    free = [b for b in range(m.n_bodies) if b not in held]
    e = np.zeros(len(free))
    e[free.index(m.rotor)] = 1.0
    theta = np.linalg.solve(k[np.ix_(free, free)], e)
    return float(1.0 / theta[free.index(m.rotor)])


def first_mode(vehicle: Vehicle) -> tuple[float, float]:
    """(frequency Hz, damping ratio) of the lowest oscillating mode with the rotor taking part, gaps closed."""
    m = vehicle.compiled
    omega_v = vehicle.body.speed_kmh / 3.6 / vehicle.wheel.radius
    lam, vec = np.linalg.eig(state_matrix(m, omega_v))
    nb = m.n_bodies
    best: tuple[float, float] | None = None
    for k in np.argsort(np.abs(lam)):
        s = lam[k]
        if s.imag <= 2 * np.pi * MIN_MODE_HZ:  # the rigid-body and tyre roots, and their numerical ghosts
            continue
        shape = np.abs(vec[nb:2 * nb, k])  # velocity participation
        if shape[m.rotor] < 0.05 * float(shape.max()):
            continue
        wn = abs(s)
        best = (float(wn / (2 * np.pi)), float(-s.real / wn))
        break
    if best is None:
        return float("nan"), float("nan")
    return best


def lash_mrad(vehicle: Vehicle) -> float:
    """Total backlash referred to the rotor (mrad): each gap times the rotor's turns per its shaft's turn."""
    m = vehicle.compiled
    gaps = m.chalf > 0
    return float(1e3 * np.sum(2.0 * m.chalf[gaps] / m.speed_ratio[m.ca[gaps]]))


def physical(vehicle: Vehicle) -> Physical:
    f, z = first_mode(vehicle)
    return Physical(effective_stiffness(vehicle), f, z, float(vehicle.body.mass), lash_mrad(vehicle))
