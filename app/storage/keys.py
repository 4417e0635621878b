"""API keys in the store: a random token shown once, only its SHA-256 kept.

A key reads ``lsk_<id>_<secret>``: ``id`` (12 hex digits) names the row so the key can be listed
and revoked without being known, ``secret`` is 32 random bytes (URL-safe base64). Verification
looks the row up by ``id`` and compares the SHA-256 of the whole presented token with the stored
one in constant time (``hmac.compare_digest``), so neither a timing difference nor a copy of the
database gives a usable key away.

Scopes are ordered: ``read`` < ``write`` < ``admin``; a key grants its scope and every lower one.

A revoked key keeps its row, so the store remembers that keys were ever issued
(:meth:`KeyTable.key_counts`): the server stays closed after its last key is revoked.
"""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import secrets
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

from app.errors import InputError, NotFoundError
from app.storage.dialect import Connection

SCOPES = ("read", "write", "admin")
PREFIX = "lsk_"
MAX_TOKEN_CHARS = 128  # a key is 60 characters; anything much longer is refused before it is hashed


def scope_allows(have: str, need: str) -> bool:
    """Whether a key of scope ``have`` may do what needs scope ``need``."""
    return SCOPES.index(have) >= SCOPES.index(need)


def token_digest(token: str) -> str:
    """The SHA-256 (hex) of a presented token: what the store keeps and what the server caches by."""
    return hashlib.sha256(token.encode("utf-8", "replace")).hexdigest()


@dataclass(frozen=True)
class ApiKey:
    id: str
    name: str
    scope: str
    created_at: str
    revoked_at: str | None = None


class KeyTable:
    """The ``api_keys`` table; mixed into the store, which provides the connections."""

    def _conn(self) -> Connection:
        raise NotImplementedError

    def _tx(self) -> contextlib.AbstractContextManager[Connection]:
        raise NotImplementedError

    @staticmethod
    def _key(row: Any) -> ApiKey:
        return ApiKey(row["id"], row["name"], row["scope"], row["created_at"], row["revoked_at"])

    def create_key(self, scope: str, name: str = "") -> tuple[ApiKey, str]:
        """A new key of ``scope``; returns the record and the token (the only time it is available)."""
        if scope not in SCOPES:
            raise InputError(f"scope {scope!r}: use one of {', '.join(SCOPES)}", code="invalid_scope")
        if len(name) > 200:
            raise InputError("key name longer than 200 characters")
        key_id = secrets.token_hex(6)
        token = f"{PREFIX}{key_id}_{secrets.token_urlsafe(32)}"
        created = datetime.now(UTC).isoformat(timespec="milliseconds")
        with self._tx() as db:
            db.execute("INSERT INTO api_keys (id, name, scope, sha256, created_at) VALUES (?,?,?,?,?)",
                       (key_id, name, scope, token_digest(token), created))
        return ApiKey(key_id, name, scope, created), token

    def verify_key(self, token: str) -> ApiKey | None:
        """The active key ``token`` belongs to, or None (unknown, malformed, too long or revoked)."""
        if len(token) > MAX_TOKEN_CHARS:
            return None
        key_id = token[len(PREFIX):len(PREFIX) + 12] if token.startswith(PREFIX) else ""
        row = self._conn().execute("SELECT * FROM api_keys WHERE id = ?", (key_id,)).fetchone()
        stored = row["sha256"] if row is not None else "0" * 64
        same = hmac.compare_digest(stored, token_digest(token))  # compared even for an unknown id
        if row is None or not same or row["revoked_at"] is not None:
            return None
        return self._key(row)

    def list_keys(self) -> list[ApiKey]:
        return [self._key(r) for r in self._conn().execute("SELECT * FROM api_keys ORDER BY created_at")]

    def revoke_key(self, key_id: str) -> ApiKey:
        key_id = key_id.removeprefix(PREFIX)[:12]
        with self._tx() as db:
            row = db.execute("SELECT * FROM api_keys WHERE id = ?", (key_id,)).fetchone()
            if row is None:
                raise NotFoundError(f"no API key {key_id!r}")
            if row["revoked_at"] is None:
                db.execute("UPDATE api_keys SET revoked_at = ? WHERE id = ?",
                           (datetime.now(UTC).isoformat(timespec="milliseconds"), key_id))
            row = db.execute("SELECT * FROM api_keys WHERE id = ?", (key_id,)).fetchone()
        return self._key(row)

    def active_keys(self) -> int:
        """How many keys are not revoked."""
        return self.key_counts()[0]

    def key_counts(self) -> tuple[int, int]:
        """``(active, issued)``: keys not revoked, and keys ever created (revoked ones keep their row).

        ``issued > 0`` with ``active == 0`` means every key was revoked: the server stays closed then,
        unless its operator opens it explicitly (``--insecure``).
        """
        row = self._conn().execute("SELECT COUNT(*) - COUNT(revoked_at), COUNT(*) FROM api_keys").fetchone()
        return int(row[0]), int(row[1])
