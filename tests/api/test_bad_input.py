"""Bad uploads and bad vehicles get typed JSON errors, and the server keeps serving."""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.api.conftest import Server, create_vehicle, upload, wait_for
from tests.conftest import shared_file


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    """One server for this module's tests: each leaves it serving, which is part of what they check."""
    srv = Server(tmp_path_factory.mktemp("bad") / "data").start()
    yield srv
    srv.stop()


INTERNAL_NAME = re.compile(r"[0-9a-f]{32}|/tmp/|lashscope-data")


def _assert_error(r: httpx.Response, status: int, code: str) -> None:
    assert r.status_code == status, r.text
    body = r.json()
    assert set(body) == {"detail", "code"} and body["code"] == code and body["detail"]
    assert not INTERNAL_NAME.search(body["detail"]), f"error names an internal file: {body['detail']}"


def test_missing_file_field(server: Server) -> None:
    with httpx.Client(base_url=server.url, timeout=60.0) as c:
        for r in (c.post("/logs"), c.post("/logs", files={"note": (None, "no file here")})):
            _assert_error(r, 400, "missing_file")
            assert "missing multipart field 'file'" in r.json()["detail"]


def test_bad_uploads(server: Server, tmp_path: Path, demo_log: Path) -> None:
    with httpx.Client(base_url=server.url, timeout=60.0) as c:
        junk = tmp_path / "junk.blf"
        junk.write_bytes(os.urandom(20000))
        r = upload(c, junk)
        _assert_error(r, 415, "unsupported_format")
        assert "junk.blf" in r.json()["detail"]

        broken = tmp_path / "broken.blf"
        raw = demo_log.read_bytes()
        broken.write_bytes(raw[:200] + os.urandom(3000))  # a BLF header with garbage behind it
        r = upload(c, broken)
        assert r.status_code in (201, 422), r.text
        if r.status_code == 422:
            assert r.json()["code"].startswith("log_")
        else:
            assert r.json()["issues"], "a damaged log that is kept must report its damage"

        empty = tmp_path / "empty.asc"
        empty.write_bytes(b"")
        assert upload(c, empty).status_code in (400, 422)

        big = tmp_path / "big.blf"
        big.write_bytes(raw[:4096] + os.urandom(5 * 2**20))  # over the 4 MiB cap of the test server
        _assert_error(upload(c, big), 413, "upload_too_large")
        with big.open("rb") as fh:
            _assert_error(c.post("/logs", params={"filename": "big.blf"}, content=fh.read()), 413,
                          "upload_too_large")
        assert list((server.data_dir / "tmp").iterdir()) == []  # partial files removed
        assert all(x["filename"] != "big.blf" for x in c.get("/logs").json())

        _assert_error(c.post("/analyses", json={"log_id": "log_nope", "vehicle": "ev"}), 404, "not_found")
        _assert_error(c.post("/analyses", json={"vehicle": "ev"}), 422, "validation_error")
        assert c.get("/health").json()["status"] == "ok"


def test_wrong_dbc_bad_map_and_missing_signals(server: Server, tmp_path: Path) -> None:
    with httpx.Client(base_url=server.url, timeout=60.0) as c:
        bad = tmp_path / "bad.dbc"
        bad.write_text("BO_ this is not a database\n")
        r = c.post("/vehicles", data={"name": "x", "preset": "paper"}, files={"dbc": ("bad.dbc", bad.read_bytes())})
        _assert_error(r, 422, "database_error")
        r = c.post("/vehicles", data={"name": "x", "preset": "paper"},
                   files={"dbc": ("notes.md", b"# meeting notes\nnot a database\n")})
        assert r.status_code in (415, 422), r.text
        _assert_error(r, r.status_code, r.json()["code"])
        assert "notes.md" in r.json()["detail"]

        other = shared_file("cantools-testfiles", "dbc", "abs.dbc")  # loads fine, but not this vehicle's DBC
        r = c.post("/vehicles", data={"name": "x", "preset": "paper"},
                   files={"dbc": ("abs.dbc", other.read_bytes())})
        _assert_error(r, 422, "signal_map_error")

        toml = tmp_path / "car.toml"
        toml.write_text('name = "car"\n[motor]\nrotor_inertia = -1.0\n')
        r = c.post("/vehicles", data={"name": "x"}, files={"driveline": ("car.toml", toml.read_bytes())})
        assert r.status_code == 422 and r.json()["code"] in ("invalid_parameter", "sim_error")
        _assert_error(c.post("/vehicles", data={"preset": "paper"}), 400, "invalid_input")

        # a real log from another vehicle: decodes nothing the signal map needs
        create_vehicle(c)
        foreign = shared_file("python-can-testdata", "test", "data", "issue_1905.blf")
        r = upload(c, foreign)
        assert r.status_code == 201, r.text
        analysis = c.post("/analyses", json={"log_id": r.json()["id"], "vehicle": "ev"}).json()
        body = wait_for(c, analysis["id"])
        job: Any = body["job"]
        assert body["status"] == "failed" and job["error"]["code"] == "missing_signal"
        detail = job["error"]["detail"]
        assert "issue_1905.blf" in detail and not INTERNAL_NAME.search(detail), detail
        _assert_error(c.get(f"/analyses/{analysis['id']}/metrics"), 422, "missing_signal")
        _assert_error(c.post("/analyses", json={"log_id": r.json()["id"], "vehicle": "ev",
                                                "options": {"model": "quantum"}}), 400, "invalid_input")
        assert c.get("/health").status_code == 200


def test_unknown_resources_are_json_404(server: Server) -> None:
    for path in ("/logs/nope", "/vehicles/nope", "/analyses/nope", "/analyses/nope/speed", "/nope"):
        _assert_error(httpx.get(server.url + path), 404, "not_found")
    _assert_error(httpx.put(server.url + "/logs"), 405, "method_not_allowed")
