"""The rigid-body response over whole drives: the inertia at the motor per logged N m (model-free).

Below its first torsional mode the driveline turns as one body, ``J dw/dt = g T - c0 - c2 w |w|`` at the motor
(``g`` the air-gap torque per logged N m, ``c0`` rolling resistance and grade, ``c2`` the aerodynamic drag).
Over every driving second of the logs -- the brakes off (:func:`app.analysis.events.brake_levels`), above a crawl,
no hole in the data -- the speed change from a *settled* sample (no torque reversal for :data:`SETTLE_S`, no
torque step building a twist) is fitted in integrated form::

    w(t) - w(t0) = (int T dt) / J' - c0' (t - t0) - c2' (int w |w| dt)

over pieces of up to :data:`PIECE_S`. The lash traverse, the twist and the shuffle keep the motor speed within a
bounded distance of the rigid body's while the integrals grow, so they neither bias the slope as a lagging
regressor does (a fit of the acceleration on the torque read 20-40 % heavy on the independent generator's
drives) nor add up; starting each piece where they have died out removes the rest. The fit gives ``J / g``:
kilogram metres squared at the rotor per logged N m, from no simulator, over far more data than the event
windows. The vehicle file's figure is its rigid inertia (:func:`app.analysis.diagnosis.uncertainty.rigid_inertia`)
over its torque gain.

A heavier car and a torque channel that reads high change it alike, so it pins down their combination, not
either one: the report says so. The 90 % interval comes from a bootstrap over the pieces; pieces whose residual
stands out (a spinning or locking wheel) are trimmed once.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from app.analysis.diagnosis.uncertainty import rigid_inertia
from app.analysis.events import SPEED, TORQUE, EventParams, brake_levels
from app.analysis.series import FloatArray, finite_signal, moving_mean
from app.serial import PLAIN, Rule, Serial, computed, lists, rule
from app.signals import SignalSet
from sim import Vehicle

GRID_S = 0.02  # the samples are put on this grid
PIECE_S = 4.0  # driving stretches are cut into pieces up to this long, from one settled sample to another
MIN_PIECE_S = 1.0  # ... and at least this long
SETTLE_S = 0.6  # a settled sample: no torque reversal in this long (the lash traverse and its shuffle are over)
REVERSAL_BAND_NM = 5.0  # ... a reversal leaves this band on the other side
STEADY_S, STEADY_NM = 0.3, 20.0  # ... and the torque moved less than this over this long (no twist building up)
END_S = 0.1  # a piece's end speeds are means over this long
MIN_SPEED_RPM = 100.0  # a crawl is left out (rolling resistance switches sign at rest)
BRAKE_MARGIN_S = 0.4  # samples this close to an applied brake are left out
MAX_GAP_S = 0.1  # a stretch ends at a larger hole in the speed or the torque
TRIM_SIGMA = 4.0  # pieces whose residual is beyond this many robust sigmas (wheel spin, a locking wheel) are trimmed
N_BOOT = 200
MIN_DRIVING_S = 10.0  # driving time needed for an estimate
MIN_TORQUE_SPREAD_NM = 5.0  # the torque's standard deviation over those samples, at least
MIN_R2 = 0.5  # a fit that explains less of the speed changes is no estimate


@dataclass(frozen=True)
class RigidBody(Serial):
    """Inertia at the motor per logged N m, from whole drives (None figures: no estimate, ``reason`` says why)."""

    inertia_kgm2: float | None = field(metadata=rule(digits=6))
    ci: tuple[float, float] | None = field(metadata=rule(convert=lists, digits=6))
    file_inertia_kgm2: float = field(metadata=rule(digits=6))
    driving_s: float = field(metadata=rule(digits=3))
    r2: float | None = field(metadata=rule(digits=6))
    reason: str = field(default="", metadata=rule(falsy_none=True))

    serial_computed = computed(ratio=Rule(digits=6), off_the_file=PLAIN, describe=Rule(key="summary"))
    serial_order = ("inertia_kgm2", "ci", "file_inertia_kgm2", "ratio", "off_the_file", "driving_s", "r2", "reason",
                    "describe")

    @property
    def ratio(self) -> float | None:
        """The measured figure over the file's: a heavier car, or a torque that reads high, both raise it."""
        return None if self.inertia_kgm2 is None else self.inertia_kgm2 / self.file_inertia_kgm2

    @property
    def off_the_file(self) -> bool:
        """Whether the file's figure lies outside the 90 % interval."""
        return bool(self.ci is not None and not self.ci[0] <= self.file_inertia_kgm2 <= self.ci[1])

    def describe(self) -> str:
        if self.inertia_kgm2 is None or self.ci is None or self.ratio is None:
            return f"rigid body (model-free): no estimate ({self.reason})"
        line = (f"rigid body (model-free, {self.driving_s:.0f} s of driving, R^2 {self.r2:.2f}): "
                f"{self.inertia_kgm2:.4g} kg m^2 at the motor per logged N m [{self.ci[0]:.4g}, {self.ci[1]:.4g}], "
                f"the file's {self.file_inertia_kgm2:.4g}: {self.ratio:.2f}x")
        if self.off_the_file:
            line += (f" -- a heavier car (its inertia at the motor {self.ratio:.2f}x the file's), or a torque channel "
                     f"reading {self.ratio:.2f}x the air-gap torque: the logs cannot tell these apart")
        return line


