"""Shared fixtures: paths to the public sample data, committed copies (``tests/data``) first, then ``../shared``."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from app.storage.sqlstore import SQLStore
    from tests.pgserver import PgServer

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("LASHSCOPE_SHARED", REPO.parent / "shared")).resolve()
DATA = SHARED / "data"
COMMITTED = REPO / "tests" / "data"  # small copies of some of those files, same layout (tests/data/PROVENANCE.md)


def sample_path(*parts: str) -> Path:
    """The committed copy under ``tests/data`` when there is one, else the path under ``../shared/data``."""
    local = COMMITTED.joinpath(*parts)
    return local if local.exists() else DATA.joinpath(*parts)


def sample_files(folder: str, *patterns: str) -> list[Path]:
    """Files matching the glob ``patterns`` under ``folder`` of ``tests/data`` and ``../shared/data``, sorted by
    their path inside the folder; a committed copy stands in for the shared file of the same path."""
    found: dict[Path, Path] = {}
    for root in (DATA / folder, COMMITTED / folder):  # committed last: it replaces the shared file
        if root.is_dir():
            found.update((p.relative_to(root), p) for pat in patterns for p in root.glob(pat) if p.is_file())
    return [found[k] for k in sorted(found)]


def shared_file(*parts: str) -> Path:
    """A file under ``tests/data`` or ``../shared/data``; skips the test with a reason when it is in neither."""
    path = sample_path(*parts)
    if not path.exists():
        pytest.skip(f"public sample data not found: {path} (set LASHSCOPE_SHARED)")
    return path


def edited_map(tmp_path: Path, channel: str, line: str) -> Path:
    """The reference signal map with ``line`` (``invert = true``, ``factor = 12.0``) added to ``channel``'s table."""
    text = (REPO / "dbc" / "lashscope_ev.map.toml").read_text(encoding="utf-8")
    head = f"[channels.{channel}]\n"
    assert head in text
    out = tmp_path / "edited.map.toml"
    out.write_text(text.replace(head, head + line + "\n"), encoding="utf-8")
    return out


@pytest.fixture
def chain_builds(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The name of the vehicle of every run of ``sim.model.build_chain`` during the test: the real builder,
    counted wherever a module holds it."""
    from sim import Vehicle
    from sim.model import ChainModel, build_chain

    real = build_chain
    calls: list[str] = []

    def counted(vehicle: Vehicle) -> ChainModel:
        calls.append(vehicle.name)
        return real(vehicle)

    for module in list(sys.modules.values()):
        if getattr(module, "build_chain", None) is real:
            monkeypatch.setattr(module, "build_chain", counted)
    return calls


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not DATA.is_dir():
        pytest.skip(f"public sample data folder not found: {DATA} (set LASHSCOPE_SHARED)")
    return DATA


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Tests that start ``lashscope serve`` in a subprocess are ``slow``: ``pytest -m "not slow"`` is the
    development lane (the same code paths run in-process in ``tests/api/test_limits.py`` and
    ``test_security.py``); CI runs everything. Tests on the PostgreSQL backend are ``postgres``."""
    from tests.api.conftest import Server

    for item in items:
        callspec = getattr(item, "callspec", None)
        if "pg_server" in getattr(item, "fixturenames", ()) or (
                callspec is not None and "postgresql" in callspec.params.values()):
            item.add_marker(pytest.mark.postgres)
        module = getattr(item, "module", None)
        if getattr(module, "Server", None) is Server or {"server", "small_cap_server"} & set(
                getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.slow)


@pytest.fixture(scope="session")
def pg_server() -> Iterator[PgServer]:
    """A PostgreSQL server on loopback for the whole session (started on first use, stopped at the end)."""
    from tests.pgserver import PgServer, unavailable_reason

    reason = unavailable_reason()
    if reason is not None:
        pytest.skip(reason)
    server = PgServer().start()
    try:
        yield server
    finally:
        server.stop()


def new_store_url(request: pytest.FixtureRequest, backend: str, files: Path) -> str:
    """A new, empty store on ``backend`` ("sqlite" or "postgresql") with its files in ``files``, as a URL
    ``open_store`` and ``--store`` take (PostgreSQL: a new database on the session's test server)."""
    if backend == "sqlite":
        return str(files)
    server: PgServer = request.getfixturevalue("pg_server")
    return f"{server.database()}?files={files}"


@pytest.fixture(params=["sqlite", "postgresql"])
def store_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """A new store's URL on each backend, its files in ``tmp_path`` (both open with ``open_store(url)``)."""
    return new_store_url(request, request.param, tmp_path)


@pytest.fixture
def store(store_url: str) -> Iterator[SQLStore]:
    """A new store on each backend (SQLite, PostgreSQL), its files in ``tmp_path``."""
    from app.storage.url import open_store

    s = open_store(store_url)
    try:
        yield s
    finally:
        s.close()
