"""Smaller holes closed: HEAD, oversized vehicle texts and error messages, local port probes through the
loopback hub, internal paths in live status, a full data volume during an analysis, absurd analysis options."""

from __future__ import annotations

import contextlib
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from app.api.errors import MAX_DETAIL_CHARS, short_detail
from sim import dump_toml, load_vehicle
from tests.api.conftest import upload, wait_for
from tests.api.inprocess import TestClient, in_process

PAPER = dump_toml(load_vehicle("paper"))


@pytest.fixture
def client(tmp_path: Path) -> Iterator[TestClient]:
    with in_process(tmp_path / "data") as c:
        yield c


def _error(r: object, status: int, code: str) -> str:
    assert r.status_code == status, r.text  # type: ignore[attr-defined]
    body = r.json()  # type: ignore[attr-defined]
    assert body["code"] == code, body
    detail: str = body["detail"]
    return detail


def test_head_answers_every_get_route_with_headers_only(client: TestClient) -> None:
    assert client.post("/vehicles", data={"name": "ev", "preset": "paper"}).status_code == 201
    for path in ("/health", "/vehicles", "/vehicles/ev", "/logs", "/openapi.json", "/"):
        got, head = client.get(path), client.head(path)
        assert head.status_code == got.status_code == 200, (path, head.status_code)
        assert head.content == b"" and head.headers["content-type"] == got.headers["content-type"]
        if "content-length" in got.headers and "content-encoding" not in got.headers:
            assert head.headers["content-length"] == got.headers["content-length"], path
    assert client.head("/vehicles/nope").status_code == 404
    assert client.head("/analyses/an_0/tolerance").status_code == 404
    _error(client.request("PUT", "/vehicles"), 405, "method_not_allowed")  # HEAD only where GET is


def test_vehicle_texts_are_capped_and_listings_stay_small(client: TestClient) -> None:
    huge = PAPER.replace('description = "', 'description = "' + "x" * 3_000_000, 1)
    r = client.post("/vehicles", data={"name": "big"}, files={"driveline": ("big.toml", huge.encode())})
    assert "256 KiB" in _error(r, 413, "vehicle_file_too_large")  # refused by its size before it is parsed
    long = PAPER.replace('description = "', 'description = "' + "x" * 100_000, 1)
    r = client.post("/vehicles", data={"name": "big"}, files={"driveline": ("big.toml", long.encode())})
    detail = _error(r, 422, "invalid_parameter")
    assert detail.startswith("description = ") and "at most 4000 characters" in detail and len(detail) < 500
    long_name = PAPER.replace('name = "paper"', f'name = "{"n" * 300}"', 1)
    r = client.post("/vehicles", data={"name": "long"}, files={"driveline": ("long.toml", long_name.encode())})
    assert _error(r, 422, "invalid_parameter").startswith("name = ")
    # the longest allowed description is returned whole for the vehicle, cut in the listings
    ok = PAPER.replace('description = "', 'description = "' + "y" * 3900, 1)
    assert client.post("/vehicles", data={"name": "ok"}, files={"driveline": ("ok.toml", ok.encode())}).status_code \
        == 201
    assert len(client.get("/vehicles/ok").json()["summary"]["description"]) > 3900
    for listing in (client.get("/vehicles").json(), client.get("/vehicles/ok/versions").json()):
        (item,) = listing
        assert len(item["summary"]["description"]) == 203 and item["summary"]["description"].endswith("...")


def test_a_contact_law_that_is_not_one_is_refused_by_name(client: TestClient) -> None:
    """``contact_damping`` (a word, not a number): a long string or a table is a short one-line error naming the
    field, nothing is stored; a right one is stored and read back."""
    for value in ('"' + "f" * 200_000 + '"', "{law = 'full'}", "3"):
        body = f"contact_damping = {value}\n" + PAPER
        r = client.post("/vehicles", data={"name": "law"}, files={"driveline": ("law.toml", body.encode())})
        detail = _error(r, 422, "invalid_parameter")
        assert detail.startswith("contact_damping = ") and "'limited', 'full'" in detail and len(detail) < 500
    assert client.get("/vehicles/law").status_code == 404
    body = 'contact_damping = "full"\n' + PAPER
    assert client.post("/vehicles", data={"name": "law"}, files={"driveline": ("law.toml", body.encode())}) \
        .status_code == 201
    assert 'contact_damping = "full"' in client.get("/vehicles/law/versions/1/driveline").text


def test_error_messages_are_capped(client: TestClient) -> None:
    """Thousands of keys where a table belongs: the message names a dozen, not all of them (half a million made a
    9 MB message; such a file is now refused by its size, vehicle_file_too_large)."""
    body = f"stages = {{ {', '.join(f'k{i} = {i}' for i in range(15_000))} }}\n" + PAPER
    r = client.post("/vehicles", data={"name": "keys"}, files={"driveline": ("keys.toml", body.encode())})
    detail = _error(r, 422, "invalid_parameter")
    assert detail.startswith("stages = {'k0': 0, 'k1': 1,") and "..." in detail and len(r.content) < 1000
    # and whatever an error quotes, the answer carries at most MAX_DETAIL_CHARS of it
    cut = short_detail("x" * 1_000_000)
    assert len(cut) < MAX_DETAIL_CHARS + 100 and cut.endswith(f"({1_000_000 - MAX_DETAIL_CHARS} more characters "
                                                              "left out)")
    assert short_detail("short") == "short"


