"""``simulate()``: measured torque in, resolver speed, coupling torques and gap states out."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.budget import check_output, check_steps
from sim.errors import InputSignalError, ParameterError
from sim.inputs import TorqueInput, prepare_input
from sim.linear import step_limit, tangent_stiffness
from sim.model import ChainModel, quasi_static_full
from sim.params import Vehicle
from sim.runner import MAX_EVENTS, RawRun, raise_status, run_from_state
from sim.seat import seat_rail_acceleration
from sim.sensor import delay_sample_quantize
from sim.two_inertia import pack, project, quasi_static, run_two_inertia
from sim.units import RPM_PER_RAD_S
from sim.whatif import WhatIf

F64 = NDArray[np.float64]
RPM = RPM_PER_RAD_S  # rad/s -> rpm
STEP_SAFETY = 0.4  # fraction of the explicit stability limit of the stiffest mode (sim.linear.step_limit)
TWO_INERTIA_SAFETY = 0.3  # fraction of 2/|lambda|max for the paper's two-inertia model


@dataclass(frozen=True)
class SimResult:
    """Simulation output on a uniform grid (``output_dt``).

    Attributes
    ----------
    t : (n,) s
    motor_speed_rpm : (n,) as the resolver reports it (rotor relative to housing, after the
        optional speed-sensor effect)
    rotor_speed_rpm, wheel_speed_rpm, vehicle_speed_kmh : (n,) absolute
    vehicle_accel_ms2 : (n,) m/s^2, the body's longitudinal acceleration (property, from vehicle_speed_kmh)
    seat_rail_accel_ms2 : (n,) m/s^2, what an accelerometer on the seat rail reads: the body's acceleration
        plus the rail's fore-aft motion as the body pitches under the mount reaction and the load transfer,
        and its tilt in gravity (:mod:`sim.seat`); None without a housing on mounts or without ``[body_pitch]``
    airgap_torque_nm : (n,) torque acting on the rotor (after the optional torque lag)
    coupling_torques : name -> (n,) N m at the driven member (gear pairs: the large gear;
        half-shafts: per shaft; ``mount``: housing roll reaction; ``tyre``: all driven tyres at
        the wheel axle, only with tyre slip on)
    gap_open : gap name -> (n,) bool, the gap's dead zone is open (no contact)
    gap_events : (gap, t_open, t_close) at integrator-step resolution; t_close is nan if open at the end
    dt : integrator step (s); input_gaps : spans of missing torque samples
    """

    t: F64
    motor_speed_rpm: F64
    rotor_speed_rpm: F64
    wheel_speed_rpm: F64
    vehicle_speed_kmh: F64
    airgap_torque_nm: F64
    coupling_torques: dict[str, F64]
    gap_open: dict[str, NDArray[np.bool_]]
    gap_events: list[tuple[str, float, float]]
    model: str
    dt: float
    input_gaps: tuple[tuple[float, float], ...] = ()
    body_speeds_rpm: dict[str, F64] = field(default_factory=dict)
    seat_rail_accel_ms2: F64 | None = None

    @property
    def vehicle_accel_ms2(self) -> F64:
        """(n,) m/s^2: the vehicle body's longitudinal acceleration, the derivative of ``vehicle_speed_kmh``
        (second-order central differences on the output grid, gain sin(x)/x with x = 2 pi f output_dt: within
        2 % up to 50 Hz at the 1 ms grid the analysis uses)."""
        if self.t.size < 2:
            return np.zeros(self.t.size)
        return np.asarray(np.gradient(self.vehicle_speed_kmh / 3.6, self.t), dtype=np.float64)


def choose_step(chain: ChainModel, output_dt: float, dt: float | None = None, *, torque_max: float = 0.0,
                omega_vehicle: float = 0.0) -> tuple[float, int]:
    """Integrator step (s) dividing ``output_dt`` and steps per output sample.

    Without ``dt`` the step is ``STEP_SAFETY`` times the stability limit of the stiffest mode of
    the linearised chain (:func:`sim.linear.step_limit`); progressive springs count with their
    tangent stiffness at the deflection ``torque_max`` (N m, largest input torque) can cause,
    the tyre at ``omega_vehicle`` (rad/s). The safety factor was chosen from accuracy scans
    against a tight solve_ivp reference (docs/simulation.md).
    """
    if output_dt <= 0 or not math.isfinite(output_dt):
        raise ParameterError("output_dt", output_dt, "must be a positive number of seconds")
    dt_max = dt if dt is not None else STEP_SAFETY * _step_limit(chain, torque_max, omega_vehicle)
    if dt_max <= 0 or not math.isfinite(dt_max):
        raise ParameterError("dt", dt_max, "must be a positive number of seconds")
    ratio = output_dt / dt_max
    if not math.isfinite(ratio) or ratio > 1e15:  # such a step cannot be taken; check_steps would refuse it anyway
        raise ParameterError("dt", dt_max, f"step too small for output_dt = {output_dt:.6g} s; check stiffness "
                             "and inertia values")
    sub = max(1, math.ceil(ratio - 1e-9))
    return output_dt / sub, sub


def _step_limit(chain: ChainModel, torque_max: float, omega_vehicle: float) -> float:
    """:func:`sim.linear.step_limit` at the tangent stiffness for ``torque_max``, kept on the (read-only) chain per
    the arguments it depends on: every cluster of a fit's pass runs the same chain, and the eigenvalues need
    computing once (the tyre's start speed and, with cubic springs, the largest torque are part of the key)."""
    key = (float(omega_vehicle) if chain.vehicle >= 0 else 0.0, float(torque_max) if np.any(chain.ck3) else 0.0)
    memo: dict[tuple[float, float], float] | None = chain.__dict__.get("_step_memo")
    if memo is None:
        memo = {}
        object.__setattr__(chain, "_step_memo", memo)
    limit = memo.get(key)
    if limit is None:
        limit = step_limit(chain, omega_vehicle, tangent_stiffness(chain, torque_max))
        if len(memo) < 64:
            memo[key] = limit
    return limit


def initial_speed(vehicle: Vehicle, speed0_rpm: float | None) -> float:
    """Initial motor speed (rad/s): given rpm, else the file's vehicle speed through ratio and radius."""
    if speed0_rpm is not None:
        if not math.isfinite(speed0_rpm):
            raise ParameterError("speed0_rpm", speed0_rpm, "must be finite")
        return speed0_rpm / RPM
    return vehicle.body.speed_kmh / 3.6 / vehicle.wheel.radius * vehicle.ratio


def _grid(inp: TorqueInput, output_dt: float) -> tuple[float, int]:
    """Start (s) and number of rows of the output grid; nothing is allocated here."""
    if not isinstance(output_dt, int | float) or not output_dt > 0 or not math.isfinite(output_dt):
        raise ParameterError("output_dt", output_dt, "must be a positive number of seconds")
    t0 = float(inp.t[0])
    span = float(inp.t[-1]) - t0
    n_out = math.floor(span / output_dt + 1e-9) + 1
    if n_out < 2:
        raise InputSignalError(f"input spans {span:.6g} s, shorter than output_dt = {output_dt:.6g} s")
    return t0, n_out


def multibody_row_bytes(n_bodies: int, n_couplings: int) -> int:
    """Bytes per output row of a multibody run: kernel buffers plus the result's own arrays."""
    kernel = 8 * (3 + n_bodies + n_couplings + 1) + n_couplings
    result = 8 * (4 + n_bodies + n_couplings + 1) + n_couplings
    return kernel + result


TWO_INERTIA_ROW_BYTES = 8 * 5 + 8 * 7 + 1


def simulate(
    vehicle: Vehicle, t_s: ArrayLike, torque_nm: ArrayLike, *,
    model: str = "multibody", speed0_rpm: float | None = None,
    interp: str = "hold", dt: float | None = None, output_dt: float = 0.001,
    what_if: WhatIf | None = None,
) -> SimResult:
    """Simulate the driveline under measured motor torque.

    Parameters
    ----------
    vehicle : the driveline description
    t_s, torque_nm : (n,) torque samples at irregular, strictly increasing times (s, N m)
    model : "multibody" (five gaps, housing, segmented half-shafts) or "two_inertia" (eqs. 1-6)
    speed0_rpm : motor speed at ``t_s[0]``; None -> from ``vehicle.body.speed_kmh``
    interp : "hold" or "linear" between torque samples
    dt : integrator step (s); None -> chosen from the highest mode of the linearised system
    output_dt : output grid spacing (s); the step divides it exactly
    what_if : optional changes applied to vehicle and torque first

    Raises
    ------
    InputSignalError, ParameterError, InstabilityError
    """
    inp = prepare_input(t_s, torque_nm, interp)
    if model not in ("multibody", "two_inertia"):
        raise ParameterError("model", model, "must be 'multibody' or 'two_inertia'")
    t0, n_out = _grid(inp, output_dt)
    span = float(inp.t[-1]) - t0
    if what_if is not None:
        vehicle = what_if.apply_vehicle(vehicle)
    chain = vehicle.compiled if model == "multibody" else None
    # refuse before any array of the run's length exists (what-if resampling included)
    check_output(span, output_dt, n_out, TWO_INERTIA_ROW_BYTES if chain is None
                 else multibody_row_bytes(chain.n_bodies, chain.n_couplings))
    if what_if is not None:
        t_new, q_new, resampled = what_if.apply_torque(inp.t, inp.torque)
        inp = TorqueInput(t_new, q_new, inp.linear or resampled, inp.gaps)
    inp = airgap_input(vehicle, inp)
    w0 = initial_speed(vehicle, speed0_rpm)
    if chain is None:
        return _simulate_two_inertia(vehicle, inp, w0, dt, output_dt)
    step, raw, t, speed = _run_multibody(vehicle, inp, t0, n_out, span, w0, dt, output_dt, events=True)
    torques = {name: raw.tau[:, j] * chain.creport[j] for j, name in enumerate(chain.coupling_names)}
    if chain.vehicle >= 0:
        torques["tyre"] = raw.tyre
    gaps = vehicle.gap_names
    gap_of = {j: g for g, j in chain.gap_coupling.items()}
    gap_open = {g: raw.is_open[:, chain.gap_coupling[g]].copy() for g in gaps}
    events = _pair_events([(gap_of[j], tk, kind) for j, tk, kind in raw.events if j in gap_of],
                          {g: bool(raw.is_open[0, chain.gap_coupling[g]]) for g in gaps}, t0)
    w_wheel = raw.omega[:, chain.wheel]
    w_vehicle = raw.omega[:, chain.vehicle] if chain.vehicle >= 0 else w_wheel
    res = SimResult(
        t=t, motor_speed_rpm=speed, rotor_speed_rpm=raw.omega[:, chain.rotor] * RPM,
        wheel_speed_rpm=w_wheel * RPM, vehicle_speed_kmh=w_vehicle * vehicle.wheel.radius * 3.6,
        airgap_torque_nm=raw.torque, coupling_torques=torques, gap_open=gap_open, gap_events=events,
        model="multibody", dt=step, input_gaps=inp.gaps,
        body_speeds_rpm={name: raw.omega[:, b] * RPM for b, name in enumerate(chain.body_names)},
    )
    if chain.housing >= 0 and vehicle.body_pitch.enabled:  # the mount is the last coupling (sim.model)
        seat = seat_rail_acceleration(vehicle, chain, output_dt, res.vehicle_accel_ms2, raw.tau[:, -1])
        res = replace(res, seat_rail_accel_ms2=seat)
    return res


def airgap_input(vehicle: Vehicle, inp: TorqueInput) -> TorqueInput:
    """The logged torque as the air-gap torque: times the motor's ``torque_gain`` (1: unchanged)."""
    g = vehicle.motor.torque_gain
    return inp if g == 1.0 else replace(inp, torque=inp.torque * g)


def _run_multibody(vehicle: Vehicle, inp: TorqueInput, t0: float, n_out: int, span: float, w0: float,
                   dt: float | None, output_dt: float, *, events: bool,
                   states: bool = True) -> tuple[float, RawRun, F64, F64]:
    """The multibody run of the vehicle's compiled chain from the quasi-static start: step, kernel output, output
    grid and the resolver speed as reported (after the speed sensor)."""
    chain = vehicle.compiled
    theta0, omega0, tyre0 = quasi_static_full(chain, float(inp.torque[0]), w0)
    step, sub = choose_step(chain, output_dt, dt, torque_max=float(np.max(np.abs(inp.torque))),
                            omega_vehicle=float(omega0[chain.vehicle]) if chain.vehicle >= 0 else 0.0)
    check_steps(span, step, (n_out - 1) * sub, auto=dt is None)
    eff = vehicle.effects
    raw = run_from_state(chain, inp.t, inp.torque, inp.linear, t0, step, sub, n_out, theta0, omega0, tyre0,
                         lag=(eff.torque_lag.delay_s, eff.torque_lag.tau_s), sensor_tau=eff.speed_sensor.tau_s,
                         speed_limit=20.0 * abs(w0) + 5000.0, events=events, states=states)
    t = np.asarray(t0 + np.arange(n_out) * output_dt, dtype=np.float64)
    sens = eff.speed_sensor
    speed = delay_sample_quantize(t, raw.sensor * RPM, sens.delay_s, sens.sample_s, sens.resolution_rpm)
    return step, raw, t, speed


@dataclass(frozen=True)
class SpeedRun:
    """What a model fit reads of a run: the resolver speed as :class:`SimResult` reports it and every gap's state.

    Attributes
    ----------
    t, motor_speed_rpm : (n,) s and rpm, the same numbers as ``SimResult.t`` / ``SimResult.motor_speed_rpm``
    gap_open : gap name -> (n,) bool, as ``SimResult.gap_open``
    """

    t: F64
    motor_speed_rpm: F64
    gap_open: dict[str, NDArray[np.bool_]]


def simulate_speed(
    vehicle: Vehicle, t_s: ArrayLike, torque_nm: ArrayLike, *, speed0_rpm: float | None = None,
    interp: str = "hold", output_dt: float = 0.001, gaps: bool = True,
) -> SpeedRun:
    """:func:`simulate` (multibody model, automatic step, no what-if) reduced to the resolver speed and the gaps'
    states: the same run and the same numbers, without the body speeds, coupling torques, gap-event list and
    seat-rail acceleration a fit never reads (their assembly costs a tenth of a short run). ``gaps=False``: not
    the gaps' states either (``gap_open`` empty); the kernel then writes only the speed rows, about 10 % less
    work per step at the paper vehicle's 15 steps per output row.

    Raises
    ------
    InputSignalError, ParameterError, InstabilityError : as :func:`simulate`
    """
    inp = airgap_input(vehicle, prepare_input(t_s, torque_nm, interp))
    t0, n_out = _grid(inp, output_dt)
    span = float(inp.t[-1]) - t0
    chain = vehicle.compiled
    check_output(span, output_dt, n_out, multibody_row_bytes(chain.n_bodies, chain.n_couplings))
    w0 = initial_speed(vehicle, speed0_rpm)
    _, raw, t, speed = _run_multibody(vehicle, inp, t0, n_out, span, w0, None, output_dt, events=False,
                                      states=gaps)
    return SpeedRun(t, speed, {g: raw.is_open[:, chain.gap_coupling[g]] for g in vehicle.gap_names} if gaps else {})


def _pair_events(
    raw: list[tuple[str, float, int]], open0: dict[str, bool], t0: float
) -> list[tuple[str, float, float]]:
    """(gap, t, 1=open/0=close) transitions -> (gap, t_open, t_close) intervals, sorted by t_open."""
    pending = {g: t0 for g, o in open0.items() if o}
    out: list[tuple[str, float, float]] = []
    for gap, t, kind in raw:
        if kind == 1:
            pending[gap] = t
        elif gap in pending:
            out.append((gap, pending.pop(gap), t))
    out.extend((g, t, math.nan) for g, t in pending.items())
    return sorted(out, key=lambda e: e[1])


def _simulate_two_inertia(vehicle: Vehicle, inp: TorqueInput, w0: float, dt: float | None,
                          output_dt: float) -> SimResult:
    p = project(vehicle)
    arr, road = pack(p)
    dt_max = dt if dt is not None else TWO_INERTIA_SAFETY * 2.0 / p.max_rate()
    if not dt_max > 0 or not math.isfinite(dt_max):
        raise ParameterError("dt", dt_max, "must be a positive number of seconds")
    sub = max(1, math.ceil(output_dt / dt_max - 1e-9))
    step = output_dt / sub
    t0, n_out = _grid(inp, output_dt)
    check_steps(float(inp.t[-1]) - t0, step, (n_out - 1) * sub, auto=dt is None)
    state0 = quasi_static(p, float(inp.torque[0]), w0)
    out = np.zeros((n_out, 5))
    ev_t = np.zeros(MAX_EVENTS)
    ev_kind = np.zeros(MAX_EVENTS, dtype=np.int64)
    status, t_fail, n_ev = run_two_inertia(arr, road, inp.t, inp.torque, inp.linear, t0, step, n_out, sub, state0,
                                           20.0 * abs(w0) + 5000.0, out, ev_t, ev_kind)
    raise_status(status, t_fail, step)
    t = np.asarray(t0 + np.arange(n_out) * output_dt, dtype=np.float64)
    is_open = out[:, 3] > 0.5
    events = _pair_events([("lumped", float(ev_t[k]), int(ev_kind[k])) for k in range(n_ev)],
                          {"lumped": bool(is_open[0])}, t0)
    return SimResult(
        t=t, motor_speed_rpm=out[:, 0] * RPM, rotor_speed_rpm=out[:, 0] * RPM, wheel_speed_rpm=out[:, 1] * RPM,
        vehicle_speed_kmh=out[:, 1] * vehicle.wheel.radius * 3.6, airgap_torque_nm=out[:, 4],
        coupling_torques={"halfshaft": out[:, 2]}, gap_open={"lumped": is_open}, gap_events=events,
        model="two_inertia", dt=step, input_gaps=inp.gaps,
    )
