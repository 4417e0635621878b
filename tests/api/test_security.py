"""Access control in front of every route: Host allow-list, same-origin writes, API keys with scopes."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from app.api.security import KEYS_RECHECK_S, host_name, is_loopback
from app.cli import main
from app.cli.serve import refuse_open_network
from app.errors import ForbiddenError
from app.settings import Settings
from tests.api.inprocess import TestClient, in_process


@pytest.fixture
def client(tmp_path: Path, store_url: str) -> Iterator[TestClient]:
    """The app on each store backend (``store_url``: SQLite, PostgreSQL)."""
    with in_process(tmp_path / "data", store_url=store_url, cors_origins=["http://dashboard.test"]) as c:
        yield c


def _error(r: object, status: int, code: str) -> dict[str, str]:
    assert r.status_code == status, r.text  # type: ignore[attr-defined]
    body: dict[str, str] = r.json()  # type: ignore[attr-defined]
    assert body["code"] == code, body
    return body


def test_host_names() -> None:
    assert [host_name(h) for h in ("[::1]:8000", "LocalHost:80", "example.org", "::1")] == [
        "::1", "localhost", "example.org", "::1"]
    assert is_loopback("127.0.0.2") and is_loopback("[::1]") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("10.0.0.1") and not is_loopback("example.org")


def test_without_keys_reads_are_open_and_writes_same_origin(client: TestClient) -> None:
    assert client.get("/logs").json() == []
    for host in ("localhost:8000", "127.0.0.1", "[::1]:8000", "testserver"):
        assert client.get("/health", headers={"Host": host}).status_code == 200
    # DNS rebinding: a page served as evil.test that resolves to 127.0.0.1 sends its own name
    body = _error(client.get("/logs", headers={"Host": "evil.test"}), 400, "host_not_allowed")
    assert "evil.test" in body["detail"]
    # CSRF: a cross-origin form post from a browser is refused before anything is read or stored
    for headers in ({"Origin": "http://evil.test"}, {"Sec-Fetch-Site": "cross-site"}, {"Origin": "null"},
                    {"Sec-Fetch-Site": "same-site"}):
        _error(client.post("/vehicles", data={"name": "x", "preset": "paper"}, headers=headers), 403, "cross_origin")
        _error(client.delete("/logs/log_0", headers=headers), 403, "cross_origin")
    assert client.get("/vehicles").json() == []
    # the service's own origin, a configured CORS origin and tools without Origin may write
    ok = [{"Origin": "http://testserver", "Sec-Fetch-Site": "same-origin"}, {"Origin": "http://dashboard.test"}, {}]
    for i, headers in enumerate(ok):
        r = client.post("/vehicles", data={"name": f"ev{i}", "preset": "paper"}, headers=headers)
        assert r.status_code == 201, r.text
    assert len(client.get("/vehicles").json()) == 3
    # a key that does not exist is refused even while none are required
    _error(client.get("/logs", headers={"Authorization": "Bearer lsk_0_x"}), 401, "invalid_key")


def test_keys_and_scopes(client: TestClient) -> None:
    store = client.app.state.store  # type: ignore[attr-defined]
    keys = {scope: store.create_key(scope)[1] for scope in ("read", "write", "admin")}
    time.sleep(KEYS_RECHECK_S + 0.1)  # the guard notices new keys within a second

    def auth(scope: str) -> dict[str, str]:
        return {"Authorization": f"Bearer {keys[scope]}"}

    r = client.get("/logs")
    _error(r, 401, "auth_required")
    assert r.headers["www-authenticate"].startswith("Bearer")
    assert client.get("/health").status_code == 200 and client.get("/openapi.json").status_code == 200
    # the dashboard page and its files load without a key (the page asks for one); its data calls do not
    assert client.get("/").status_code == 200 and client.get("/static/js/app.js").status_code == 200
    _error(client.get("/logs", headers={"Authorization": f"Bearer {keys['read']}x"}), 401, "invalid_key")
    _error(client.get("/logs", headers={"Authorization": f"Basic {keys['read']}"}), 401, "invalid_key")
    assert client.get("/logs", headers=auth("read")).json() == []
    body = _error(client.post("/vehicles", data={"name": "ev", "preset": "paper"}, headers=auth("read")), 403,
                  "insufficient_scope")
    assert "'write'" in body["detail"]
    assert client.post("/vehicles", data={"name": "ev", "preset": "paper"}, headers=auth("write")).status_code == 201
    _error(client.delete("/logs/log_0", headers=auth("write")), 403, "insufficient_scope")
    _error(client.delete("/logs/log_0", headers=auth("admin")), 404, "not_found")
    # with a key, a foreign origin is no longer a CSRF risk (a browser cannot attach the header cross-origin)
    r = client.post("/vehicles", data={"name": "ev2", "preset": "paper"},
                    headers={**auth("admin"), "Origin": "http://evil.test"})
    assert r.status_code == 201, r.text
    # revocation takes effect within a second
    store.revoke_key(keys["write"][4:16])
    time.sleep(KEYS_RECHECK_S + 0.1)
    _error(client.get("/logs", headers=auth("write")), 401, "invalid_key")


def test_each_key_has_its_rate(tmp_path: Path) -> None:
    with in_process(tmp_path / "data", key_rate_per_s=1) as c:
        store = c.app.state.store  # type: ignore[attr-defined]
        first, second = (store.create_key("read")[1] for _ in range(2))
        time.sleep(KEYS_RECHECK_S + 0.1)
        replies = [c.get("/logs", headers={"Authorization": f"Bearer {first}"}) for _ in range(20)]
        codes = [r.status_code for r in replies]
        assert codes[:2] == [200, 200]  # the bucket holds LASHSCOPE_RATE_BURST_S' worth
        assert 429 in codes  # 20 requests take far less than the 18 s the rate would allow them
        limited = replies[codes.index(429)]
        assert limited.json()["code"] == "rate_limited" and int(limited.headers["retry-after"]) >= 1
        assert c.get("/logs", headers={"Authorization": f"Bearer {second}"}).status_code == 200  # its own bucket


def test_each_client_address_has_its_rate_without_a_key(tmp_path: Path) -> None:
    with in_process(tmp_path / "data", client_rate_per_s=1) as c:
        codes = [c.get("/logs").status_code for _ in range(20)]
        assert codes[:2] == [200, 200] and 429 in codes  # the bucket holds LASHSCOPE_RATE_BURST_S' worth
        limited = c.get("/logs")
        assert limited.json()["code"] == "rate_limited" and "client testclient" in limited.json()["detail"]
        assert "LASHSCOPE_CLIENT_RATE_PER_S" in limited.json()["detail"]
        assert c.get("/health").status_code == 200  # monitoring is never limited
        other = TestClient(c.app, client=("192.0.2.7", 4000))  # another address (the app is running): its own bucket
        assert other.get("/logs").status_code == 200
        key = c.app.state.store.create_key("read")[1]  # type: ignore[attr-defined]
        time.sleep(KEYS_RECHECK_S + 0.1)
        # with a key, the key's own (larger) bucket counts instead of the address'
        assert c.get("/logs", headers={"Authorization": f"Bearer {key}"}).status_code == 200


def test_serve_refuses_a_network_address_without_keys(tmp_path: Path, store_url: str,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "d"
    where = ["--data-dir", str(data), "--store", store_url]
    assert main(["serve", "--host", "0.0.0.0", *where]) == 2
    assert "[keys_required]" in capsys.readouterr().err
    same = {"data_dir": data, "store_url": store_url}
    refuse_open_network(Settings(host="0.0.0.0", insecure=True, **same))  # the operator's choice
    refuse_open_network(Settings(host="127.0.0.1", **same))
    assert main(["keys", "create", "--scope", "admin", *where]) == 0
    refuse_open_network(Settings(host="0.0.0.0", **same))
    with pytest.raises(ForbiddenError):
        refuse_open_network(Settings(host="192.0.2.7", data_dir=tmp_path / "other"))


def test_network_server_without_keys_answers_nothing_but_health(tmp_path: Path) -> None:
    """Started some other way than ``lashscope serve`` (or every key revoked): still closed."""
    with in_process(tmp_path / "data", host="0.0.0.0", allowed_hosts=["*"]) as c:
        assert c.get("/health").status_code == 200
        _error(c.get("/logs"), 401, "auth_required")
        _error(c.post("/analyses", json={}), 401, "auth_required")


def test_live_buses_are_the_operators_choice(client: TestClient) -> None:
    start = {"database": "lashscope_ev.dbc"}
    body = _error(client.post("/live/sessions", json={**start, "interface": "slcan", "channel": "/dev/ttyUSB0"}),
                  403, "live_channel_not_allowed")
    assert "LASHSCOPE_LIVE_CHANNELS" in body["detail"]
    _error(client.post("/live/sessions", json={**start, "interface": "virtual", "channel": "x",
                                               "options": {"log_file": "/etc/passwd"}}), 403,
           "live_channel_not_allowed")
    r = client.post("/live/sessions", json={**start, "interface": "virtual", "channel": "ok"})
    assert r.status_code == 201, r.text
    sid = r.json()["id"]
    assert client.post(f"/live/sessions/{sid}/stop").status_code == 200
