"""Schema versions: a database made by the first release is upgraded in place with its rows intact."""

from __future__ import annotations

import sqlite3
import threading
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import urlsplit

import pytest

from app.errors import InputError, StorageError
from app.storage import JobStatus, SQLiteStore
from app.storage.dialect import POSTGRESQL
from app.storage.migrations import LATEST, schema_version, upgrade
from app.storage.postgres import PostgresStore
from app.storage.schema import MIGRATIONS
from app.storage.sqlstore import SQLStore
from app.storage.url import open_store
from tests.api.conftest import free_port

if TYPE_CHECKING:
    from tests.pgserver import PgServer

V1_SQL = Path(__file__).parent / "fixtures" / "schema_v1.sql"  # app/storage/schema.py of the first release


def _first_release_db(root: Path) -> None:
    """A data directory as the first release left it: its schema, one log, vehicle, analysis and job."""
    root.mkdir(parents=True)
    (root / "logs").mkdir()
    (root / "logs" / "ab.blf").write_bytes(b"log bytes")
    db = sqlite3.connect(root / "lashscope.sqlite3")
    db.executescript(V1_SQL.read_text())
    db.execute("INSERT INTO logs VALUES ('log_ab', 'ab', 'drive.blf', 9, 'blf', '2026-01-01T00:00:00', "
               "'logs/ab.blf', 1200, 12.5, NULL, '[]', '{\"channels\": 3}')")
    db.execute("INSERT INTO vehicles VALUES ('ev', 1, '2026-01-01T00:00:00', 'cd', 'vehicles/ev/v1/driveline.toml', "
               "'vehicles/ev/v1/database.dbc', 'vehicles/ev/v1/signals.map.toml', '{\"ratio\": 9.0}')")
    db.execute("INSERT INTO jobs (id, kind, subject, status, progress, stage, attempts, created_at, updated_at,"
               " finished_at) VALUES ('job_1', 'analysis', 'an_1', 'done', 1, 'done', 1, 't', 't', 't')")
    db.execute("INSERT INTO analyses VALUES ('an_1', 'log_ab', 'ev', 1, '{\"whole_log\": true}', 't', 'job_1', "
               "'{\"events\": 16}')")
    db.commit()
    db.close()


def test_first_release_database_is_upgraded_with_its_rows(tmp_path: Path) -> None:
    root = tmp_path / "data"
    _first_release_db(root)
    store = SQLiteStore(root)
    db = sqlite3.connect(root / "lashscope.sqlite3")
    assert schema_version(db) == LATEST == MIGRATIONS[-1][0] == 3
    assert [r[0] for r in db.execute("SELECT version FROM schema_version ORDER BY version")] == [1, 2, 3]
    log = store.get_log("log_ab")
    assert (log.filename, log.frames, log.duration_s, log.meta) == ("drive.blf", 1200, 12.5, {"channels": 3})
    assert log.path.read_bytes() == b"log bytes"
    assert store.get_vehicle("ev").summary == {"ratio": 9.0}
    rec = store.get_analysis("an_1")
    assert rec.options == {"whole_log": True} and rec.summary == {"events": 16}
    assert rec.job.status is JobStatus.DONE
    # the new table works on the upgraded database
    key, token = store.create_key("read", "dashboard")
    assert store.verify_key(token) == key
    store.close()
    # opening again applies nothing more
    assert upgrade(db) == []
    db.close()