@contextlib.contextmanager
def _banner_service() -> Iterator[int]:
    """A local TCP service that greets every connection with a banner (as SSH or SMTP do)."""
    srv = socket.create_server(("127.0.0.1", 0))
    srv.settimeout(0.2)
    stop = threading.Event()

    def serve() -> None:
        while not stop.is_set():
            try:
                conn, _ = srv.accept()
            except OSError:
                continue
            with conn:
                conn.sendall(b"SSH-2.0-OpenSSH_9.9 secret-banner\r\n")
                time.sleep(0.1)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield int(srv.getsockname()[1])
    finally:
        stop.set()
        thread.join(2)
        srv.close()


def test_the_loopback_interface_cannot_probe_local_ports(tmp_path: Path) -> None:
    start = {"database": "lashscope_ev.dbc", "interface": "tcp_loopback"}
    with _banner_service() as port, in_process(tmp_path / "data") as c:
        detail = _error(c.post("/live/sessions", json={**start, "channel": f"127.0.0.1:{port}"}), 403,
                        "live_channel_not_allowed")
        assert "secret" not in detail and "SSH" not in detail
        _error(c.post("/live/sessions", json={**start, "channel": f"localhost:{port}"}), 403,
               "live_channel_not_allowed")
        _error(c.post("/live/sessions", json={**start, "channel": "10.0.0.1:29536"}), 400, "invalid_input")
        # the default hub port is allowed however it is written (nothing listens there in this test)
        for channel in ("127.0.0.1:29536", "localhost", None):
            r = c.post("/live/sessions", json={**start, "channel": channel})
            assert r.status_code != 403, r.text
    # an operator who allows every port still gets no banner back
    with _banner_service() as port, in_process(tmp_path / "open", live_channels=["tcp_loopback:*"]) as c:
        r = c.post("/live/sessions", json={**start, "channel": f"127.0.0.1:{port}"})
        assert r.status_code == 503 and "secret" not in r.text and "SSH" not in r.text, r.text


def test_live_status_names_the_recording_not_where_it_is(client: TestClient, tmp_path: Path) -> None:
    r = client.post("/live/sessions", json={"database": "lashscope_ev.dbc", "interface": "virtual",
                                            "channel": "status"})
    assert r.status_code == 201, r.text
    sid = r.json()["id"]
    for status in (r.json(), client.get(f"/live/sessions/{sid}").json()):
        assert status["recording"] == f"live-{sid}.blf"
        assert str(tmp_path) not in str(status)
    stopped = client.post(f"/live/sessions/{sid}/stop").json()
    assert str(tmp_path) not in str(stopped)


@pytest.mark.parametrize("options, field", [
    ({"events": {"post_s": 1e9}}, "events.post_s"),
    ({"events": {"step_after_s": [0.15, 1e6]}}, "events.step_after_s"),
    ({"metrics": {"lash": {"pre_s": 50}}}, "metrics.lash.pre_s"),
    ({"tracking": {"drift_window_s": 1e300}}, "tracking.drift_window_s"),
    ({"metrics": {"min_prominence_rpm": float("inf")}}, "metrics.min_prominence_rpm"),
])
def test_analysis_options_out_of_range_are_400(client: TestClient, options: dict[str, object], field: str) -> None:
    body = {"log_id": "log_0", "vehicle": "ev", "options": options}
    r = client.post("/analyses", content=_json(body), headers={"content-type": "application/json"})
    assert field in _error(r, 400, "invalid_input")


def _json(body: object) -> bytes:
    """JSON as Python writes it (``Infinity`` included, which httpx's own encoder refuses)."""
    import json

    return json.dumps(body).encode()


@contextlib.contextmanager
def _small_volume(where: Path, size: str) -> Iterator[Path]:
    """A tmpfs of ``size`` mounted at ``where`` (skips where mounting is not permitted)."""
    where.mkdir(parents=True)
    try:
        subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)], check=True,
                       capture_output=True, timeout=30)
    except (OSError, subprocess.SubprocessError) as exc:
        pytest.skip(f"cannot mount a small volume here ({type(exc).__name__}): needs root")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], check=False, capture_output=True, timeout=30)


def _fill(volume: Path) -> None:
    """Write ``volume`` full."""
    with (volume / "filler").open("wb") as f, contextlib.suppress(OSError):
        while True:
            f.write(b"\0" * (1 << 16))
            f.flush()


def test_a_full_volume_fails_the_analysis_with_507(tmp_path: Path, demo_log: Path) -> None:
    """The data volume fills while the analysis runs: it fails as ``storage_full``, and reading it is 507."""
    with _small_volume(tmp_path / "volume", "24m") as files:
        url = f"sqlite:///{tmp_path}/db/lashscope.sqlite3?files={files}"
        (tmp_path / "db").mkdir()
        with in_process(tmp_path / "data", store_url=url) as c:
            assert c.post("/vehicles", data={"name": "ev", "preset": "paper"}).status_code == 201
            log_id = upload(c, demo_log).json()["id"]  # type: ignore[arg-type]
            _fill(files)
            analysis_id = c.post("/analyses", json={"log_id": log_id, "vehicle": "ev"}).json()["id"]
            done = wait_for(c, analysis_id)  # type: ignore[arg-type]
            assert done["status"] == "failed"
            error = done["job"]["error"]  # type: ignore[index]
            assert error["code"] == "storage_full" and "None" not in error["detail"], error
            assert str(files) not in error["detail"]
            detail = _error(c.get(f"/analyses/{analysis_id}/events"), 507, "storage_full")
            assert str(files) not in detail
