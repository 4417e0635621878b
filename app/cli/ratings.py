"""``lashscope ratings fit RATINGS.csv``: fit a drivability rating model to a user's own scores.

RATINGS.csv has a header and one scored event per line::

    log,event_index,score          # the event's index in the analysis / event store
    drive_0612.blf,3,6.5
    log,time_s,score               # or the torque zero crossing's time in s since the log's start (+-0.5 s)
    drive_0612.blf,41.2,7

``log`` is the log's file name (or its content hash, or the first 8+ characters of it, as the event store
keeps it). The events' measured criteria come from the event store (``--store DIR``, what ``lashscope
batch`` and the service write) or from analysis documents (``--analysis FILE``, ``lashscope analyze --out
FILE``). The model is written to ``--out`` (default ``ratings-model.json``); apply it with ``lashscope
analyze --ratings FILE`` or ``LASHSCOPE_RATINGS=FILE``.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path
from typing import Any

TIME_TOLERANCE_S = 0.5


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "ratings", help="fit a drivability rating model to your own scores per event",
        description="Fit a monotone model from drivability criteria to 1-10 scores given per event; "
        "without a fitted model no rating is shown.")
    rsub = p.add_subparsers(dest="ratings_command", metavar="ACTION")
    rsub.required = True
    f = rsub.add_parser("fit", help="fit and store a rating model")
    f.add_argument("ratings", type=Path, help="CSV: log, event_index or time_s, score (1-10)")
    f.add_argument("--store", type=Path, default=None, help="event store with the events' criteria")
    f.add_argument("--analysis", type=Path, action="append", default=[], metavar="FILE",
                   help="analysis JSON (lashscope analyze --out); may be repeated")
    f.add_argument("--out", type=Path, default=Path("ratings-model.json"))
    f.add_argument("--min-events", type=int, default=None, help="fewest scored events to fit (default 20)")
    f.set_defaults(func=run_fit)


def _events_from_docs(paths: list[Path]) -> list[dict[str, Any]]:
    from app.errors import InputError

    out = []
    for path in paths:
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputError(f"analysis {path}: cannot read ({exc})") from exc
        log = Path(str(doc.get("log") or path.stem)).name
        for m in doc.get("metrics", []):
            feel = (m.get("drivability") or {}).get("measured") or {}
            out.append({"log": log, "hash": "", "index": int(m["event_index"]), "t": float(m["t_cross_s"]),
                        "criteria": feel})
    return out


def _events_from_store(root: Path) -> list[dict[str, Any]]:
    from app.analysis.ratings import FEATURES
    from app.fleet.store import read_events

    cols = ["log_name", "log_hash", "event_index", "t_log_s", *(f"measured_accel_{f}" for f in FEATURES)]
    frame = read_events(root, columns=cols)
    return [{"log": r["log_name"], "hash": r["log_hash"], "index": int(r["event_index"]), "t": float(r["t_log_s"]),
             "criteria": {f: r[f"measured_accel_{f}"] for f in FEATURES}} for r in frame.to_dict("records")]


def _match(events: list[dict[str, Any]], log: str, index: int | None, t: float | None, where: str) -> dict[str, Any]:
    from app.errors import InputError

    of_log = [e for e in events if log in (e["log"], e["hash"]) or (len(log) >= 8 and e["hash"].startswith(log))]
    if not of_log:
        raise InputError(f"{where}: no analysed log {log!r} (logs known: "
                         f"{', '.join(sorted({e['log'] for e in events})[:5]) or 'none'})",
                         code="ratings_unknown_event")
    if index is not None:
        hit = [e for e in of_log if e["index"] == index]
        if not hit:
            raise InputError(f"{where}: log {log!r} has no event {index} (events "
                             f"{min(e['index'] for e in of_log)}-{max(e['index'] for e in of_log)})",
                             code="ratings_unknown_event")
        return hit[0]
    assert t is not None
    best = min(of_log, key=lambda e: abs(e["t"] - t))
    if abs(best["t"] - t) > TIME_TOLERANCE_S:
        raise InputError(f"{where}: log {log!r} has no event at {t:g} s (nearest at {best['t']:.2f} s)",
                         code="ratings_unknown_event")
    return best


def read_scores(path: Path, events: list[dict[str, Any]]) -> tuple[list[dict[str, Any]], list[float]]:
    """The scored events of RATINGS.csv matched to analysed events; typed errors name the line."""
    from app.errors import InputError

    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"ratings {path}: cannot read ({exc})") from exc
    reader = csv.DictReader(lines)
    head = set(reader.fieldnames or [])
    if not {"log", "score"} <= head or not head & {"event_index", "time_s"}:
        raise InputError(f"ratings {path}: the header must name log, score and event_index or time_s "
                         f"(found {sorted(head)})", code="ratings_csv")
    matched: list[dict[str, Any]] = []
    scores: list[float] = []
    seen: set[tuple[str, int]] = set()
    for n, row in enumerate(reader, start=2):
        where = f"ratings {path.name} line {n}"
        try:
            score = float(row["score"])
            index = int(row["event_index"]) if (row.get("event_index") or "").strip() else None
            t = float(row["time_s"]) if index is None else None
        except (TypeError, ValueError):
            raise InputError(f"{where}: score, event_index and time_s must be numbers ({dict(row)})",
                             code="ratings_csv") from None
        ev = _match(events, (row["log"] or "").strip(), index, t, where)
        key = (ev["log"], ev["index"])
        if key in seen:
            raise InputError(f"{where}: event {ev['index']} of {ev['log']} is scored twice", code="ratings_csv")
        seen.add(key)
        matched.append(ev)
        scores.append(score)
    return matched, scores


def run_fit(args: argparse.Namespace) -> int:
    import numpy as np

    from app.analysis.ratings import FEATURES, MIN_EVENTS, fit_ratings
    from app.errors import InputError
    from app.ratings_file import save_model

    if args.store is None and not args.analysis:
        raise InputError("ratings fit: name the events' criteria with --store DIR or --analysis FILE")
    events = (_events_from_store(args.store) if args.store is not None else []) + _events_from_docs(args.analysis)
    matched, scores = read_scores(args.ratings, events)
    x = np.array([[float(v) if (v := e["criteria"].get(f)) is not None else np.nan for f in FEATURES]
                  for e in matched], dtype=np.float64).reshape(len(matched), len(FEATURES))
    model = fit_ratings(x, np.array(scores), min_events=args.min_events or MIN_EVENTS)
    path = save_model(model, args.out)
    print(f"rating model {model.version}: {model.events} scored events, cross-validated RMS error "
          f"{model.cv_rms:.2f} points; criteria {', '.join(model.features)}; written to {path}")
    return 0
