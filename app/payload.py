"""A finished analysis as stored: one JSON document and named arrays (see app.storage.results).

Arrays::

    whole_t, whole_measured_rpm, whole_simulated_rpm, whole_torque_nm     whole log, uniform time base
    ev_t, ev_measured_rpm, ev_simulated_rpm, ev_torque_nm                 all event windows, concatenated;
                                                                          doc["event_rows"][i] = [start, stop)
    sig_<k>_t, sig_<k>_v                                                  decoded channel k (doc["signals"])
"""

from __future__ import annotations

from dataclasses import asdict
from typing import Any

import numpy as np
import numpy.typing as npt

from app.analysis.compare import resolution_reasons, summarize
from app.analysis.feel import summarize_feel
from app.analysis.ratings import RatingModel, apply_ratings
from app.analysis.sampling import spacing
from app.pipeline import AnalysisResult
from app.ratings_file import model_from_env

SERIES_COLUMNS = ("measured_rpm", "simulated_rpm", "torque_nm")


def result_payload(res: AnalysisResult, ratings: RatingModel | None = None,
                   ) -> tuple[dict[str, Any], dict[str, npt.NDArray[np.float64]]]:
    """The stored document and arrays; drivability ratings only with a fitted model (``ratings``, else the one
    ``LASHSCOPE_RATINGS`` names: :mod:`app.ratings_file`)."""
    arrays: dict[str, npt.NDArray[np.float64]] = {}
    events: list[dict[str, Any]] = []
    metrics: list[dict[str, Any]] = []
    rows: dict[str, list[int]] = {}
    parts: dict[str, list[npt.NDArray[np.float64]]] = {k: [] for k in ("t", *SERIES_COLUMNS)}
    n = 0
    for er in res.event_results:
        d = er.event.to_dict()
        d["error"] = er.error
        d["has_series"] = er.aligned is not None
        d["has_metrics"] = er.comparison is not None
        d["tracking"] = er.tracking.to_dict() if er.tracking is not None else None
        events.append(d)
        if er.aligned is not None:
            a = er.aligned
            for key, arr in (("t", a.t), ("measured_rpm", a.measured_rpm), ("simulated_rpm", a.simulated_rpm),
                             ("torque_nm", a.torque_nm)):
                parts[key].append(arr)
            rows[str(er.event.index)] = [n, n + a.t.size]
            n += a.t.size
        if er.comparison is not None:
            m = er.comparison.to_dict()
            m["kind"] = er.event.kind.value
            m["t_cross_s"] = er.event.t_cross_s
            m["sim_gap_open_time_s"] = er.sim_gap_open_time_s
            m["tracking"] = er.tracking.to_dict() if er.tracking is not None else None
            m["drivability"] = er.feel.to_dict() if er.feel is not None else None
            metrics.append(m)
    for key, chunks in parts.items():
        arrays[f"ev_{key}"] = np.concatenate(chunks) if chunks else np.empty(0)
    whole: dict[str, Any] | None = None
    if res.whole is not None:
        w = res.whole
        arrays.update(whole_t=w.t, whole_measured_rpm=w.measured_rpm, whole_simulated_rpm=w.simulated_rpm,
                      whole_torque_nm=w.torque_nm)
        whole = {"dt_s": float(w.t[1] - w.t[0]) if w.t.size > 1 else None, "points": int(w.t.size),
                 "t_start_s": float(w.t[0]), "t_end_s": float(w.t[-1]),
                 **(asdict(res.whole_error) if res.whole_error is not None else {})}
    signals: dict[str, Any] = {}
    for k, (name, sig) in enumerate(sorted(res.signals.items())):
        arrays[f"sig_{k}_t"], arrays[f"sig_{k}_v"] = sig.t, sig.values
        signals[name] = {"key": k, "unit": sig.unit, "samples": len(sig), "interp": sig.interp.value,
                         "t_start_s": float(sig.t[0]) if len(sig) else None,
                         "t_end_s": float(sig.t[-1]) if len(sig) else None}
    comparisons = [er.comparison for er in res.event_results if er.comparison is not None]
    feels = [er.feel for er in res.event_results if er.feel is not None]
    feel_kinds = [er.event.kind.value for er in res.event_results if er.feel is not None]
    included = sum(1 for e in res.events if e.included)
    summary = {
        "events": len(res.events), "included": included, "excluded": len(res.events) - included,
        "with_metrics": len(comparisons), "tip_in": sum(1 for e in res.events if e.kind.value == "tip_in"),
        "tip_out": sum(1 for e in res.events if e.kind.value == "tip_out"),
        "offset_ms": res.offset.lag_s * 1e3 if res.offset.applied else 0.0, "offset_applied": res.offset.applied,
        "offset_correlation": res.offset.correlation,
        "metrics": summarize(comparisons) if comparisons else {},
        "resolution": resolution_reasons(comparisons),
        "tracking": res.tracking.to_dict(),
        "findings": [f.to_dict() for f in res.findings],
        "whole_rms_rpm": res.whole_error.rms_rpm if res.whole_error else None,
        "whole_nrmse": res.whole_error.nrmse if res.whole_error else None,
        "drivability": summarize_feel(feels, feel_kinds) if feels else {},
        "read": res.ingest.get("read"),  # damaged or truncated input: frames and seconds lost, a note
    }
    doc = {
        "schema": 1, "summary": summary, "events": events, "metrics": metrics, "event_rows": rows,
        "offset": asdict(res.offset), "whole": whole, "signals": signals, "ingest": res.ingest,
        "timings_s": res.timings_s, "notes": res.notes, "tracking": res.tracking.to_dict(),
        "sampling": {name: spacing(sig.t).to_dict() for name, sig in sorted(res.signals.items())},
        "acceleration": res.acceleration.describe() if res.acceleration is not None else None,
    }
    model = ratings if ratings is not None else model_from_env()
    if model is not None and feels:
        apply_ratings(doc, model)
    return doc, arrays
