"""Work whose cost no count decided beforehand can bound runs in a child process with a CPU-time and a
memory limit (``app.bounded``): a log read with the client's own regular expression, a signal map proposed
from a stored log. Past a limit the answer is typed and names it; the server's temporary files are gone."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.bounded import run_bounded
from app.errors import FormatFileError, WorkLimitError
from app.settings import default_dbc_dir
from tests.api.attacks import backtracking_log, described_format, overlapping_dbc
from tests.api.conftest import upload
from tests.api.inprocess import in_process


def test_run_bounded_returns_the_value_or_the_typed_error(tmp_path: Path) -> None:
    limits = {"root": tmp_path, "what": "the check", "setting": "X_CPU_S", "cpu_s": 5.0, "memory_mb": 1024}
    assert run_bounded("builtins:len", "abcd", **limits) == 4
    with pytest.raises(FormatFileError) as err:
        run_bounded("app.ingest.readers.described:parse_layout", "regex = 1", "mine.toml", **limits)
    assert err.value.code == "format_file" and err.value.status == 422
    assert str(err.value).startswith("mine.toml: regex: expected str")


def test_run_bounded_stops_at_the_cpu_and_memory_limits(tmp_path: Path) -> None:
    with pytest.raises(WorkLimitError) as err:  # about 2**64 steps inside one call of the regex engine
        run_bounded("re:match", r"(a+)+$", "a" * 64 + "b", root=tmp_path, what="matching", setting="X_CPU_S",
                    cpu_s=0.5, memory_mb=1024, code="validation_limit")
    assert err.value.code == "validation_limit"
    assert str(err.value) == "matching took more than 0.5 s of CPU (X_CPU_S) and was stopped"
    with pytest.raises(WorkLimitError) as err:
        run_bounded("builtins:bytearray", 4 * 2**30, root=tmp_path, what="allocating", setting="X_CPU_S",
                    cpu_s=5.0, memory_mb=700)
    assert (err.value.code, str(err.value)) == ("work_limit", "allocating needed more than 700 MiB of memory and "
                                                              "was stopped")


def test_a_backtracking_format_description_is_stopped_at_the_validation_limit(tmp_path: Path) -> None:
    data = tmp_path / "data"
    with in_process(data, validate_cpu_s=1.0) as c:
        r = c.post("/logs", files={"file": ("bench.txt.gz", backtracking_log()),
                                   "format_file": ("bench.toml", described_format())})
        assert r.status_code == 422, r.text
        assert r.json() == {"code": "validation_limit", "detail": "reading bench.txt.gz took more than 1 s of CPU "
                                                                  "(LASHSCOPE_VALIDATE_CPU_S) and was stopped"}
        assert c.get("/logs").json() == []
        assert c.get("/health").json()["status"] == "ok"
    assert list((data / "tmp").iterdir()) == []  # the upload, its description and the child's inflated copy
    assert list((data / "logs").iterdir()) == []


def test_a_format_description_nested_too_deeply_is_a_format_error(tmp_path: Path) -> None:
    with in_process(tmp_path / "data") as c:
        r = c.post("/logs", files={"file": ("bench.txt", b"1;123;00\n"),
                                   "format_file": ("deep.toml", b"name = " + b"[" * 30_000)})
        assert (r.status_code, r.json()) == (422, {"code": "format_file", "detail": "deep.toml: not valid TOML: "
                                                   "tables or arrays nested too deeply"})


def test_a_signal_map_proposal_runs_within_limits_and_keeps_its_typed_errors(tmp_path: Path, demo_log: Path) -> None:
    data = tmp_path / "data"
    with in_process(data) as c:
        log_id = upload(c, demo_log).json()["id"]  # type: ignore[arg-type]
        r = c.post("/vehicles/signal-map-proposal", data={"log_id": log_id},
                   files={"dbc": ("crowded.dbc", overlapping_dbc(1100), "application/octet-stream")})
        assert (r.status_code, r.json()["code"]) == (422, "database_too_complex"), r.text
        assert "crowded.dbc" in r.json()["detail"] and str(data) not in r.json()["detail"]
        r = c.post("/vehicles/signal-map-proposal", data={"log_id": log_id},
                   files={"dbc": ("ev.dbc", (default_dbc_dir() / "lashscope_ev.dbc").read_bytes(),
                                  "application/octet-stream")})
        assert r.status_code == 200 and r.json()["missing"] == [], r.text
    assert list((data / "tmp").iterdir()) == []


@pytest.mark.parametrize("path", ["/identifications/id_" + "a" * 300, "/batches/ba_" + "b" * 300,
                                  "/batches/ba_" + "b" * 300 + "/logs",
                                  "/identifications/id_" + "a" * 300 + "/vehicle"])
def test_an_id_longer_than_a_file_name_is_not_found(tmp_path: Path, path: str) -> None:
    with in_process(tmp_path / "data") as c:
        for method in ("GET", "DELETE", "POST"):
            r = c.request(method, path)
            assert r.status_code in (404, 405), (method, r.status_code, r.text)
        assert c.get(path).json()["code"] in ("batch_not_found", "identification_not_found")

