"""``lashscope vehicles list|show|compare``: figures and fields of real vehicle files, registered versions, errors."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pytest

from app.cli import main
from app.identify.base import with_base
from app.storage.url import open_store
from sim import dump_toml, load_vehicle

REPO = Path(__file__).resolve().parents[2]


def _scaled_file(tmp_path: Path, provenance: str = "") -> Path:
    """The paper car with every stage's stiffness 0.7x and its mass 1.2x, as a user's file."""
    vehicle = with_base(load_vehicle("paper"), {"stiffness": 0.7, "mass": 1.2})
    path = tmp_path / "paper_scaled.toml"
    path.write_text(dump_toml(vehicle) + provenance, encoding="utf-8")
    return path


def test_compare_leads_with_the_figures_that_moved(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _scaled_file(tmp_path)
    assert main(["vehicles", "compare", "paper", str(path), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    figs = {f["key"]: f for f in doc["figures"]}
    assert figs["stiffness"]["ratio"] == pytest.approx(0.7, rel=1e-9)  # every stage scaled: the series stiffness too
    assert figs["mass"]["ratio"] == pytest.approx(1.2, rel=1e-12) and figs["mass"]["a"] == 1750.0
    assert figs["lash"]["ratio"] == pytest.approx(1.0) and figs["torque_gain"]["ratio"] == 1.0
    assert 0.7 < figs["freq"]["ratio"] < 0.9  # a softer shaft on a heavier car: a lower first mode
    changed = {f["field"]: f for f in doc["fields"] if f["changed"]}
    assert changed["body.mass"]["ratio"] == pytest.approx(1.2)
    stiff = [k for k in changed if k.endswith("stiffness")]
    assert stiff and all(changed[k]["ratio"] == pytest.approx(0.7) for k in stiff)
    assert set(changed) == {"body.mass", *stiff}  # nothing else moved
    assert doc["provenance"] == {"a": None, "b": None}
    assert main(["vehicles", "compare", "paper", str(path)]) == 0
    text = capsys.readouterr().out
    assert "vehicle mass (kg)" in text and "1.200x" in text and "0.700x" in text
    assert f"driveline fields: {len(changed)} of {len(doc['fields'])} differ" in text


def test_an_identified_file_shows_its_provenance(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    prov = ('\n[provenance]\nidentified_from = "paper"\ndate = "2026-11-28T10:00:00+00:00"\nevents = 24\n'
            'logs = [{name = "drive1.blf", sha256 = "' + "ab" * 32 + '", events = 24}]\n'
            'not_identified = ["lash"]\nresidual_to_noise_before = 14.2\nresidual_to_noise_after = 1.1\n'
            '[provenance.fitted.stiffness]\nratio = 0.7\nvalue = 78.9\nlo = 75.1\nhi = 82.6\nunit = "N m/rad"\n')
    path = _scaled_file(tmp_path, prov)
    assert tomllib.loads(path.read_text(encoding="utf-8"))["provenance"]["events"] == 24
    assert main(["vehicles", "show", str(path)]) == 0
    text = capsys.readouterr().out
    assert "identified from paper on 2026-11-28" in text and "drive1.blf (sha256 abababababab, 24 events)" in text
    assert "stiffness  78.9 [75.1, 82.6] N m/rad  (0.70x the file's)" in text
    assert "not identified (kept at the file's): lash" in text and "14.2 -> 1.1" in text
    assert main(["vehicles", "compare", "paper", str(path), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["provenance"]["b"]["fitted"]["stiffness"]["lo"] == 75.1
    assert not any(f["field"].startswith("provenance") for f in doc["fields"])  # not part of the driveline


def test_registered_versions_by_name_and_number(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "store"
    store = open_store(f"sqlite:///{data / 'lashscope.sqlite3'}", data)
    try:
        dbc, smap = REPO / "dbc" / "lashscope_ev.dbc", REPO / "dbc" / "lashscope_ev.map.toml"
        first = tmp_path / "v1.toml"
        first.write_text(dump_toml(load_vehicle("paper")), encoding="utf-8")
        store.add_vehicle("ev", driveline=first, database=dbc, signal_map=smap, summary={})
        store.add_vehicle("ev", driveline=_scaled_file(tmp_path), database=dbc, signal_map=smap, summary={})
    finally:
        store.close()
    assert main(["vehicles", "list", "--data-dir", str(data)]) == 0
    assert "ev: 2 version(s), latest 2" in capsys.readouterr().out
    assert main(["vehicles", "compare", "ev@1", "ev", "--data-dir", str(data), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["a"].startswith("ev version 1") and "the latest" in doc["b"]
    assert {f["key"]: f["ratio"] for f in doc["figures"]}["mass"] == pytest.approx(1.2)
    assert main(["vehicles", "compare", "ev@2", "ev@2", "--data-dir", str(data), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["changed"] == 0
    assert main(["vehicles", "compare", "ev@1", "ev@7", "--data-dir", str(data)]) == 2
    assert "[not_found]" in capsys.readouterr().err


@pytest.mark.parametrize(("args", "code"), [
    (["vehicles", "compare", "paper", "no_such_car"], "vehicle_not_found"),
    (["vehicles", "compare", "paper", "ev@0"], "invalid_parameter"),
    (["vehicles", "compare", "paper", "ev@two"], "invalid_parameter"),
    (["vehicles", "show", "missing.toml"], "vehicle_not_found"),
])
def test_bad_references_are_one_line_errors(args: list[str], code: str, tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*args, "--data-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"[{code}]" in err and "Traceback" not in err


@pytest.mark.parametrize(("content", "needle"), [
    ("[body\nmass = ", "not a readable TOML file"),
    ("[body]\nmass = -5.0\n", "not a valid vehicle file"),
    (b"\xff\xfe\x00garbage", "cannot read"),
])
def test_broken_files_name_the_side(content: str | bytes, needle: str, tmp_path: Path,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.toml"
    if isinstance(content, bytes):
        bad.write_bytes(content)
    else:
        bad.write_text(content, encoding="utf-8")
    assert main(["vehicles", "compare", "paper", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "[invalid_vehicle]" in err and needle in err and str(bad) in err and err.count("\n") == 1
