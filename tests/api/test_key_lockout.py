"""API keys under attack: revoking the last key keeps the server closed, wrong keys are rate-limited per
client and leave nothing behind in the server's memory."""

from __future__ import annotations

import time
from pathlib import Path

from app.api.security import KEYS_RECHECK_S, RequestGuard
from app.storage.keys import MAX_TOKEN_CHARS
from tests.api.inprocess import TestClient, in_process


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
