"""``KEY=$(lashscope keys create ...)`` captures the key alone."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from app.storage.url import open_store


def test_keys_create_prints_only_the_key_on_stdout(tmp_path: Path) -> None:
    data = tmp_path / "data"
    run = subprocess.run([sys.executable, "-m", "app", "keys", "create", "--scope", "write", "--name", "ci",
                          "--data-dir", str(data)], capture_output=True, text=True, timeout=120, check=True)
    key = run.stdout.removesuffix("\n")
    assert key and "\n" not in key and " " not in key  # what $(...) captures is usable as a header value
    assert "created key" in run.stderr and "not shown again" in run.stderr
    store = open_store(data)
    try:
        found = store.verify_key(key)
        assert found is not None and found.scope == "write" and found.name == "ci"
    finally:
        store.close()
