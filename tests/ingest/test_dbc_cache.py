"""The parsed-DBC cache: one parse per content per process, LRU-bounded, edits seen."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest

from app.errors import DatabaseError
from app.ingest import dbc_cache
from app.settings import default_dbc_dir

DBC = default_dbc_dir() / "lashscope_ev.dbc"


@pytest.fixture(autouse=True)
def fresh_cache() -> Iterator[None]:
    dbc_cache.clear()
    yield
    dbc_cache.clear()


def test_same_content_is_parsed_once_even_under_another_name(tmp_path: Path) -> None:
    copy = tmp_path / "copy.dbc"
    shutil.copy(DBC, copy)
    first = dbc_cache.cached_database(DBC)
    assert dbc_cache.cached_database(DBC) is first
    assert dbc_cache.cached_database(copy) is first
    assert (dbc_cache.stats.hits, dbc_cache.stats.misses) == (2, 1)
    assert first.db.get_message_by_name("MCU_Speed").frame_id == first.db.get_message_by_name("MCU_Speed").frame_id


def test_an_edited_file_is_parsed_again(tmp_path: Path) -> None:
    path = tmp_path / "car.dbc"
    shutil.copy(DBC, path)
    before = dbc_cache.cached_database(path)
    text = path.read_text(encoding="utf-8")
    path.write_text(text.replace("MCU_Speed", "MCU_SpeedX"), encoding="utf-8")
    after = dbc_cache.cached_database(path)
    assert after is not before and dbc_cache.stats.misses == 2
    names = {m.name for m in after.db.messages}
    assert "MCU_SpeedX" in names and "MCU_Speed" not in names


def test_least_recently_used_entry_is_dropped(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(dbc_cache, "MAX_ENTRIES", 2)
    text = DBC.read_text(encoding="utf-8")
    paths = []
    for k in range(3):  # three distinct contents (a trailing comment line differs)
        p = tmp_path / f"v{k}.dbc"
        p.write_text(text + f"\nCM_ \"variant {k}\";\n", encoding="utf-8")
        paths.append(p)
    a = dbc_cache.cached_database(paths[0])
    dbc_cache.cached_database(paths[1])
    assert dbc_cache.cached_database(paths[0]) is a  # a is now the most recent
    dbc_cache.cached_database(paths[2])  # evicts v1
    assert dbc_cache.cached_database(paths[0]) is a
    misses = dbc_cache.stats.misses
    dbc_cache.cached_database(paths[1])
    assert dbc_cache.stats.misses == misses + 1


def test_missing_database_is_a_typed_error_and_not_cached(tmp_path: Path) -> None:
    with pytest.raises(DatabaseError, match=r"missing\.dbc: cannot read database file"):
        dbc_cache.cached_database(tmp_path / "missing.dbc")
    bad = tmp_path / "bad.dbc"
    bad.write_text("BO_ nonsense\n", encoding="utf-8")
    with pytest.raises(DatabaseError):
        dbc_cache.cached_database(bad)
    assert dbc_cache.stats.misses == 0
