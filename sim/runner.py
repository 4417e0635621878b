"""One call of the compiled chain kernel from a given state: the layer between ``simulate`` and numba.

:func:`run_from_state` owns the kernel's argument list and output buffers, so callers (the
simulator, tests that start from a mode shape) never depend on the kernel signature.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.errors import InstabilityError
from sim.integrate import STATUS_NONFINITE, STATUS_OK, is_kernel_layout, run_chain
from sim.model import ChainModel
from sim.unrolled import needs_cubic, serial_kernel

F64 = NDArray[np.float64]
MAX_EVENTS = 20000


@dataclass(frozen=True)
class RawRun:
    """Kernel output on the output grid (row ``i`` at ``t0 + i * sub * dt``), SI units.

    resolver : (n,) rad/s, rotor relative to housing; sensor : (n,) after the speed filter
    torque : (n,) N m air-gap torque; omega : (n, nb) rad/s body speeds
    tau : (n, nc) N m coupling torques in each coupling's ``a`` angle; tyre : (n,) N m (zeros if off)
    is_open : (n, nc) dead zone open; events : (coupling, t, 1 = open / 0 = close)
    """

    resolver: F64
    sensor: F64
    torque: F64
    omega: F64
    tau: F64
    tyre: F64
    is_open: NDArray[np.bool_]
    events: list[tuple[int, float, int]]


def run_from_state(
    chain: ChainModel, t_in: F64, q_in: F64, linear: bool, t0: float, step: float, sub: int, n_out: int,
    theta0: F64, omega0: F64, tyre0: float = 0.0, *, lag: tuple[float, float] = (0.0, 0.0),
    sensor_tau: float = 0.0, speed_limit: float = math.inf, events: bool = True, states: bool = True,
) -> RawRun:
    """Integrate ``chain`` from ``(theta0, omega0, tyre0)`` at ``t0`` with step ``step``, ``sub`` steps per row.

    ``events=False`` leaves ``RawRun.events`` empty (the kernel still logs them when ``states`` is on; they are not
    converted); ``states=False`` leaves ``omega``, ``tau``, ``tyre`` and ``is_open`` with no rows (the kernel does
    not write them; the resolver, sensor and torque rows are the same numbers). Both off: the kernel's speed-only
    loop (no gap states kept at all), again the same numbers.

    Raises
    ------
    InstabilityError : a state became non-finite or a speed exceeded ``speed_limit`` (rad/s)
    """
    if not is_kernel_layout(chain.ca, chain.cb, chain.housing):
        raise ValueError("the kernel needs the layout of sim.model.build_chain (mount last)")
    nb, nc = chain.n_bodies, chain.n_couplings
    tyre_on = chain.vehicle >= 0
    out_res, out_sens, out_torque = np.zeros(n_out), np.zeros(n_out), np.zeros(n_out)
    rows = n_out if states else 0
    out_omega, out_tau = np.zeros((rows, nb)), np.zeros((rows, nc + int(tyre_on)))
    out_open = np.zeros((rows, nc), dtype=np.bool_)
    n_ev = MAX_EVENTS if events or states else 0  # neither read: the kernel keeps no gap states (same speeds)
    ev_gap = np.zeros(n_ev, dtype=np.int64)
    ev_t = np.zeros(n_ev)
    ev_kind = np.zeros(n_ev, dtype=np.int64)
    kernel = None
    if not (events or states) and is_serial(chain):  # the fits' runs: the loop written out for this layout
        kernel = serial_kernel(nb, chain.n_couplings - (1 if chain.housing >= 0 else 0), chain.rotor, chain.wheel,
                               chain.housing, chain.vehicle, needs_cubic(chain.ck, chain.ck3))
    if kernel is not None:
        status, t_fail, n_ev = kernel(
            chain.inertia, chain.ca, chain.cb, chain.cr, chain.ce, chain.ck, chain.ck3, chain.cc, chain.chalf,
            chain.cramp, chain.cb2, chain.wheel_drag, chain.road, chain.rotor_drag, np.array(lag, dtype=np.float64),
            float(sensor_tau), np.array([chain.tyre[0], chain.tyre[1], tyre0]),
            np.ascontiguousarray(t_in, dtype=np.float64), np.ascontiguousarray(q_in, dtype=np.float64), linear,
            float(t0), float(step), int(n_out), int(sub), np.array(theta0, dtype=np.float64),
            np.array(omega0, dtype=np.float64), float(speed_limit), out_res, out_sens, out_torque)
        raise_status(status, t_fail, step)
        return RawRun(resolver=out_res, sensor=out_sens, torque=out_torque, omega=out_omega, tau=out_tau[:, :nc],
                      tyre=np.zeros(0), is_open=out_open, events=[])
    status, t_fail, n_ev = run_chain(
        chain.inertia, chain.ca, chain.cb, chain.cr, chain.ce, chain.ck, chain.ck3, chain.cc, chain.chalf, chain.cramp,
        chain.cb2,
        chain.rotor, chain.housing, chain.wheel, chain.wheel2, chain.wheel_drag, chain.road, chain.rotor_drag,
        np.array(lag, dtype=np.float64),
        float(sensor_tau), chain.vehicle, np.array([chain.tyre[0], chain.tyre[1], tyre0]),
        np.ascontiguousarray(t_in, dtype=np.float64), np.ascontiguousarray(q_in, dtype=np.float64), linear,
        float(t0), float(step), int(n_out), int(sub), np.array(theta0, dtype=np.float64),
        np.array(omega0, dtype=np.float64), float(speed_limit),
        out_res, out_sens, out_torque, out_omega, out_tau, out_open, ev_gap, ev_t, ev_kind,
    )
    raise_status(status, t_fail, step)
    return RawRun(
        resolver=out_res, sensor=out_sens, torque=out_torque, omega=out_omega, tau=out_tau[:, :nc],
        tyre=out_tau[:, nc].copy() if tyre_on else np.zeros(rows), is_open=out_open,
        events=[(int(ev_gap[k]), float(ev_t[k]), int(ev_kind[k])) for k in range(n_ev)] if events else [],
    )


def is_serial(chain: ChainModel) -> bool:
    """Coupling ``j`` joins body ``j`` to ``j + 1`` for every chain coupling, one wheel body: the layout
    :mod:`sim.unrolled` writes out."""
    nch = chain.n_couplings - (1 if chain.housing >= 0 else 0)
    j = np.arange(nch)
    return bool(chain.wheel2 < 0 and chain.wheel == nch and np.all(chain.ca[:nch] == j)
                and np.all(chain.cb[:nch] == j + 1) and np.all(chain.cb2[:nch] < 0))


def raise_status(status: int, t_fail: float, step: float) -> None:
    """Turn a kernel status code into :class:`InstabilityError` (no-op when OK)."""
    if status == STATUS_OK:
        return
    what = "non-finite state" if status == STATUS_NONFINITE else "diverging speed"
    raise InstabilityError(f"{what} at t = {t_fail:.6f} s with step dt = {step:.3g} s; reduce dt or check "
                           "stiffness/inertia values")
