"""The generator's car: paper-preset numbers read as data, plus the truth knobs of every effect.

``Car`` holds SI values (kg m^2, N m/rad, N m s/rad, rad, kg, m, s). Fields the preset does not
have are the generator's own nominal choices: a differential-pinion inertia, a relaxation-length
tyre with force saturation, a 2 ms moving-average speed sensor. The nominal tyre (20 MN per unit
slip, 0.05 m relaxation length) is stiffer than a real one on purpose: the nominal car must lie in
the diagnosed model's family (the real tyre is the ``tyre_slip`` case, 25-80 kN). At low slip speed
the tyre is a damper of ``R^2 C / V`` between wheel and body; at 2 MN (the first choice) that damper
still moved the shuffle frequency of a clean tip-in by enough to leave 3 rpm RMS (5x the noise) against
the paper model, i.e. a faint tyre effect on every "no effect" drive; at 20 MN the difference is
0.8 rpm, set by the other formulation differences (``tests/bench/test_indep_generator.py`` checks it). The preset's
differential stiffness and damping are for both side gears together; each side-gear contact
gets half. Each effect is a
plain field change (see :func:`with_effect`), so an effect drawn for a case is a ``Car``.
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass
from pathlib import Path

PRESET = Path(__file__).resolve().parents[2] / "sim" / "presets" / "paper.toml"
G = 9.81


@dataclass(frozen=True)
class Car:
    """Everything the dynamics and the sensor need (SI units)."""

    # motor and reducer
    j_rotor: float
    j_input: float
    j_inter: float
    j_case: float
    j_side: float  # one side gear
    j_pinion: float  # differential pinions, in side-gear angle
    i1: float  # 79/27
    i2: float  # 77/20
    k_spline: float
    c_spline: float
    k_mesh1: float  # 79-gear angle
    c_mesh1: float
    k_mesh2: float  # 77-gear angle
    c_mesh2: float
    k_diff: float  # per side gear
    c_diff: float
    # total clearances (rad, own shaft angle)
    gap_spline: float
    gap_mesh1: float
    gap_mesh2: float
    gap_diff: float
    gap_shaft: float
    # half-shafts (left, right) and wheels
    k_shaft_l: float
    k_shaft_r: float
    c_shaft_l: float
    c_shaft_r: float
    j_shaft: float
    j_wheel: float
    radius: float
    # body and road
    mass: float
    crr: float
    cda: float
    rho: float
    # tyre: F = F_max tanh(C kappa / F_max), sigma kappa' = (omega R - V) - |V| kappa
    tyre_c: float  # N per unit slip, per tyre
    tyre_sigma: float  # relaxation length, m
    tyre_mu: float
    # housing on mounts
    j_housing: float
    k_mount: float
    c_mount: float
    # effects (all off at the nominal values below)
    drag_coulomb: float = 0.0  # N m at the rotor
    drag_viscous: float = 0.0  # N m s/rad at the rotor
    shaft_hardening: float = 0.0  # relative tangent-stiffness rise at 0.1 rad of shaft twist
    mount_hardening: float = 0.0  # relative tangent-stiffness rise at 0.02 rad of housing roll
    lag_tau: float = 0.0  # s, first-order actuator lag of the air-gap torque
    lag_dead: float = 0.0  # s, actuator dead time
    sensor_window: float = 0.002  # s, moving-average window of the inverter's speed estimate
    sensor_delay: float = 0.0  # s, reporting delay of the speed
    ripple_nm: float = 0.0  # N m, torque ripple amplitude at the first motor order

    def with_(self, **changes: float) -> Car:
        return dataclasses.replace(self, **changes)


def nominal_car(preset: Path = PRESET) -> Car:
    """The paper preset's car in this generator's terms."""
    p = tomllib.loads(preset.read_text(encoding="utf-8"))
    red, hs, gaps = p["reducer"], p["halfshaft"], p["gaps"]
    z = red["teeth"]
    mass = float(p["body"]["mass"])
    return Car(
        j_rotor=p["motor"]["rotor_inertia"], j_input=red["input_shaft_inertia"],
        j_inter=red["intermediate_inertia"], j_case=red["differential_inertia"],
        j_side=red["side_gears_inertia"] / 2, j_pinion=0.002,
        i1=z[1] / z[0], i2=z[3] / z[2],
        k_spline=red["spline_stiffness"], c_spline=red["spline_damping"],
        k_mesh1=red["mesh1_stiffness"], c_mesh1=red["mesh1_damping"],
        k_mesh2=red["mesh2_stiffness"], c_mesh2=red["mesh2_damping"],
        k_diff=red["diff_stiffness"] / 2, c_diff=red["diff_damping"] / 2,  # preset: both side gears together
        gap_spline=gaps["spline"]["nominal"], gap_mesh1=gaps["mesh1"]["nominal"],
        gap_mesh2=gaps["mesh2"]["nominal"], gap_diff=gaps["differential"]["nominal"],
        gap_shaft=gaps["halfshaft"]["nominal"],
        k_shaft_l=hs["stiffness"], k_shaft_r=hs["stiffness"], c_shaft_l=hs["damping"], c_shaft_r=hs["damping"],
        j_shaft=hs["inertia"], j_wheel=p["wheel"]["inertia"], radius=p["wheel"]["radius"],
        mass=mass, crr=p["body"]["rolling_resistance"], cda=p["body"]["drag_area"], rho=p["body"]["air_density"],
        tyre_c=2.0e7, tyre_sigma=0.05, tyre_mu=1.1,
        j_housing=p["housing"]["inertia"], k_mount=p["housing"]["mount_stiffness"],
        c_mount=p["housing"]["mount_damping"],
    )


def ratio(car: Car) -> float:
    """Overall reduction, motor to wheel."""
    return car.i1 * car.i2


def tyre_load(car: Car) -> float:
    """Vertical load on one driven tyre, N (55 % of the weight on the driven axle)."""
    return 0.55 * car.mass * G / 2


# Effect knobs: library id -> parameter -> (car field change). Values are the generator's own
# parameters, documented with their ranges in cases.py.
def with_effect(car: Car, effect: str, v: dict[str, float]) -> Car:
    """``car`` with one effect's truth parameters applied (see cases.EFFECT_DRAWS for meanings)."""
    if effect == "backlash":
        return car.with_(gap_diff=car.gap_diff * v["diff_scale"], gap_shaft=car.gap_shaft * v["shaft_scale"],
                         gap_mesh2=car.gap_mesh2 * v["mesh_scale"])
    if effect == "housing_mount":
        return car.with_(k_mount=car.k_mount * v["k_scale"], c_mount=car.c_mount * v["c_scale"])
    if effect == "torque_lag":
        return car.with_(lag_tau=v["tau_s"], lag_dead=v["dead_s"])
    if effect == "speed_sensor":
        return car.with_(sensor_window=v["window_s"], sensor_delay=v["delay_s"])
    if effect == "drag":
        return car.with_(drag_coulomb=v["coulomb_nm"], drag_viscous=v["viscous_nms"])
    if effect == "progressive_stiffness":
        return car.with_(shaft_hardening=v["shaft_rel"], mount_hardening=v["mount_rel"])
    if effect == "tyre_slip":
        return car.with_(tyre_c=v["c_n"], tyre_sigma=v["sigma_m"])
    if effect == "unequal_shafts":
        return car.with_(k_shaft_l=car.k_shaft_l * v["left_scale"], k_shaft_r=car.k_shaft_r * v["right_scale"],
                         c_shaft_l=car.c_shaft_l * v["left_scale"], c_shaft_r=car.c_shaft_r * v["right_scale"])
    if effect == "torque_ripple":
        return car.with_(ripple_nm=v["amplitude_nm"])
    raise ValueError(f"unknown generator effect {effect!r}")
