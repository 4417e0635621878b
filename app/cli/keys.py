"""``lashscope keys``: create, list and revoke the API keys of a store.

The key is printed once, by ``create``; the store keeps only its SHA-256, so a lost key is
revoked and replaced, never recovered. The server re-reads the keys within a second, so this
works on a store a running server uses. Creating the first key switches the server from open
(loopback only) to keys-required for every request but ``/health``; revoking the last one leaves it
closed (``serve --insecure`` opens it again).
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

SCOPES = ("read", "write", "admin")  # app.storage.keys.SCOPES, without importing the store for --help


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "keys", help="create, list and revoke API keys",
        description="API keys for the REST API (Authorization: Bearer <key>). Scopes: read (GET), write (+ POST, "
        "uploads, jobs), admin (+ DELETE).")
    where = argparse.ArgumentParser(add_help=False)
    where.add_argument("--data-dir", default=None, help="the server's data directory (default ./lashscope-data)")
    where.add_argument("--store", default=None, help="the store as a URL instead, e.g. sqlite:////srv/ls/db.sqlite3 or "
                       "postgresql://user@host:5432/db")
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    actions.required = True
    create = actions.add_parser("create", parents=[where],
                                help="create a key and print it (the only time it is shown)")
    create.add_argument("--scope", required=True, choices=SCOPES)
    create.add_argument("--name", default="", help="a note: who or what uses the key")
    listing = actions.add_parser("list", parents=[where], help="list keys (ids, scopes, names; never the keys)")
    listing.add_argument("--json", action="store_true")
    revoke = actions.add_parser("revoke", parents=[where], help="revoke a key by its id (or the key itself)")
    revoke.add_argument("key_id")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from app.settings import Settings
    from app.storage.url import open_store

    overrides = {k: v for k, v in (("data_dir", args.data_dir), ("store_url", args.store)) if v is not None}
    settings = Settings(**overrides)
    store = open_store(settings.store_location, files=settings.data_dir)
    try:
        if args.action == "create":
            key, token = store.create_key(args.scope, args.name)
            print(token, flush=True)  # stdout holds the key alone, so KEY=$(lashscope keys create ...) captures it
            print(f"lashscope: created key {key.id} (scope {key.scope}); it is not shown again", file=sys.stderr,
                  flush=True)
        elif args.action == "list":
            keys = store.list_keys()
            if args.json:
                print(json.dumps([k.__dict__ for k in keys], indent=2))
            for k in [] if args.json else keys:
                state = f"revoked {k.revoked_at}" if k.revoked_at else "active"
                print(f"{k.id}  {k.scope:<5}  {state:<32}  created {k.created_at}  {k.name}")
        else:
            key = store.revoke_key(args.key_id)
            print(f"lashscope: key {key.id} revoked ({key.revoked_at})")
    finally:
        store.close()
    return 0
