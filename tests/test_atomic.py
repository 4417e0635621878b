"""app.atomic: the one write-then-rename helper every rewritten file goes through."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import pytest

from app import atomic


def test_write_replaces_the_whole_file_and_leaves_no_temporary(tmp_path: Path) -> None:
    target = tmp_path / "doc.json"
    target.write_text("old", encoding="utf-8")
    atomic.write_text(target, "new content")
    assert target.read_text(encoding="utf-8") == "new content"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["doc.json"]


def test_a_failed_write_keeps_the_old_file_and_removes_its_temporary(tmp_path: Path) -> None:
    target = tmp_path / "doc.json"
    target.write_text("old", encoding="utf-8")
    with pytest.raises(RuntimeError, match="writer failed"), atomic.atomic_path(target) as tmp:
        tmp.write_text("half", encoding="utf-8")
        raise RuntimeError("writer failed")
    assert target.read_text(encoding="utf-8") == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["doc.json"]


def test_two_writers_of_one_file_never_share_a_temporary_name(tmp_path: Path) -> None:
    target = tmp_path / "cache.json"
    names: list[Path] = []
    barrier = threading.Barrier(2)

    def write(text: str) -> None:
        with atomic.atomic_path(target) as tmp:
            names.append(tmp)
            tmp.write_text(text * 10_000, encoding="utf-8")
            barrier.wait(timeout=10)  # both temporaries exist at once

    threads = [threading.Thread(target=write, args=(c,)) for c in "ab"]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=20)
    assert len(set(names)) == 2 and all(n.parent == tmp_path and n.name.startswith(".cache.json.") for n in names)
    assert target.read_text(encoding="utf-8") in ("a" * 10_000, "b" * 10_000)  # one whole version, not a mix
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache.json"]


def test_the_file_gets_the_mode_a_plain_write_would_give(tmp_path: Path) -> None:
    plain = tmp_path / "plain.txt"
    plain.write_text("x", encoding="utf-8")
    atomic.write_text(tmp_path / "atomic.txt", "x")
    assert os.stat(tmp_path / "atomic.txt").st_mode == os.stat(plain).st_mode
