"""A text log in a format described by the user: uploaded with its TOML description, stored beside it,
and read with it by the analysis worker (a separate process)."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.readers import open_log
from tests.api.conftest import create_vehicle, wait_for
from tests.api.inprocess import in_process

LAYOUT = r"""
name = "bench logger"
regex = '^(?P<time>\d+\.\d+);(?P<id>[0-9A-F]+);(?P<ext>[SX]);(?P<data>[0-9A-F]*)$'
time_unit = "ms"
data_encoding = "hex_string"
skip_lines = 1
extended = "field"
extended_values = ["X"]
"""


def _bench_text(blf: Path) -> tuple[bytes, int]:
    """The demo drive's frames as the bench logger writes them: ``ms;ID;S|X;hex`` (exact ms decimals)."""
    with open_log(blf) as log:
        chunk = FrameChunk.concat(list(log.chunks()))
    rows = ["time_ms;id;fmt;data\n"]
    ext = (chunk.flags & int(FrameFlag.EXTENDED)) != 0
    for t, i, x, n, data in zip(chunk.t_ns.tolist(), chunk.arb_id.tolist(), ext.tolist(), chunk.dlc.tolist(),
                                chunk.data, strict=True):
        rows.append(f"{t // 10**6}.{t % 10**6:06d};{i:X};{'X' if x else 'S'};{bytes(data[:n]).hex().upper()}\n")
    return "".join(rows).encode(), len(chunk)


def test_described_log_is_stored_with_its_description_and_analysed(tmp_path: Path, demo_log: Path) -> None:
    text, frames = _bench_text(demo_log)
    data = tmp_path / "data"
    with in_process(data) as client:
        refused = client.post("/logs", files={"file": ("bench.txt", text)})
        assert refused.status_code == 415 and refused.json()["code"] == "unsupported_format"
        r = client.post("/logs", files={"file": ("bench.txt", text), "format_file": ("bench.toml", LAYOUT.encode())})
        assert r.status_code == 201, r.text
        log = r.json()
        assert log["format"] == "described" and log["frames"] == frames and log["issues"] == []
        stored = list((data / "logs").glob("*.format.toml"))
        assert len(stored) == 1 and stored[0].read_text() == LAYOUT
        assert list((data / "tmp").iterdir()) == []
        create_vehicle(client)
        aid = client.post("/analyses", json={"log_id": log["id"], "vehicle": "ev"}).json()["id"]
        done = wait_for(client, aid, timeout=300)
        assert done["status"] == "done", done
        metrics = client.get(f"/analyses/{aid}/metrics").json()
        assert metrics["summary"]["metrics"]["fluctuation_rpm"]["measured_median"] > 50
        assert client.delete(f"/logs/{log['id']}").status_code == 204
        assert list((data / "logs").glob("*")) == []  # the description went with its log


@pytest.mark.parametrize(("layout", "message"), [
    ('regex = "(?P<time>x)"', "bench.toml: regex: needs the named group"),
    ('columns = { time = 0, id = 1, data = 2 }\ntime_unit = "fortnight"', "bench.toml: time_unit: 'fortnight'"),
])
def test_bad_description_is_refused_naming_the_field(tmp_path: Path, layout: str, message: str) -> None:
    data = tmp_path / "data"
    with in_process(data) as client:
        r = client.post("/logs", files={"file": ("bench.txt", b"1.0;100;S;00\n"),
                                        "format_file": ("bench.toml", layout.encode())})
        assert r.status_code == 422 and r.json()["code"] == "format_file", r.text
        assert message in r.json()["detail"]
        assert client.get("/logs").json() == []
        assert list(data.glob("logs/*")) == []  # neither the log nor its description was kept
        assert list((data / "tmp").iterdir()) == []  # nor any temporary file


def test_a_third_file_field_is_refused(tmp_path: Path) -> None:
    with in_process(tmp_path / "data") as client:
        r = client.post("/logs", files={"file": ("a.log", b"(0.0) can0 123#00\n"),
                                        "dbc": ("a.dbc", b"VERSION \"\"\n")})
        assert r.status_code == 400 and r.json()["code"] == "too_many_files", r.text
        assert client.get("/logs").json() == []


def test_the_formats_route_lists_the_registry(tmp_path: Path) -> None:
    from app.log_formats import LOG_FORMATS

    with in_process(tmp_path / "data") as client:
        got = client.get("/logs/formats").json()
    assert got == [{"name": f.name, "label": f.label} for f in LOG_FORMATS]
    assert {"analyser_tsv", "serial_dump", "described"} <= {f["name"] for f in got}
