"""Gzipped MF4 over HTTP: a real CANedge file is accepted; a gzip bomb gets 413 ``inflated_too_large``, not a 500."""

from __future__ import annotations

import gzip
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from app.ingest.frames import FrameChunk
from app.ingest.readers import open_log
from tests.api.conftest import Server, upload
from tests.conftest import shared_file


@pytest.fixture
def small_cap_server(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Server]:
    monkeypatch.setenv("LASHSCOPE_MAX_INFLATED_MB", "1")
    srv = Server(tmp_path / "data").start()
    yield srv
    srv.stop()


def test_gzipped_mf4_upload_and_bomb(small_cap_server: Server, tmp_path: Path) -> None:
    real = shared_file("css-electronics-mf4", "examples", "data-processing", "LOG", "17BD1DB7", "00000006",
                       "00000170.MF4")  # 80 kB, under the 1 MiB cap
    with open_log(real) as log:
        frames = len(FrameChunk.concat(list(log.chunks())))
    gz = tmp_path / "00000170.MF4.gz"
    gz.write_bytes(gzip.compress(real.read_bytes()))
    bomb = tmp_path / "bomb.mf4.gz"
    bomb.write_bytes(gzip.compress(b"MDF     4.10    " + bytes(6 << 20), compresslevel=9))
    with httpx.Client(base_url=small_cap_server.url, timeout=120.0) as c:
        r = upload(c, gz)
        assert r.status_code == 201, r.text
        assert (r.json()["format"], r.json()["frames"]) == ("mf4", frames) and frames > 100
        r = upload(c, bomb)
        assert r.status_code == 413, r.text
        body = r.json()
        assert body["code"] == "inflated_too_large"
        assert body["detail"].startswith("bomb.mf4.gz: decompresses to more than the 1 MiB cap")
        assert c.get("/health").json()["status"] == "ok"
        assert [x["filename"] for x in c.get("/logs").json()] == ["00000170.MF4.gz"]
    assert list((small_cap_server.data_dir / "tmp").iterdir()) == []