def test_new_database_gets_every_migration_in_order(tmp_path: Path) -> None:
    db = sqlite3.connect(tmp_path / "x.sqlite3", isolation_level=None)
    assert schema_version(db) == 0
    assert upgrade(db) == [v for v, _, _ in MIGRATIONS]
    tables = {r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    assert {"logs", "vehicles", "jobs", "analyses", "api_keys", "schema_version"} <= tables


def test_a_newer_database_is_refused(tmp_path: Path) -> None:
    SQLiteStore(tmp_path).close()
    db = sqlite3.connect(tmp_path / "lashscope.sqlite3")
    db.execute("INSERT INTO schema_version VALUES (?, 't')", (LATEST + 1,))
    db.commit()
    db.close()
    with pytest.raises(StorageError) as err:
        SQLiteStore(tmp_path)
    assert err.value.code == "schema_too_new" and f"version {LATEST + 1}" in str(err.value)


def test_store_from_url(tmp_path: Path) -> None:
    db_file = tmp_path / "srv" / "main.sqlite3"
    db_file.parent.mkdir()
    store = open_store(f"sqlite:///{db_file}")
    assert store.database == db_file and store.root == db_file.parent and db_file.is_file()
    assert store.url == f"sqlite:///{db_file}"
    key, token = store.create_key("admin")
    store.close()
    again = open_store(store.url)  # what a job worker does
    assert again.verify_key(token) == key
    again.close()

    files = tmp_path / "files"
    elsewhere = open_store(f"sqlite:///{tmp_path / 'other.sqlite3'}?files={files}")
    assert elsewhere.root == files and (files / "logs").is_dir()
    reopened = open_store(elsewhere.url)
    assert reopened.root == files and reopened.database == tmp_path / "other.sqlite3"
    elsewhere.close()
    reopened.close()

    plain = open_store(tmp_path / "dir")
    assert plain.database == tmp_path / "dir" / "lashscope.sqlite3"
    plain.close()
    for bad in ("mysql://db.example/lashscope", "sqlite://host/x.sqlite3", "sqlite:///"):
        with pytest.raises(InputError) as e:
            open_store(bad)
        assert e.value.code == "unsupported_store"


def test_postgres_database_gets_every_migration_once_with_wide_columns(pg_server: PgServer, tmp_path: Path) -> None:
    url = pg_server.database()
    stores: list[SQLStore] = []
    errors: list[BaseException] = []

    def open_one(k: int) -> None:  # two servers starting on one new database at once
        try:
            stores.append(open_store(url, files=tmp_path / f"files{k}"))
        except BaseException as exc:
            errors.append(exc)

    threads = [threading.Thread(target=open_one, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and len(stores) == 2
    db = stores[0]._conn()
    assert [r[0] for r in db.execute("SELECT version FROM schema_version ORDER BY version")] == [1, 2, 3]
    assert schema_version(db, POSTGRESQL) == LATEST and upgrade(db, POSTGRESQL) == []
    types = dict(db.execute("SELECT column_name, data_type FROM information_schema.columns"
                            " WHERE table_name = 'jobs'").fetchall())
    assert (types["lease_until"], types["progress"], types["attempts"]) == ("double precision", "double precision",
                                                                           "bigint")
    db.execute("INSERT INTO schema_version VALUES (?, 't')", (LATEST + 1,))
    for s in stores:
        s.close()
    with pytest.raises(StorageError) as err:
        open_store(url, files=tmp_path)
    assert err.value.code == "schema_too_new"


def test_postgres_store_from_url(pg_server: PgServer, tmp_path: Path) -> None:
    url = pg_server.database()
    files = tmp_path / "shared files"
    store = open_store(f"{url}?files={files}")
    assert isinstance(store, PostgresStore) and store.root == files and (files / "logs").is_dir()
    key, token = store.create_key("admin")
    again = open_store(store.url)  # what a job worker does
    assert again.root == files and again.verify_key(token) == key
    for s in (store, again):
        s.close()
    with_default = open_store(url, files=tmp_path / "data")  # the server's --data-dir
    assert with_default.root == tmp_path / "data" and with_default.verify_key(token) == key
    with_default.close()

    port = urlsplit(url).port
    for bad, code in ((url, "unsupported_store"),  # no files directory anywhere
                      (f"postgresql://lashscope:s3cret@127.0.0.1:{port}/?files={tmp_path}", "unsupported_store"),
                      (f"postgresql://lashscope:s3cret@127.0.0.1:{free_port()}/x?files={tmp_path}",
                       "store_unreachable")):
        with pytest.raises((InputError, StorageError)) as e:
            open_store(bad)
        assert e.value.code == code and "s3cret" not in str(e.value)  # type: ignore[union-attr]
