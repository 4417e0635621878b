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
plain field change (see :func:`with_effect`), so an effect drawn for a case is a ``Car``; so is a
base-parameter error, a wrong data sheet (see :func:`with_base`).

The second car, :func:`chain_car`, is ``sim/presets/chain_drive.toml`` read as data and mapped onto
the same equations: the spline stage is the spline, the chain (11/42) is the first gear pair (the
pair's reversed rotation is undone by the second one, and with the housing held it carries no
reaction), the second pair is a 1:1 pair that is very stiff and lash-free (the driven sprocket
and the differential case are one body, its inertia split between the pair's two sides), and "no
housing" is a housing on very stiff, well damped mounts. The preset's rotor and hub-bearing drags
are lumped as a rotor drag (the wheel part referred through the ratio).
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass
from pathlib import Path

PRESETS = Path(__file__).resolve().parents[2] / "sim" / "presets"
PRESET = PRESETS / "paper.toml"
CHAIN_PRESET = PRESETS / "chain_drive.toml"
CHAIN_LOW = Path(__file__).with_name("chain_low.toml")  # the chain car with a low, heavily damped first mode
CARS = ("paper", "chain_drive", "chain_low")  # the generator's nominal cars (see vehicle_source)
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


def chain_car(preset: Path = CHAIN_PRESET) -> Car:
    """The chain_drive preset's car in this generator's terms (mapping in the module docstring)."""
    p = tomllib.loads(preset.read_text(encoding="utf-8"))
    st = {s["kind"]: s for s in p["stage"]}
    rotor, spline, chain, diff, hs, wheel = (st[k] for k in ("rotor", "spline", "chain", "differential",
                                                              "halfshaft", "wheel"))
    z = chain["teeth"]
    i1 = z[1] / z[0]
    lash = chain["lash_rad"]
    k_chain = chain["stiffness"]
    return Car(
        j_rotor=rotor["rotor_inertia"], j_input=spline["inertia"],
        j_inter=chain["inertia"] / 2, j_case=chain["inertia"] / 2, j_side=diff["inertia"] / 2, j_pinion=0.0005,
        i1=i1, i2=1.0,
        k_spline=spline["stiffness"], c_spline=spline["damping"],
        k_mesh1=k_chain, c_mesh1=chain["damping"],
        # the joint between sprocket and case: 20x the chain, damped at ~0.3 of its own critical damping
        k_mesh2=20 * k_chain, c_mesh2=0.6 * (20 * k_chain * chain["inertia"] / 4) ** 0.5,
        k_diff=diff["stiffness"] / 2, c_diff=diff["damping"] / 2,  # preset: both side gears together
        gap_spline=spline["lash_rad"], gap_mesh1=lash["nominal"] if isinstance(lash, dict) else lash,
        gap_mesh2=0.0, gap_diff=diff["lash_rad"], gap_shaft=hs["lash_rad"],
        k_shaft_l=hs["stiffness"], k_shaft_r=hs["stiffness"], c_shaft_l=hs["damping"], c_shaft_r=hs["damping"],
        j_shaft=hs["inertia"], j_wheel=wheel["inertia"], radius=wheel["radius"],
        mass=float(p["body"]["mass"]), crr=p["body"]["rolling_resistance"], cda=p["body"]["drag_area"],
        rho=p["body"]["air_density"],
        tyre_c=2.0e7, tyre_sigma=0.05, tyre_mu=1.6,
        # no housing: a 1 kg m^2 body on mounts 1000x the driveline's stiffness at the rotor, near critically damped
        j_housing=1.0, k_mount=1.0e7, c_mount=5.0e3,
        drag_coulomb=rotor["coulomb_drag"] + 2 * wheel["coulomb_drag"] / i1,
        drag_viscous=rotor["viscous_damping"] + 2 * wheel["viscous_drag"] / i1**2,
    )


def car_named(name: str) -> Car:
    """The nominal car of a lashscope preset name (:data:`CARS`)."""
    if name == "paper":
        return nominal_car()
    if name == "chain_drive":
        return chain_car()
    if name == "chain_low":
        return chain_car(CHAIN_LOW)
    raise ValueError(f"no generator car for preset {name!r}")


def vehicle_source(name: str) -> str:
    """What lashscope loads as the vehicle file of the nominal car ``name`` (``sim.load_vehicle``): a preset
    name, or the path of the benchmark's own file."""
    if name not in CARS:
        raise ValueError(f"no generator car {name!r}; known: {', '.join(CARS)}")
    return str(CHAIN_LOW) if name == "chain_low" else name


def is_chain(name: str) -> bool:
    """Whether the nominal car ``name`` is one of the chain cars (slow, bursty logger)."""
    return name.startswith("chain")


def ratio(car: Car) -> float:
    """Overall reduction, motor to wheel."""
    return car.i1 * car.i2


def tyre_load(car: Car) -> float:
    """Vertical load on one driven tyre, N (55 % of the weight on the driven axle)."""
    return 0.55 * car.mass * G / 2


def with_base(car: Car, v: dict[str, float]) -> Car:
    """``car`` with a wrong data sheet undone: the truth differs from the nominal car by ``v``'s scales.

    ``k_scale`` both half-shafts' stiffness, ``c_scale`` every shaft and mesh damping (spline, both
    pairs, differential, half-shafts; not the mounts), ``mass_scale`` the body mass, ``gap_scale``
    every clearance. Missing keys leave a parameter as it is.
    """
    k, c, gap = v.get("k_scale", 1.0), v.get("c_scale", 1.0), v.get("gap_scale", 1.0)
    return car.with_(
        k_shaft_l=car.k_shaft_l * k, k_shaft_r=car.k_shaft_r * k,
        c_spline=car.c_spline * c, c_mesh1=car.c_mesh1 * c, c_mesh2=car.c_mesh2 * c, c_diff=car.c_diff * c,
        c_shaft_l=car.c_shaft_l * c, c_shaft_r=car.c_shaft_r * c,
        mass=car.mass * v.get("mass_scale", 1.0),
        gap_spline=car.gap_spline * gap, gap_mesh1=car.gap_mesh1 * gap, gap_mesh2=car.gap_mesh2 * gap,
        gap_diff=car.gap_diff * gap, gap_shaft=car.gap_shaft * gap)


def stiffness_at_motor(car: Car) -> float:
    """Effective torsional stiffness of the driveline referred to the motor (N m/rad).

    Every compliance divided by its squared ratio from the motor, in series; each side's differential
    contact and half-shaft in series, both sides in parallel. The housing mounts are not part of it
    (lashscope models them as their own element).
    """
    i1, ig = car.i1, ratio(car)
    side = 1 / (1 / car.k_diff + 1 / car.k_shaft_l) + 1 / (1 / car.k_diff + 1 / car.k_shaft_r)
    return 1 / (1 / car.k_spline + i1**2 / car.k_mesh1 + ig**2 / car.k_mesh2 + ig**2 / side)


def lash_at_motor_mrad(car: Car) -> float:
    """Total lash seen at the rotor (mrad): each clearance times the motor's turns per its shaft's turn.

    The two side-gear contacts and the two half-shafts are in parallel: each side's clearance counts once.
    """
    i1, ig = car.i1, ratio(car)
    return 1e3 * (car.gap_spline + i1 * car.gap_mesh1 + ig * (car.gap_mesh2 + car.gap_diff + car.gap_shaft))


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
