"""Windows start from the true state: warm starts, clusters of close reversals, continuous runs."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
import pytest
from scipy.interpolate import PchipInterpolator

from app.analysis.diagnosis import DiagnosisOptions, diagnose_signals, report_dict
from app.analysis.diagnosis.forward import FINE_DT, DiagEvent, Nuisance, clusters, simulate_events
from app.analysis.diagnosis.prepare import WindowParams, warm_start
from app.analysis.diagnosis.uncertainty import input_uncertainty
from app.errors import InputError
from app.signals import SignalSet
from sim import simulate
from tests.diagnosis.conftest import paper

Signals = Callable[..., SignalSet]
CLOSE = (0.7, 2.5)  # s between reversals: each one still carries the previous one's shuffle
OPTS = DiagnosisOptions(candidates=("drag", "backlash"), seed=3, max_pairs=0)


def _torque(step_at: float) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(0.0, 20.0, 0.01)
    return t, np.where(t < step_at, -40.0, 80.0)


def _scan_back(tq_t: np.ndarray, tq_v: np.ndarray, t_window: float, p: WindowParams) -> float:
    """The warm start by its definition: sample by sample back from the window, the spread of the torque over
    the settle time before each."""
    lo = max(float(tq_t[0]), t_window - p.max_warm_s)
    near = (tq_t >= lo - p.settle_s) & (tq_t <= t_window)
    tt, vv = tq_t[near], tq_v[near]
    first = np.searchsorted(tt, tt - p.settle_s)
    for j in range(tt.size - 1, -1, -1):
        if tt[j] < lo or tt[j] - p.settle_s < tq_t[0]:
            break
        if float(np.ptp(vv[first[j]:j + 1])) <= p.settle_tol_nm:
            return t_window if j == tt.size - 1 else float(tt[j])
    return lo


@pytest.mark.parametrize("seed", range(4))
def test_warm_start_equals_the_sample_by_sample_search(seed: int) -> None:
    """Random torques at 20 Hz to 1 kHz (wandering, quantised, with a NaN sample) and windows anywhere."""
    rng = np.random.default_rng(seed)
    p = WindowParams()
    for _ in range(150):
        rate = float(rng.choice([20, 50, 100, 1000]))
        n = int(rng.integers(2, 8000 if rate == 1000 else 1200))
        t = np.cumsum(rng.uniform(0.3, 1.7, n) / rate) + rng.uniform(0, 5)
        v = np.cumsum(rng.normal(0, float(rng.choice([0.05, 0.3, 1.0, 3.0])), n))
        if rng.random() < 0.2:
            v = np.round(v)
        if rng.random() < 0.1:
            v[rng.integers(0, n)] = np.nan
        t_window = float(rng.uniform(t[0] - 1, t[-1] + 0.5))
        assert warm_start(t, v, t_window, p) == _scan_back(t, v, t_window, p)


def test_warm_start_is_the_window_start_when_the_torque_has_settled() -> None:
    t, q = _torque(5.0)
    assert warm_start(t, q, 10.0, WindowParams()) == 10.0  # 5 s steady before the window


def test_warm_start_goes_back_to_the_last_quasi_static_point() -> None:
    t, q = _torque(9.0)  # a step 1 s before the window: quasi-static just before it, at 8.99 s
    assert warm_start(t, q, 10.0, WindowParams()) == pytest.approx(8.99, abs=1e-9)


def test_warm_start_without_a_quasi_static_point_is_max_warm_early_or_the_log_start() -> None:
    t = np.arange(0.0, 20.0, 0.01)
    q = 60.0 * np.sign(np.sin(2 * np.pi * t / 1.5))  # a reversal every 0.75 s
    assert warm_start(t, q, 10.0, WindowParams()) == pytest.approx(6.0, abs=0.011)
    assert warm_start(t, q, 2.0, WindowParams()) == 0.0


def _event(index: int, t_start: float, sim_t0: float | None, t_tq: np.ndarray, q: np.ndarray) -> DiagEvent:
    st = np.arange(t_start, t_start + 1.3, 0.01)
    m = (t_tq >= (sim_t0 if sim_t0 is not None else t_start) - 0.2) & (t_tq <= t_start + 1.5)
    return DiagEvent(index, "tip_in", t_start + 0.3, t_start, t_start + 1.3, 3000.0, 100.0, t_tq[m], q[m], st,
                     np.full(st.size, 3000.0), np.ones(st.size), st < t_start + 0.2, sim_t0, 3000.0)


def test_overlapping_windows_are_one_continuous_run() -> None:
    t_tq = np.arange(0.0, 12.0, 0.01)
    q = np.interp(t_tq, [0, 2, 2.05, 3.2, 3.25, 4.4, 4.45, 12], [-40, -40, 80, 80, -40, -40, 80, 80])
    evs = [_event(0, 1.7, 0.5, t_tq, q), _event(1, 2.9, 1.0, t_tq, q), _event(2, 4.1, 1.5, t_tq, q),
           _event(3, 9.0, None, t_tq, q)]
    assert clusters(evs) == [[0, 1, 2], [3]]
    outs = simulate_events(evs, paper(), 1.0)
    # the cluster equals one simulation from the first event's warm start over the whole span
    grid = evs[0].t_fine[0] + FINE_DT * np.arange(round((evs[2].t_fine[-1] - evs[0].t_fine[0]) / FINE_DT) + 1)
    m = (t_tq >= evs[0].torque_t[0]) & (t_tq <= evs[2].torque_t[-1])  # the three events' torque samples
    ref = simulate(paper(), grid, PchipInterpolator(t_tq[m], q[m])(grid), speed0_rpm=3000.0, interp="linear",
                   output_dt=FINE_DT)
    for ev, out in zip(evs[:3], outs[:3], strict=True):
        assert out.t[0] == pytest.approx(ev.t_fine[0], abs=1e-9) and out.t[-1] == pytest.approx(ev.t_fine[-1], abs=1e-9)
        np.testing.assert_allclose(out.speed, np.interp(out.t, ref.t, ref.motor_speed_rpm), atol=1e-6)
    # the third event alone from its own warm start 2.6 s earlier: the start's error has decayed to
    # a fraction of an rpm in its pre-event part; from a rest state at its window start it is not
    w = (outs[2].t > evs[2].t_start) & (outs[2].t < evs[2].t_start + 0.3)
    alone = simulate_events([evs[2]], paper(), 1.0)[0]
    assert np.ptp(alone.speed[w] - outs[2].speed[w]) < 0.5
    cold = simulate_events([_event(2, 4.1, None, t_tq, q)], paper(), 1.0)[0]
    wc = (cold.t > evs[2].t_start) & (cold.t < evs[2].t_start + 0.3)
    assert np.ptp(cold.speed[wc] - outs[2].speed[w]) > 20.0


def test_close_reversals_without_effect_are_no_significant_gap(signals_for: Signals) -> None:
    sig = signals_for(None, (), 21, 30.0, 0.006, CLOSE)
    cold = diagnose_signals(sig, paper(), OPTS, window=WindowParams(max_warm_s=0.0))
    warm = diagnose_signals(sig, paper(), OPTS)
    # from a quasi-static state at every window start: far above the noise, mostly before the event
    before = cold.decision.gap_ratio
    assert before is not None and before.value > 10.0
    # ... and still a significant gap with the model-form tolerance on: its weight stays full where the
    # model predicts no swing, so the cold start's pre-event residual is not hidden
    tolerant = diagnose_signals(sig, paper(), replace(OPTS, model_form_rel=0.15), window=WindowParams(max_warm_s=0.0))
    assert tolerant.decision.gap_ratio is not None and tolerant.decision.gap_ratio.lo > 1.15
    assert tolerant.decision.status != "no_significant_gap"
    pre_share = report_dict(cold)["localisation"]["phases"][0]
    assert pre_share["phase"] == "pre_event" and pre_share["energy_share"] > 0.5
    # through the cluster of close reversals: at the noise floor
    after = warm.decision.gap_ratio
    assert after is not None and after.value < 1.5, warm.decision.reason
    assert warm.decision.status == "no_significant_gap"
    assert max(e.warm_s for e in warm.events) > 1.0  # windows were warmed up through earlier reversals
    # windows cut short by the next reversal to 0.3-0.6 s after the crossing are kept
    assert any(0.3 <= e.t_end - e.t_event < 0.6 for e in warm.events)


def test_model_form_tolerance_follows_the_predicted_oscillation() -> None:
    """``form_rel`` adds (form_rel x local RMS of the predicted oscillation)^2: large where the model predicts
    the shuffle, nothing where it predicts a quiet stretch; 0 leaves the variance as it was."""
    t_tq = np.arange(0.0, 12.0, 0.01)
    q = np.interp(t_tq, [0, 8.0, 8.05, 12], [-40, -40, 80, 80])  # one reversal after a long quiet hold
    ev = _event(0, 7.7, None, t_tq, q)  # window 7.7..9.0 s, reversal at 8.0 s
    nuis = Nuisance(0.0, 1.0, 0.0)
    plain = input_uncertainty([ev], paper(), nuis)[0]
    tolerant = input_uncertainty([ev], paper(), nuis, form_rel=0.1)[0]
    extra = tolerant - plain
    quiet = ev.speed_t < 7.85  # before the reversal, more than a window's half-width away from it
    swing = (ev.speed_t > 8.1) & (ev.speed_t < 8.6)  # the shuffle after the impact
    assert np.all(extra >= -1e-12)
    assert float(np.max(extra[quiet])) < 1e-3  # (rpm^2) the quiet stretch keeps its full weight
    assert float(np.median(extra[swing])) > 1.0  # >= (0.1 x 10 rpm)^2 where the model swings by tens of rpm
    assert np.array_equal(input_uncertainty([ev], paper(), nuis, form_rel=0.0)[0], plain)
    with pytest.raises(InputError, match="model_form_rel"):
        DiagnosisOptions(model_form_rel=-0.1)