@dataclass(frozen=True)
class _Piece:
    """One stretch of driving between two settled samples: its speed change (rad/s) and the regressors' changes."""

    dw: FloatArray  # w(t) - w(start)
    x: FloatArray  # (n, 3): integral of the torque (N m s), elapsed time (s), integral of w |w| (rad^2/s)
    torque: FloatArray


def _settled(t: FloatArray, q: FloatArray) -> npt.NDArray[np.bool_]:
    """Samples where the driveline turns as one body: no torque reversal in the last :data:`SETTLE_S` (the lash
    traverse and the shuffle that follows have died out) and no step over :data:`STEADY_NM` in the last
    :data:`STEADY_S` (no twist building up)."""
    sign = np.where(q > REVERSAL_BAND_NM, 1, np.where(q < -REVERSAL_BAND_NM, -1, 0))
    last = np.maximum.accumulate(np.where(sign != 0, np.arange(sign.size), 0))
    held = sign[last]  # the last sign outside the band (0 before the first)
    flips = np.concatenate(([False], (held[1:] != held[:-1]) & (held[:-1] != 0)))
    last_flip = np.maximum.accumulate(np.where(flips, t, -np.inf))
    quiet = t - last_flip >= SETTLE_S
    n = max(round(STEADY_S / GRID_S), 1)
    pad = np.concatenate((np.full(n, q[0]), q))
    windows = np.lib.stride_tricks.sliding_window_view(pad, n + 1)
    lo, hi = windows.min(axis=1), windows.max(axis=1)
    return np.asarray(quiet & (hi - lo <= STEADY_NM), dtype=np.bool_)


def _pieces(signals: SignalSet, threshold: float) -> list[_Piece]:
    """Driving stretches of one log -- brakes off, above a crawl, no hole in the data -- cut into pieces whose ends
    are settled samples."""
    speed, torque = finite_signal(signals[SPEED]), finite_signal(signals[TORQUE])
    if len(speed) < 4 or len(torque) < 4:
        return []
    t0, t1 = max(speed.t[0], torque.t[0]), min(speed.t[-1], torque.t[-1])
    if t1 - t0 < 2 * MIN_PIECE_S:
        return []
    t = np.arange(t0, t1, GRID_S)
    w_raw = speed.at(t) * (np.pi / 30.0)
    q = torque.at(t)
    ok = np.isfinite(w_raw) & np.isfinite(q) & (np.abs(w_raw) * 30.0 / np.pi > MIN_SPEED_RPM)
    for sig in (speed, torque):
        holes = np.flatnonzero(np.diff(sig.t) > MAX_GAP_S)
        for k in holes:
            ok &= ~((t > sig.t[k]) & (t < sig.t[k + 1]))
    for name in sorted(signals):
        if name.startswith("brake") and len(signals[name]):
            level = brake_levels(signals[name], threshold)[1]
            applied = (np.nan_to_num(signals[name].at(t), nan=0.0) > level).astype(np.float64)
            ok &= moving_mean(t - BRAKE_MARGIN_S, applied, 2.0 * BRAKE_MARGIN_S) == 0.0
    w_raw = np.where(np.isfinite(w_raw), w_raw, 0.0)
    q = np.where(np.isfinite(q), q, 0.0)
    w = moving_mean(t - 0.5 * END_S, w_raw, END_S)  # an end's speed: the mean over END_S about it
    ends = ok & _settled(t, q)
    # integrals by the trapezoid rule on the grid
    cq = np.concatenate(([0.0], np.cumsum(0.5 * (q[1:] + q[:-1]) * GRID_S)))
    drag = w_raw * np.abs(w_raw)  # air drag opposes the motion, reversing included
    cw2 = np.concatenate(([0.0], np.cumsum(0.5 * (drag[1:] + drag[:-1]) * GRID_S)))
    out = []
    edges = np.flatnonzero(np.diff(np.concatenate(([0], ok.astype(np.int8), [0]))))
    lo_n, hi_n = round(MIN_PIECE_S / GRID_S), round(PIECE_S / GRID_S)
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        cand = a + np.flatnonzero(ends[a:b])
        i = 0
        while i < cand.size:
            s0 = int(cand[i])
            e = min(s0 + hi_n, b - 1)
            if e - s0 < lo_n:
                break
            sl = slice(s0 + 1, e + 1)
            out.append(_Piece(w[sl] - w[s0], np.column_stack([cq[sl] - cq[s0], t[sl] - t[s0], cw2[sl] - cw2[s0]]),
                              q[s0:e + 1]))
            i = int(np.searchsorted(cand, e))
    return out


