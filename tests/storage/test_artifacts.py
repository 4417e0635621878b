"""Job artefacts behind the store (``store.artifacts``) on both backends: round trips, the layout earlier
releases wrote (plain JSON at the same places) read in place, schema versions (newer refused, older migrated
or refused by name), and ids that cannot name an artefact reach no path."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from app.errors import InputError, StorageError
from app.storage.artifacts import ENVELOPE, KINDS, Artifacts, Kind
from app.storage.sqlstore import SQLStore

DID = "an_0123456789abcdef--dg0a1b2c3d"
TOL = "an_0123456789abcdef/n=10/seed=3"


def test_documents_round_trip_update_and_delete(store: SQLStore, tmp_path: Path) -> None:
    art = store.artifacts
    assert art.get("diagnosis", DID, "status") is None and not art.has("diagnosis", DID, "status")
    art.put("diagnosis", DID, "status", {"id": DID, "options": {"seed": 0}})
    art.put("diagnosis", DID, "report", {"decision": {"status": "explained"}, "x": [1.5, None]})
    assert art.get("diagnosis", DID, "status") == {"id": DID, "options": {"seed": 0}}
    assert art.update("diagnosis", DID, "status", decision="explained") == {
        "id": DID, "options": {"seed": 0}, "decision": "explained"}
    assert art.get("diagnosis", DID, "status")["decision"] == "explained"
    assert art.get("diagnosis", DID, "report") == {"decision": {"status": "explained"}, "x": [1.5, None]}
    stored = json.loads((tmp_path / "analyses" / "an_0123456789abcdef" / "diagnoses" / DID / "report.json").read_text())
    assert stored[ENVELOPE] == "diagnosis/report" and stored["version"] == KINDS["diagnosis"].version
    art.put("tolerance", TOL, "band", {"events": [{"p50": 2.0}]})
    assert art.get("tolerance", TOL, "band") == {"events": [{"p50": 2.0}]}
    art.delete("diagnosis", DID)
    assert art.get("diagnosis", DID, "report") is None and art.get("diagnosis", DID, "status") is None
    assert not (tmp_path / "analyses" / "an_0123456789abcdef" / "diagnoses" / DID).exists()
    # a tolerance band does not own the analysis' folder: deleting it leaves its neighbours
    (tmp_path / "analyses" / "an_0123456789abcdef" / "result.json").write_text("{}", encoding="utf-8")
    art.delete("tolerance", TOL)
    assert art.get("tolerance", TOL, "band") is None
    assert (tmp_path / "analyses" / "an_0123456789abcdef" / "result.json").is_file()


def test_files_are_written_atomically_with_their_ending(store: SQLStore) -> None:
    art = store.artifacts
    assert art.file("diagnosis", DID, "plot_events") is None
    with art.writing("diagnosis", DID, "plot_events") as tmp:
        assert tmp.suffix == ".png" and tmp.parent.is_dir()  # a plotting library picks the format by the name
        tmp.write_bytes(b"\x89PNG one")
    first = art.file("diagnosis", DID, "plot_events")
    assert first is not None and first.read_bytes() == b"\x89PNG one"
    with pytest.raises(RuntimeError), art.writing("diagnosis", DID, "plot_events") as tmp:
        tmp.write_bytes(b"half")
        raise RuntimeError("the plot failed")
    assert first.read_bytes() == b"\x89PNG one"
    assert sorted(p.name for p in first.parent.iterdir()) == ["diagnosis_events.png"]  # no temporary left
    art.put_text("identification", "id_0011aabb", "vehicle", "[vehicle]\nname = 'ev'\n")
    path = art.file("identification", "id_0011aabb", "vehicle")
    assert path is not None and path.read_text(encoding="utf-8") == "[vehicle]\nname = 'ev'\n"
    assert art.has("identification", "id_0011aabb", "vehicle")


def test_a_batch_has_a_working_folder_beside_its_documents(store: SQLStore, tmp_path: Path) -> None:
    art = store.artifacts
    art.put("batch", "ba_00ff", "request", {"log_ids": ["log_1"]})
    assert art.workdir("batch", "ba_00ff") == tmp_path.resolve() / "jobs" / "ba_00ff" / "out"
    with pytest.raises(InputError):
        art.workdir("diagnosis", DID)
    art.workdir("batch", "ba_00ff").mkdir()
    art.delete("batch", "ba_00ff")
    assert not (tmp_path / "jobs" / "ba_00ff").exists() and art.get("batch", "ba_00ff", "request") is None


def _write(path: Path, doc: object) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=1), encoding="utf-8")


def test_the_layout_earlier_releases_wrote_is_read_in_place(store: SQLStore, tmp_path: Path) -> None:
    """Plain JSON files where the job kinds used to write them come back through the store, unchanged."""
    d = tmp_path / "analyses" / "an_0123456789abcdef" / "diagnoses" / DID
    _write(d / "status.json", {"id": DID, "job_id": "job_1", "options": {"seed": 4}})
    _write(d / "report.json", {"schema": "lashscope.diagnosis/1", "decision": {"status": "partial"}})
    _write(d / "validation.json", {"log_id": "log_2", "job_id": "job_2", "shrink": 0.4})
    _write(d / "charts.json", {"schema": "lashscope.diagnosis-charts/1"})
    (d / "diagnosis_residual.png").write_bytes(b"\x89PNG")
    _write(tmp_path / "analyses" / "an_0123456789abcdef" / "tolerance_n10_seed3.json", {"n": 10, "seed": 3})
    _write(tmp_path / "jobs" / "ba_00ff" / "request.json", {"log_ids": ["log_1"], "vehicle": "ev"})
    _write(tmp_path / "jobs" / "ba_00ff" / "summary.json", {"logs": 1, "ok": 1})
    _write(tmp_path / "jobs" / "id_00aa" / "request.json", {"log_ids": ["log_1"], "params": ["lash"]})
    _write(tmp_path / "jobs" / "id_00aa" / "result.json", {"named": ["lash"]})
    (tmp_path / "jobs" / "id_00aa" / "identified.toml").write_text("[vehicle]\n", encoding="utf-8")
    _write(tmp_path / "vehicles" / "ev" / "v2" / "gap_sensitivity.json", {"format": 2, "name": "ev"})

    art = store.artifacts
    assert art.get("diagnosis", DID, "status") == {"id": DID, "job_id": "job_1", "options": {"seed": 4}}
    assert art.get("diagnosis", DID, "report") == {"schema": "lashscope.diagnosis/1",
                                                   "decision": {"status": "partial"}}
    assert art.get("diagnosis", DID, "validation")["shrink"] == 0.4
    assert art.get("diagnosis", DID, "charts") == {"schema": "lashscope.diagnosis-charts/1"}
    assert art.has("diagnosis", DID, "plot_residual") and not art.has("diagnosis", DID, "plot_events")
    assert art.get("tolerance", TOL, "band") == {"n": 10, "seed": 3}
    assert art.get("batch", "ba_00ff", "request") == {"log_ids": ["log_1"], "vehicle": "ev"}
    assert art.get("batch", "ba_00ff", "summary") == {"logs": 1, "ok": 1}
    assert art.get("identification", "id_00aa", "request")["params"] == ["lash"]
    assert art.get("identification", "id_00aa", "result") == {"named": ["lash"]}
    assert art.file("identification", "id_00aa", "vehicle") == tmp_path.resolve() / "jobs/id_00aa/identified.toml"
    assert art.get("gap_sensitivity", "ev/v2", "doc") == {"format": 2, "name": "ev"}
    # an old document updated is written in the versioned form, its content kept
    art.update("diagnosis", DID, "status", applied={"vehicle": "ev", "version": 3})
    raw = json.loads((d / "status.json").read_text(encoding="utf-8"))
    assert raw[ENVELOPE] == "diagnosis/status" and raw["doc"]["options"] == {"seed": 4}
    assert raw["doc"]["applied"] == {"vehicle": "ev", "version": 3}


def test_a_document_newer_than_this_program_is_refused(store: SQLStore, tmp_path: Path) -> None:
    path = tmp_path / "jobs" / "ba_00ff" / "request.json"
    _write(path, {ENVELOPE: "batch/request", "version": KINDS["batch"].version + 1, "doc": {"log_ids": []}})
    with pytest.raises(StorageError) as err:
        store.artifacts.get("batch", "ba_00ff", "request")
    assert err.value.code == "artifact_too_new" and "upgrade lashscope" in str(err.value)
    _write(path, {ENVELOPE: "batch/request", "version": "two", "doc": {}})
    with pytest.raises(StorageError) as err:
        store.artifacts.get("batch", "ba_00ff", "request")
    assert err.value.code == "artifact_unreadable"
    path.write_text("{half a docu", encoding="utf-8")
    with pytest.raises(StorageError) as err:
        store.artifacts.get("batch", "ba_00ff", "request")
    assert err.value.code == "artifact_unreadable" and "ba_00ff" in str(err.value)


def test_older_documents_are_migrated_in_order_or_refused_by_name(tmp_path: Path) -> None:
    """A kind at version 3 whose migrations start at 2: a version 2 document goes through 2 -> 3, a
    version-1 (or unversioned) one is refused by name; writing stores version 3."""
    kind = Kind("note", r"n_[0-9]+", "notes/{id}", documents={"doc": "doc.json"}, version=3, oldest=2,
                migrations={2: lambda d: {**{k: v for k, v in d.items() if k != "gap"}, "gap_m": d["gap"] / 1000}})
    art = Artifacts(tmp_path, {"note": kind})
    _write(tmp_path / "notes" / "n_1" / "doc.json", {ENVELOPE: "note/doc", "version": 2, "doc": {"gap": 2.5}})
    assert art.get("note", "n_1", "doc") == {"gap_m": 0.0025}
    _write(tmp_path / "notes" / "n_2" / "doc.json", {"gap": 2.5})  # before versions: version 1
    with pytest.raises(StorageError) as err:
        art.get("note", "n_2", "doc")
    assert err.value.code == "artifact_too_old" and "version 1" in str(err.value)
    art.put("note", "n_3", "doc", {"gap_m": 0.001})
    assert json.loads((tmp_path / "notes" / "n_3" / "doc.json").read_text())["version"] == 3
    with pytest.raises(ValueError, match="no migration"):
        Kind("bad", r"b", "b", documents={"doc": "doc.json"}, version=2)


@pytest.mark.parametrize(("kind", "bad"), [
    ("diagnosis", "../../etc--dg00"), ("diagnosis", "an_1--dg00/../../x"), ("diagnosis", "an_1--dgXYZ"),
    ("diagnosis", "an_1.--dg00"), ("tolerance", "an_1/n=0/seed=0"), ("tolerance", "an_1/n=1/seed=../x"),
    ("batch", "ba_../x"), ("batch", "id_00"), ("identification", "id_/"), ("identification", "id_a\x00b"),
    ("gap_sensitivity", "EV/v1"), ("gap_sensitivity", "ev/v0"), ("gap_sensitivity", "../ev/v1"), ("batch", ""),
])
def test_an_id_that_names_no_artefact_reaches_no_path(store: SQLStore, tmp_path: Path, kind: str, bad: str) -> None:
    before = sorted(tmp_path.rglob("*"))
    art = store.artifacts
    part = next(iter(KINDS[kind].documents))
    assert not art.valid(kind, bad)
    assert art.get(kind, bad, part) is None and not art.has(kind, bad, part)
    with pytest.raises(InputError) as err:
        art.put(kind, bad, part, {"x": 1})
    assert err.value.code == "invalid_artifact_id"
    art.delete(kind, bad)
    assert sorted(tmp_path.rglob("*")) == before


def test_unknown_kinds_and_parts_are_typed_errors(store: SQLStore) -> None:
    with pytest.raises(InputError) as err:
        store.artifacts.put("nonsense", "x", "doc", {})
    assert err.value.code == "invalid_artifact_id" and "diagnosis" in str(err.value)
    with pytest.raises(InputError) as err:
        store.artifacts.put("batch", "ba_00", "result", {})
    assert err.value.code == "invalid_artifact_part" and "request" in str(err.value)
