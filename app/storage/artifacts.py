"""Job artefacts: what a background job was asked and what it answered, kept by the store.

The job kinds and the routes that start them read and write their artefacts only through
:class:`Artifacts` (``store.artifacts``): by artefact kind, id and part, never by file name. An
artefact kind (:data:`KINDS`) says which ids it accepts (a pattern: an id that does not match names
nothing and can reach no path), where its files live under the store's files directory, its parts
(JSON documents, and files such as plots or a vehicle file) and the schema version of its documents::

    diagnosis        <aid>--dg<hex>          analyses/<aid>/diagnoses/<id>/  status, report, charts,
                                                                             validation; PNG plots
    tolerance        <aid>/n=<n>/seed=<s>    analyses/<aid>/tolerance_n<n>_seed<s>.json
    batch            ba_<hex>                jobs/<id>/  request, summary; out/ (the batch's own output)
    identification   id_<hex>                jobs/<id>/  request, result; identified.toml
    gap_sensitivity  <vehicle>/v<version>    vehicles/<vehicle>/v<version>/gap_sensitivity.json

Every write is atomic (:mod:`app.atomic`). A document is stored in an envelope naming its kind, part
and schema version (``{"lashscope_artifact": "diagnosis/report", "version": 1, "doc": {...}}``),
versioned the way the store's rows are (:mod:`app.storage.migrations`): a document of an older version
is brought up to date on reading by its kind's ordered migrations, one newer than this program knows
is refused (``artifact_too_new``), and one older than any migration reaches is refused by name
(``artifact_too_old``). Documents written before artefacts carried a version (plain JSON, the same
content) are read as version 1, in place: data stored by earlier releases keeps working.
"""

from __future__ import annotations

import contextlib
import json
import re
import shutil
import threading
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from app import atomic
from app.errors import InputError, StorageError

ENVELOPE = "lashscope_artifact"
Migration = Callable[[dict[str, Any]], dict[str, Any]]

_ANALYSIS = r"(?P<analysis>an_[A-Za-z0-9_]{1,64})"


@dataclass(frozen=True)
class Kind:
    """An artefact kind: the ids it accepts, where its files live, its parts and its documents' version.

    ``folder`` and the file names are templates filled from the id's named groups (and ``{id}``);
    ``owned``: the folder is the artefact's own and goes with it (else only its files do).
    ``migrations[v]`` turns a document of version ``v`` into version ``v + 1``.
    """

    name: str
    pattern: str
    folder: str
    documents: Mapping[str, str]
    files: Mapping[str, str] = field(default_factory=dict)
    workdir: str | None = None
    owned: bool = True
    version: int = 1
    migrations: Mapping[int, Migration] = field(default_factory=dict)
    oldest: int = 1  # the oldest version the migrations start from

    def __post_init__(self) -> None:
        missing = [v for v in range(self.oldest, self.version) if v not in self.migrations]
        if missing:
            raise ValueError(f"artefact kind {self.name}: no migration from version(s) {missing}")

    def match(self, artifact_id: str) -> dict[str, str] | None:
        m = re.fullmatch(self.pattern, artifact_id)
        return {**m.groupdict(), "id": artifact_id} if m else None


KINDS: dict[str, Kind] = {k.name: k for k in (
    Kind("diagnosis", _ANALYSIS + r"--dg[0-9a-f]{1,32}", "analyses/{analysis}/diagnoses/{id}",
         documents={"status": "status.json", "report": "report.json", "charts": "charts.json",
                    "validation": "validation.json"},
         files={"plot_events": "diagnosis_events.png", "plot_residual": "diagnosis_residual.png"}),
    Kind("tolerance", _ANALYSIS + r"/n=(?P<n>[1-9][0-9]{0,8})/seed=(?P<seed>0|[1-9][0-9]{0,9})",
         "analyses/{analysis}", documents={"band": "tolerance_n{n}_seed{seed}.json"}, owned=False),
    Kind("batch", r"ba_[0-9a-f]{1,32}", "jobs/{id}", documents={"request": "request.json", "summary": "summary.json"},
         workdir="out"),
    Kind("identification", r"id_[0-9a-zA-Z]{1,32}", "jobs/{id}",
         documents={"request": "request.json", "result": "result.json"}, files={"vehicle": "identified.toml"}),
    Kind("gap_sensitivity", r"(?P<vehicle>[a-z0-9_-]{1,64})/v(?P<version>[1-9][0-9]{0,17})",
         "vehicles/{vehicle}/v{version}", documents={"doc": "gap_sensitivity.json"}, owned=False),
)}