def _fit(pieces: Sequence[_Piece]) -> tuple[FloatArray, FloatArray]:
    """Least squares of every piece's speed changes on its regressors: (coefficients, per-piece RMS residual)."""
    x = np.concatenate([p.x for p in pieces])
    y = np.concatenate([p.dw for p in pieces])
    coef = np.linalg.lstsq(x, y, rcond=None)[0]
    return coef, np.array([float(np.sqrt(np.mean((p.dw - p.x @ coef) ** 2))) for p in pieces])


def rigid_body(signal_sets: Sequence[SignalSet], vehicle: Vehicle, seed: int = 0,
               brake_threshold: float = EventParams.brake_threshold) -> RigidBody:
    """The rigid-body inertia at the motor per logged N m over ``signal_sets`` (one per log), with its interval.

    See the module's text for the method; figures are None with a ``reason`` when the drives do not give one.
    """
    file_j = rigid_inertia(vehicle) / vehicle.motor.torque_gain
    pieces = [p for s in signal_sets for p in _pieces(s, brake_threshold)]
    driving_s = sum(float(p.x[-1, 1]) for p in pieces)
    if driving_s < MIN_DRIVING_S:
        return RigidBody(None, None, file_j, driving_s, None,
                         f"{driving_s:.1f} s of driving with the brakes off, under {MIN_DRIVING_S:g} s")
    spread = float(np.std(np.concatenate([p.torque for p in pieces])))
    if spread < MIN_TORQUE_SPREAD_NM:
        return RigidBody(None, None, file_j, driving_s, None,
                         f"the torque hardly varies (standard deviation {spread:.2g} N m)")
    coef, rms = _fit(pieces)
    med = float(np.median(rms))
    mad = 1.4826 * float(np.median(np.abs(rms - med)))
    pieces = [p for p, r in zip(pieces, rms, strict=True) if r <= med + TRIM_SIGMA * max(mad, 1e-12)]
    coef, rms = _fit(pieces)
    y = np.concatenate([p.dw for p in pieces])
    r2 = 1.0 - float(np.sum(rms**2 * np.array([p.dw.size for p in pieces]))) / max(float(np.sum(y * y)), 1e-300)
    if not coef[0] > 0.0 or r2 < MIN_R2:
        return RigidBody(None, None, file_j, driving_s, r2,
                         f"the motor speed does not follow the logged torque (R^2 {r2:.2f}, "
                         f"slope {coef[0]:.3g} rad/s^2 per N m)")
    rng = np.random.default_rng(seed)
    boot = []
    for _ in range(N_BOOT):
        c, _ = _fit([pieces[k] for k in rng.integers(0, len(pieces), len(pieces))])
        if c[0] > 0.0:
            boot.append(1.0 / c[0])
    if len(boot) < N_BOOT // 2:
        return RigidBody(None, None, file_j, driving_s, r2, "the bootstrap resamples do not give a positive slope")
    lo, hi = (float(x) for x in np.percentile(boot, [5.0, 95.0]))
    return RigidBody(float(1.0 / coef[0]), (lo, hi), file_j, driving_s, r2)
