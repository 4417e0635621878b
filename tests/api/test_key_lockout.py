"""API keys under attack: revoking the last key keeps the server closed, wrong keys are rate-limited per
client and leave nothing behind in the server's memory."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import httpx

from app.api.security import KEYS_RECHECK_S, RequestGuard
from app.storage.keys import MAX_TOKEN_CHARS
from tests.api.inprocess import TestClient, in_process

if TYPE_CHECKING:  # imported at run time, Server would mark every test here slow (tests/conftest.py)
    from tests.api.conftest import Server


def _guard(client: TestClient) -> RequestGuard:
    """The running app's request guard (the middleware stack is built on the first request)."""
    layer = client.app.middleware_stack  # type: ignore[attr-defined]
    while not isinstance(layer, RequestGuard):
        layer = layer.app
    return layer


def _bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def test_revoking_the_last_key_keeps_the_server_closed(tmp_path: Path, store_url: str) -> None:
    data = tmp_path / "data"
    with in_process(data, store_url=store_url) as c:
        store = c.app.state.store  # type: ignore[attr-defined]
        key, token = store.create_key("admin")
        time.sleep(KEYS_RECHECK_S + 0.1)
        assert c.get("/logs", headers=_bearer(token)).status_code == 200
        store.revoke_key(key.id)
        assert store.key_counts() == (0, 1)
        time.sleep(KEYS_RECHECK_S + 0.1)
        for r in (c.get("/logs"), c.post("/vehicles", data={"name": "ev", "preset": "paper"}),
                  c.delete("/logs/log_0")):
            assert r.status_code == 401 and r.json()["code"] == "auth_required", r.text
            assert "revoked" in r.json()["detail"] and "--insecure" in r.json()["detail"]
        assert c.get("/logs", headers=_bearer(token)).json()["code"] == "invalid_key"
        assert c.get("/health").status_code == 200
    # a restart reads the same state from the store: still closed
    with in_process(data, store_url=store_url) as c:
        assert c.post("/vehicles", data={"name": "ev", "preset": "paper"}).json()["code"] == "auth_required"
    # the operator opens it explicitly
    with in_process(data, store_url=store_url, insecure=True) as c:
        assert c.post("/vehicles", data={"name": "ev", "preset": "paper"}).status_code == 201
        assert c.get("/vehicles").status_code == 200
        # ... and a new key closes it again, --insecure or not (on loopback it only covers the revoked state)
        c.app.state.store.create_key("read")  # type: ignore[attr-defined]
        time.sleep(KEYS_RECHECK_S + 0.1)
        assert c.get("/vehicles").json()["code"] == "auth_required"


def test_wrong_keys_are_rate_limited_per_client_and_not_remembered(tmp_path: Path) -> None:
    with in_process(tmp_path / "data", auth_failure_rate_per_s=1, key_rate_per_s=0) as c:
        token = c.app.state.store.create_key("read")[1]  # type: ignore[attr-defined]
        time.sleep(KEYS_RECHECK_S + 0.1)
        guesses = [c.get("/logs", headers=_bearer(f"lsk_{i:012x}_{'x' * 43}")) for i in range(30)]
        codes = [r.status_code for r in guesses]
        assert codes[:2] == [401, 401]  # two seconds' worth of failures
        assert codes.count(429) >= 25  # 30 guesses take far less than the 28 s the rate allows them
        limited = guesses[codes.index(429)]
        assert limited.json()["code"] == "rate_limited" and int(limited.headers["retry-after"]) >= 1
        assert "LASHSCOPE_AUTH_FAILURE_RATE_PER_S" in limited.json()["detail"]
        # while its bucket is empty even a right key from that address waits: guessing cannot go on meanwhile
        assert c.get("/logs", headers=_bearer(token)).status_code == 429
        # another address is not held up by this one's guesses
        other = TestClient(c.app, client=("192.0.2.7", 4000))
        assert other.get("/logs", headers=_bearer(token)).status_code == 200
        # a huge token is refused without being looked up; nothing but the one right key is remembered
        huge = other.get("/logs", headers=_bearer("lsk_" + "A" * (1 << 20)))
        assert len(token) < MAX_TOKEN_CHARS < (1 << 20)
        assert huge.status_code == 401 and huge.json()["code"] == "invalid_key"
        guard = _guard(c)
        assert len(guard._verified) == 1 and token not in guard._verified
        assert all(len(digest) == 64 for digest in guard._verified)
        time.sleep(2.1)  # the bucket refills
        assert c.get("/logs", headers=_bearer(token)).status_code == 200


def test_malformed_authorization_counts_as_a_failure(tmp_path: Path) -> None:
    with in_process(tmp_path / "data", auth_failure_rate_per_s=1) as c:
        codes = [c.get("/logs", headers={"Authorization": header}).status_code
                 for header in ("Basic abc", "Bearer", "Bearer ", "Token x", "Basic abc")]
        assert codes[:2] == [401, 401] and codes[-1] == 429


def test_a_real_server_stays_closed_after_revoke_and_answers_head(server: Server) -> None:
    """``lashscope keys`` in another process against a running server; HEAD through uvicorn, a live
    event stream included (headers only, not held open)."""
    def keys(*args: str) -> str:
        return subprocess.run([sys.executable, "-m", "app", "keys", *args, "--data-dir", str(server.data_dir)],
                              capture_output=True, text=True, timeout=120, check=True).stdout

    with httpx.Client(base_url=server.url, timeout=30.0) as c:
        r = c.post("/live/sessions", json={"database": "lashscope_ev.dbc", "interface": "virtual", "channel": "h"})
        assert r.status_code == 201, r.text
        stream = f"/live/sessions/{r.json()['id']}/stream"
        t0 = time.monotonic()
        head = c.head(stream)
        assert head.status_code == 200 and head.content == b"" and time.monotonic() - t0 < 10
        assert head.headers["content-type"].startswith("text/event-stream")
        assert c.head("/logs").status_code == 200 and c.head("/logs").content == b""
        token = keys("create", "--scope", "admin").splitlines()[0].strip()
        keys("revoke", token[4:16])
        time.sleep(KEYS_RECHECK_S + 0.2)
        for r in (c.get("/logs"), c.head("/logs"), c.post("/vehicles", data={"name": "ev", "preset": "paper"})):
            assert r.status_code == 401, r.text
        assert c.get("/health").status_code == 200
