"""API keys: shown once, stored as a hash, scopes ordered, revocation final."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from app.cli import main
from app.errors import InputError, NotFoundError
from app.storage import SQLiteStore
from app.storage.keys import scope_allows
from app.storage.sqlstore import SQLStore
from app.storage.url import open_store


def test_keys_are_stored_hashed_and_verified(store: SQLStore, tmp_path: Path) -> None:
    assert store.active_keys() == 0
    key, token = store.create_key("write", "ci")
    assert token.startswith(f"lsk_{key.id}_") and len(token) > 50
    if isinstance(store, SQLiteStore):
        raw = (tmp_path / "lashscope.sqlite3").read_bytes() + (tmp_path / "lashscope.sqlite3-wal").read_bytes()
        assert token.encode() not in raw  # only the hash is kept
    rows = [tuple(r) for r in store._conn().execute("SELECT * FROM api_keys").fetchall()]
    assert len(rows) == 1 and hashlib.sha256(token.encode()).hexdigest() in rows[0]
    assert not any(token in str(v) for v in rows[0])
    assert store.verify_key(token) == key and store.active_keys() == 1
    for wrong in (token[:-1] + ("A" if token[-1] != "A" else "B"), "lsk_" + key.id, "", "Bearer x", token + "x"):
        assert store.verify_key(wrong) is None
    assert store.revoke_key(key.id).revoked_at is not None
    assert store.verify_key(token) is None and store.active_keys() == 0
    with pytest.raises(NotFoundError):
        store.revoke_key("000000000000")
    with pytest.raises(InputError):
        store.create_key("root")
    store.close()


def test_scopes_are_ordered() -> None:
    assert scope_allows("admin", "write") and scope_allows("write", "read") and scope_allows("read", "read")
    assert not scope_allows("read", "write") and not scope_allows("write", "admin")


def test_keys_command(tmp_path: Path, store_url: str, capsys: pytest.CaptureFixture[str]) -> None:
    data = str(tmp_path / "d")

    def keys(*argv: str) -> int:  # on PostgreSQL the same commands, with the server's --store
        return main(["keys", *argv, *(("--store", store_url) if "://" in store_url else ())])

    assert keys("create", "--scope", "admin", "--name", "ops", "--data-dir", data) == 0
    token = capsys.readouterr().out.splitlines()[0]
    assert keys("list", "--data-dir", data) == 0
    listing = capsys.readouterr().out
    key_id = token[4:16]
    assert key_id in listing and "admin" in listing and "ops" in listing and token not in listing
    assert keys("revoke", key_id, "--data-dir", data) == 0
    assert "revoked" in capsys.readouterr().out
    store = open_store(store_url if "://" in store_url else data)
    assert store.verify_key(token) is None
    store.close()
    assert keys("revoke", "ffffffffffff", "--data-dir", data) == 2
    assert "[not_found]" in capsys.readouterr().err
