"""The event-store hook: the service's analyses write the same Parquet rows as the batch.

Whoever ran an analysis calls :func:`after_analysis` with the stored document
(:func:`app.payload.result_payload`): the ``analysis`` job kind (:mod:`app.jobkinds.analysis`) and
``lashscope analyze``; :func:`app.pipeline.run_analysis` itself has no side effects. When the
environment names an event store (``LASHSCOPE_EVENT_STORE=DIR``) the analysis' events are
written there (:mod:`app.fleet.store`, ``source = "service"``), so one query covers uploads and
batches. ``lashscope serve`` sets it to ``<data dir>/events`` unless it is set already (``off``
disables it); the job workers it spawns inherit it. Elsewhere (``lashscope analyze``, library
calls, tests) it is unset and nothing is written.

The hook never fails an analysis: a store that cannot be written is logged as a warning.
The vehicle of the rows is the registered vehicle's name (``VehicleInputs.name``; the driveline
description's name when the inputs do not come from the store), the driveline's is in ``driveline``.
The log's hash is the one its upload stored when the caller has it (``log_hash``), else the log is
hashed here.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.fleet.rows import event_rows
from app.log_source import LogSource, content_hash, source_name
from app.settings import Settings
from app.storage.results import json_safe

if TYPE_CHECKING:
    from app.pipeline import VehicleInputs

ENV = "LASHSCOPE_EVENT_STORE"
OFF = ("", "0", "off", "none", "false")
log = logging.getLogger(__name__)


def store_dir() -> Path | None:
    """The event store the hook writes to (``Settings.event_store``, read now), or None when it is off."""
    value = Settings().event_store.strip()
    return None if value.lower() in OFF else Path(value)


def enable_for_service(data_dir: Path) -> None:
    """``lashscope serve``: write under ``<data_dir>/events`` unless the environment says otherwise."""
    os.environ.setdefault(ENV, str(data_dir / "events"))


def after_analysis(log_source: LogSource, inputs: VehicleInputs, doc: dict[str, Any], *,
                   log_hash: str | None = None) -> None:
    """Write the events of ``doc`` (the analysis' stored document) to the event store when one is
    configured; never raises. ``log_hash``: the log's SHA-256 when the caller already has it."""
    root = store_dir()
    if root is None:
        return
    try:
        from app.fleet.store import write_rows  # pyarrow: loaded only when a store is configured

        if log_hash is None:
            seek = getattr(log_source, "seek", None)
            if callable(seek):  # a file object the decoder read to its end
                seek(0)
            log_hash = content_hash(log_source)
        rows = event_rows(dict(json_safe(doc)), vehicle=inputs.name or inputs.vehicle.name, log_hash=log_hash,
                          log_name=source_name(log_source), source="service", driveline=inputs.vehicle.name)
        write_rows(root, rows, source="service", log_hash=log_hash)
    except Exception as exc:  # the analysis itself succeeded; the store is a by-product
        log.warning("event store %s: events of %s not written: %s", root, log_source, exc)
