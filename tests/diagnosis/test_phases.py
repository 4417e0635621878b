"""The lash-traverse phase against the simulator's own gap events, at 1 kHz and 100 Hz."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from app.analysis.diagnosis.forward import FINE_DT, DiagEvent, Prediction, simulate_event
from app.analysis.diagnosis.localise import MIN_TRAVERSE_S, open_runs, phase_times
from sim import Vehicle, load_vehicle, simulate
from sim.effects import apply_effects
from sim.metrics import unloaded_intervals

T_EVENT = 0.5  # s, torque zero crossing of every case
SPEED_RPM = 1500.0
# name -> (backlash scale, torque before and after (N m), ramp duration (s))
CASES = {
    "tip-in, one clean traverse": (1.0, (-50.0, 150.0), 0.135),
    "tip-out, rebound after the impact": (1.0, (150.0, -50.0), 0.135),
    "fast tip-in, wide lash: rebound and a reopening by the shuffle": (2.0, (-80.0, 200.0), 0.03),
    "tip-out, narrow lash: impact chatter": (0.5, (150.0, -50.0), 0.135),
}


@cache
def _vehicle(scale: float) -> Vehicle:
    v = load_vehicle("paper")
    return v if scale == 1.0 else apply_effects(v, {"backlash": {"reducer_scale": scale, "halfshaft_scale": scale}})


def _event(before_after: tuple[float, float], ramp_s: float, rate_hz: float) -> DiagEvent:
    """A window around a linear torque ramp through zero at ``T_EVENT``, speed sampled at ``rate_hz``."""
    q0, q1 = before_after
    t_ramp0 = T_EVENT - ramp_s * (-q0) / (q1 - q0)  # the ramp crosses zero at T_EVENT
    torque_t = np.arange(0.0, 1.6, 0.01)
    torque = np.interp(torque_t, [0.0, t_ramp0, t_ramp0 + ramp_s, 1.6], [q0, q0, q1, q1])
    speed_t = np.arange(0.2, 1.5, 1.0 / rate_hz)
    n = speed_t.size
    kind = "tip_in" if q1 > q0 else "tip_out"
    return DiagEvent(0, kind, T_EVENT, 0.2, 1.5, SPEED_RPM, q1 - q0, torque_t, torque, speed_t,
                     np.full(n, SPEED_RPM), np.ones(n), speed_t < T_EVENT - 0.1)


def _truth(ev: DiagEvent, vehicle: Vehicle) -> list[tuple[float, float]]:
    """Unloaded intervals from the simulator's gap events inside the search window.

    A contact between two of them that no output sample falls in cannot show in any sampled gap
    mask (a hand-over between gaps, a contact of a tenth of a millisecond), so it is bridged.
    """
    res = simulate(vehicle, ev.t_fine, ev.torque_fn(ev.t_fine), speed0_rpm=ev.speed0(), interp="linear",
                   output_dt=FINE_DT)
    t_out = np.asarray(res.t)
    merged: list[tuple[float, float]] = []
    for a, b in unloaded_intervals(res.gap_events, float(ev.t_fine[-1])):
        if merged and not np.any((t_out >= merged[-1][1]) & (t_out < a)):
            merged[-1] = (merged[-1][0], max(b, merged[-1][1]))
        else:
            merged.append((a, b))
    return [(a, b) for a, b in merged if T_EVENT - 0.15 <= a <= T_EVENT + 0.4]


@pytest.mark.parametrize("rate_hz", [1000.0, 100.0])
@pytest.mark.parametrize("case", list(CASES))
def test_traverse_is_the_loss_of_load_to_the_impact(case: str, rate_hz: float) -> None:
    scale, before_after, ramp_s = CASES[case]
    vehicle = _vehicle(scale)
    ev = _event(before_after, ramp_s, rate_hz)
    out = simulate_event(ev, vehicle, 1.0)
    assert out.gap_open is not None
    truth = _truth(ev, vehicle)
    assert truth, "the reversal opens the lash"
    t_open, t_close = truth[0]  # the loss of load; its end is the impact
    assert t_close - t_open > MIN_TRAVERSE_S
    ph = phase_times(ev, Prediction(ev.speed_meas, out.t, out.speed, out.gap_open, 0.0))
    assert ph.t_open == pytest.approx(t_open, abs=1.5e-3)
    assert ph.t_close == pytest.approx(t_close, abs=1.5e-3)
    n_true = int(np.sum((ev.speed_t >= t_open) & (ev.speed_t < t_close)))
    assert abs(ph.resolved_samples - n_true) <= (2 if rate_hz > 500 else 1)
    if rate_hz > 500:
        assert ph.resolved_samples >= 5
    if "rebound" in case or "chatter" in case:
        # the lash opens again after the impact: the last open stretch is not the traverse
        assert len(truth) >= 2
        runs = open_runs(out.gap_open & (out.t <= T_EVENT + 0.4))
        assert out.t[runs[-1, 0]] > t_close


def test_open_runs_are_the_true_stretches() -> None:
    g = np.array([0, 1, 1, 0, 0, 1, 0, 1, 1, 1], dtype=bool)
    assert open_runs(g).tolist() == [[1, 3], [5, 6], [7, 10]]
    assert open_runs(np.zeros(4, dtype=bool)).shape == (0, 2)