class Artifacts:
    """The artefacts of a store whose files live under ``root``."""

    def __init__(self, root: Path, kinds: Mapping[str, Kind] = KINDS) -> None:
        self.root = Path(root)
        self.kinds = dict(kinds)
        self._lock = threading.Lock()  # read-merge-write of a document (update) within a process

    # -- addressing ------------------------------------------------------------------------
    def valid(self, kind: str, artifact_id: str) -> bool:
        """Whether ``artifact_id`` can name an artefact of ``kind``."""
        k = self.kinds.get(kind)
        return k is not None and k.match(artifact_id) is not None

    def _where(self, kind: str, artifact_id: str) -> tuple[Kind, dict[str, str], Path]:
        k = self.kinds.get(kind)
        if k is None:
            raise InputError(f"no artefact kind {kind!r} (known: {', '.join(sorted(self.kinds))})",
                             code="invalid_artifact_id")
        groups = k.match(artifact_id)
        if groups is None:
            raise InputError(f"{artifact_id[:80]!r} is not a {kind} id", code="invalid_artifact_id")
        return k, groups, self.root / k.folder.format(**groups)

    def _path(self, kind: str, artifact_id: str, part: str, table: str) -> tuple[Kind, Path]:
        k, groups, folder = self._where(kind, artifact_id)
        names = k.documents if table == "documents" else k.files
        if part not in names:
            raise InputError(f"a {kind} has no {table[:-1]} {part!r} (it has {', '.join(names)})",
                             code="invalid_artifact_part")
        return k, folder / names[part].format(**groups)

    # -- documents -------------------------------------------------------------------------
    def get(self, kind: str, artifact_id: str, part: str) -> dict[str, Any] | None:
        """The document, brought to its kind's current version; None when it was never written (or the id
        names nothing)."""
        if not self.valid(kind, artifact_id):
            return None
        k, path = self._path(kind, artifact_id, part, "documents")
        try:
            raw = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            return None
        except (OSError, ValueError) as exc:
            raise StorageError(f"the stored {kind} {part} of {artifact_id} cannot be read: {exc}",
                               code="artifact_unreadable") from exc
        return _current(k, part, artifact_id, raw)

    def put(self, kind: str, artifact_id: str, part: str, doc: Mapping[str, Any]) -> None:
        """Store ``doc`` (replacing the part's earlier document) at the kind's current version, atomically."""
        k, path = self._path(kind, artifact_id, part, "documents")
        envelope = {ENVELOPE: f"{kind}/{part}", "version": k.version, "doc": dict(doc)}
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic.write_text(path, json.dumps(envelope, indent=1, allow_nan=False, default=str))

    def update(self, kind: str, artifact_id: str, part: str, **fields: Any) -> dict[str, Any]:
        """Merge ``fields`` into the document (one atomic rewrite); returns the new document."""
        with self._lock:
            doc = self.get(kind, artifact_id, part) or {}
            doc.update(fields)
            self.put(kind, artifact_id, part, doc)
        return doc

    def has(self, kind: str, artifact_id: str, part: str) -> bool:
        if not self.valid(kind, artifact_id):
            return False
        k = self.kinds[kind]
        table = "documents" if part in k.documents else "files"
        return self._path(kind, artifact_id, part, table)[1].is_file()

    # -- files (plots, vehicle files) ------------------------------------------------------
    def file(self, kind: str, artifact_id: str, part: str) -> Path | None:
        """The stored file of a part (to serve or read), None when absent or the id names nothing."""
        if not self.valid(kind, artifact_id):
            return None
        path = self._path(kind, artifact_id, part, "files")[1]
        return path if path.is_file() else None

    @contextlib.contextmanager
    def writing(self, kind: str, artifact_id: str, part: str) -> Iterator[Path]:
        """A path to write a file part to (a plotting library takes a file name; the path ends like the part's
        file, e.g. ``.png``); it replaces the part atomically when the block ends without an error."""
        path = self._path(kind, artifact_id, part, "files")[1]
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic.atomic_path(path, suffix=path.suffix) as tmp:
            yield tmp

    def put_text(self, kind: str, artifact_id: str, part: str, text: str) -> None:
        with self.writing(kind, artifact_id, part) as tmp:
            tmp.write_text(text, encoding="utf-8")

    # -- the rest --------------------------------------------------------------------------
    def workdir(self, kind: str, artifact_id: str) -> Path:
        """The folder where a kind's job writes output of its own format (a batch's records and events)."""
        k, _, folder = self._where(kind, artifact_id)
        if k.workdir is None:
            raise InputError(f"a {kind} has no working folder", code="invalid_artifact_part")
        return folder / k.workdir

    def delete(self, kind: str, artifact_id: str) -> None:
        """Remove an artefact: its folder when it owns one, else its parts' files. Unknown ids: nothing."""
        if not self.valid(kind, artifact_id):
            return
        k, groups, folder = self._where(kind, artifact_id)
        if k.owned:
            shutil.rmtree(folder, ignore_errors=True)
            return
        for name in (*k.documents.values(), *k.files.values()):
            (folder / name.format(**groups)).unlink(missing_ok=True)


def _current(k: Kind, part: str, artifact_id: str, raw: Any) -> dict[str, Any]:
    """A stored document at the kind's current version (see the module's docstring)."""
    if isinstance(raw, dict) and ENVELOPE in raw:
        version, doc = raw.get("version"), raw.get("doc")
        if not isinstance(version, int) or not isinstance(doc, dict):
            raise StorageError(f"the stored {k.name} {part} of {artifact_id} has no readable version",
                               code="artifact_unreadable")
    elif isinstance(raw, dict):
        version, doc = 1, raw  # written before artefacts carried a version: version 1's content
    else:
        raise StorageError(f"the stored {k.name} {part} of {artifact_id} is not a document", code="artifact_unreadable")
    if version > k.version:
        raise StorageError(f"the stored {k.name} {part} of {artifact_id} is version {version}, newer than this "
                           f"lashscope knows (up to {k.version}); upgrade lashscope", code="artifact_too_new")
    if version < k.oldest:
        raise StorageError(f"the stored {k.name} {part} of {artifact_id} is version {version}, older than this "
                           f"lashscope reads (from {k.oldest}); run it again", code="artifact_too_old")
    while version < k.version:
        doc = k.migrations[version](doc)
        version += 1
    return doc
