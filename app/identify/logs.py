"""Logs in, an identified vehicle version out: ``lashscope identify`` and the identification job.

::

    identify_logs([log, ...], vehicle, IdentifyOptions(dbc=..., signal_map=...), validate=[other])
      decode each log, find its tip-in/tip-out events, prepare the diagnosis windows
      model-free first mode of every window, pooled over events and logs       (.modal)
      grey-box fit of the base parameters on every event of every log          (.fit)
      withheld drive(s): the analysis with the file's and with the identified vehicle
      the identified vehicle as a new file, with its provenance

Events of several logs are fitted together: each log's windows are moved onto a time line of
their own (the driveline is time-invariant, so a shift changes nothing but keeps the simulator from
running one log's events into another's).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from app.analysis.diagnosis.forward import DiagEvent
from app.analysis.diagnosis.noise import NoiseFloor
from app.analysis.diagnosis.prepare import DIAGNOSIS_EVENTS, prepare
from app.analysis.events import EventParams, detect_events
from app.errors import InsufficientDataError
from app.identify.base import BASE_NAMES
from app.identify.fit import MIN_EVENTS, FitOptions, Identification, Param, identify_staged
from app.identify.modal import ModalEstimate
from app.identify.rigid import rigid_body
from app.pipeline import AnalysisOptions, analyze_signals, decode_log
from app.settings import get_settings
from app.signals import SignalSet
from app.storage.sqlstore import file_sha256
from sim import Vehicle, dump_toml
from sim.vehicle_file import toml_value

Progress = Callable[[float, str], None]
LOG_GAP_S = 1000.0  # s between two logs' time lines


@dataclass(frozen=True)
class IdentifyOptions:
    """Inputs and settings of an identification.

    Attributes
    ----------
    dbc, signal_map : how the logs decode (None: the project's reference files).
    seed : seed of the input-uncertainty draws.
    params : base parameters to fit.
    model : simulator model.
    level : interval level.
    events : event thresholds (default: the diagnosis').
    """

    dbc: Path | None = None
    signal_map: Path | None = None
    seed: int = 0
    params: tuple[str, ...] = BASE_NAMES
    model: str = "multibody"
    level: float = 0.9
    events: EventParams = field(default_factory=lambda: DIAGNOSIS_EVENTS)

    def fit_options(self) -> FitOptions:
        return FitOptions(params=self.params, model=self.model, level=self.level, seed=self.seed)


@dataclass
class IdentifyResult:
    """What :func:`identify_logs` found (see :meth:`to_dict` for the documented JSON)."""

    identification: Identification
    logs: list[dict[str, Any]]
    validation: dict[str, Any]
    base_vehicle: Vehicle
    elapsed_s: float

    @property
    def params(self) -> dict[str, Param]:
        return self.identification.params

    @property
    def modal(self) -> ModalEstimate | None:
        """The model-free first mode pooled over every event window."""
        return self.identification.modal

    @property
    def named(self) -> list[str]:
        return self.identification.named

    @property
    def vehicle(self) -> Vehicle:
        """The new vehicle version: the identified base parameters, and the torque gain where it moved."""
        return self.identification.written_vehicle

    def to_dict(self) -> dict[str, Any]:  # by hand: the identification's entries between the logs and the validation
        return {
            "vehicle": self.base_vehicle.name,
            "logs": self.logs,
            **self.identification.to_dict(),
            "validation": self.validation,
            "elapsed_s": round(self.elapsed_s, 3),
        }

    def provenance(self) -> dict[str, Any]:
        """What the new vehicle version was identified from, and what came out (stored in its file)."""
        return {
            "identified_from": self.base_vehicle.name,
            "date": datetime.now(UTC).replace(microsecond=0).isoformat(),
            "logs": [{"name": lg["name"], "sha256": lg["sha256"], "events": lg["events"]} for lg in self.logs],
            "fitted": {k: {"ratio": _r(p.ratio), "value": _r(p.value), "lo": _r(p.lo), "hi": _r(p.hi),
                           "unit": p.unit} for k, p in self.params.items() if p.identified},
            "not_identified": [k for k in BASE_NAMES if not self.params[k].identified],
            "residual_to_noise_before": _r(self.identification.chi2_before / max(self.identification.n_samples, 1)),
            "residual_to_noise_after": _r(self.identification.chi2_after / max(self.identification.n_samples, 1)),
            "events": self.identification.n_events,
            **({"contact_damping": self.identification.form} if self.identification.form else {}),
        }

    def vehicle_toml(self, name: str | None = None) -> str:
        """The identified vehicle as a file: the same driveline with the fitted values, and a ``[provenance]``."""
        veh = self.vehicle if name is None else replace(self.vehicle, name=name)
        veh = replace(veh, description=(f"{self.base_vehicle.description} -- identified from "
                                        f"{len(self.logs)} log(s): {', '.join(self.named) or 'nothing off the file'}"
                                        ).strip(" -"))
        lines = [dump_toml(veh).rstrip("\n"), "", "[provenance]"]
        lines += [f"{k} = {toml_value(_filled(v))}" for k, v in self.provenance().items()]
        return "\n".join(lines) + "\n"


def _r(x: float) -> float | None:
    return round(float(x), 6) if np.isfinite(x) else None


def _filled(v: Any) -> Any:
    """``v`` with every None (a figure that is not finite) written as "", which TOML has no null for."""
    if isinstance(v, dict):
        return {k: _filled(x) for k, x in v.items()}
    if isinstance(v, list):
        return [_filled(x) for x in v]
    return "" if v is None else v


def shifted(events: Sequence[DiagEvent], dt: float, first_index: int) -> list[DiagEvent]:
    """``events`` moved by ``dt`` seconds and renumbered from ``first_index``."""
    out = []
    for k, ev in enumerate(events):
        out.append(replace(
            ev, index=first_index + k, t_event=ev.t_event + dt, t_start=ev.t_start + dt, t_end=ev.t_end + dt,
            torque_t=ev.torque_t + dt, speed_t=ev.speed_t + dt,
            sim_t0=None if ev.sim_t0 is None else ev.sim_t0 + dt))
    return out


def prepared_logs(signal_sets: Sequence[tuple[str, SignalSet]], params: EventParams
                  ) -> tuple[list[DiagEvent], NoiseFloor, list[dict[str, Any]]]:
    """Every log's prepared events on one time line, the noise floor of the log with most events, per-log facts."""
    events: list[DiagEvent] = []
    facts: list[dict[str, Any]] = []
    noises: list[tuple[int, NoiseFloor]] = []
    t_next = 0.0
    for name, signals in signal_sets:
        found = detect_events(signals, params)
        prep, noise, skipped = prepare(signals, found)
        if prep:
            dt = t_next - min(float(ev.t_fine[0]) for ev in prep)
            events += shifted(prep, dt, len(events))
            t_next = max(float(ev.t_fine[-1]) for ev in events) + LOG_GAP_S
        noises.append((len(prep), noise))
        facts.append({"name": name, "events": len(prep), "skipped": len(skipped),
                      "speed_period_ms": round(1e3 * noise.period_s, 3), "noise_rpm": round(noise.sigma_rpm, 4)})
    noise = max(noises, key=lambda x: x[0])[1]
    return events, noise, facts


def tracking(signals: SignalSet, vehicle: Vehicle) -> dict[str, Any]:
    """The analysis' tracking verdict and median per-event NRMSE of ``vehicle`` on a drive."""
    res = analyze_signals(signals, vehicle, AnalysisOptions(whole_log=False))
    nrmse = [r.comparison.error.nrmse for r in res.event_results if r.comparison is not None]
    finite = [x for x in nrmse if np.isfinite(x)]
    return {"verdict": res.tracking.verdict, "nrmse": _r(float(np.median(finite))) if finite else None,
            "events": len(finite), "reasons": list(res.tracking.reasons)[:4]}


def identify_logs(logs: Sequence[Path], vehicle: Vehicle, options: IdentifyOptions | None = None,
                  validate: Sequence[Path] = (), progress: Progress | None = None) -> IdentifyResult:
    """Identify ``vehicle``'s base parameters from ``logs``; check the result on the ``validate`` drives.

    Raises
    ------
    InsufficientDataError : fewer usable events than an identification needs over all logs.
    NotIdentifiableError : nothing of the vehicle can be fitted from them.
    IngestError and subclasses : a log or the DBC cannot be read.
    """
    opts = options or IdentifyOptions()
    say = progress or (lambda f, m: None)
    clock = time.process_time()
    dbc, smap = _files(opts)
    decoded: list[tuple[str, SignalSet]] = []
    hashes = {}
    for k, path in enumerate(logs):
        say(0.02 + 0.08 * k / max(len(logs), 1), f"decoding {Path(path).name}")
        signals, _ = decode_log(path, dbc, smap)
        decoded.append((Path(path).name, signals))
        hashes[Path(path).name] = file_sha256(Path(path))
    events, noise, facts = prepared_logs(decoded, opts.events)
    for f in facts:
        f["sha256"] = hashes[f["name"]]
    if len(events) < MIN_EVENTS:
        raise InsufficientDataError(
            f"identification needs at least {MIN_EVENTS} tip-in/tip-out events with usable windows; the logs give "
            + ", ".join(f"{f['name']}: {f['events']}" for f in facts))
    rigid = rigid_body([sig for _, sig in decoded], vehicle, opts.seed, opts.events.brake_threshold)
    ident = identify_staged(events, noise, vehicle, opts.fit_options(), lambda f, m: say(0.1 + 0.72 * f, m),
                            rigid=rigid)
    validation: dict[str, Any] = {}
    if validate:
        say(0.85, "validation on the withheld drive(s)")
        before, after = [], []
        for path in validate:
            signals, _ = decode_log(path, dbc, smap)
            before.append({"log": Path(path).name, **tracking(signals, vehicle)})
            after.append({"log": Path(path).name, **tracking(signals, ident.written_vehicle)})
        validation = {"before": before, "after": after,
                      "nrmse_before": _median([v["nrmse"] for v in before]),
                      "nrmse_after": _median([v["nrmse"] for v in after]),
                      "verdict_before": before[0]["verdict"], "verdict_after": after[0]["verdict"]}
    say(1.0, "identified: " + (", ".join(ident.named) or "nothing off the file"))
    return IdentifyResult(ident, facts, validation, vehicle, time.process_time() - clock)


def _median(xs: Sequence[float | None]) -> float | None:
    v = [x for x in xs if x is not None]
    return _r(float(np.median(v))) if v else None


def _files(opts: IdentifyOptions) -> tuple[Path, Path]:
    dbc_dir = get_settings().dbc_dir
    return (opts.dbc or dbc_dir / "lashscope_ev.dbc", opts.signal_map or dbc_dir / "lashscope_ev.map.toml")
