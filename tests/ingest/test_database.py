"""Database loading: every cantools test file, the production DBCs, repairs with line numbers, typed errors."""

from __future__ import annotations

import re
from pathlib import Path

import cantools
import pytest

from app.errors import DatabaseError
from app.ingest.database import load_database
from tests.conftest import sample_files, shared_file

TESTFILES = "cantools-testfiles"  # tests/data holds two of them, ../shared/data all
ALL_TESTFILES = sample_files(TESTFILES, "*/*")


def _cantools_loads(path: Path) -> bool:
    try:
        cantools.database.load_file(str(path))
    except Exception:
        return False
    return True


@pytest.mark.skipif(not ALL_TESTFILES, reason=f"cantools test files not found under {TESTFILES}")
@pytest.mark.parametrize("path", ALL_TESTFILES, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_cantools_testfiles_load_or_fail_typed(path: Path) -> None:
    if _cantools_loads(path):
        for tolerant in (False, True):
            loaded = load_database(path, tolerant=tolerant)
            assert loaded.repairs == []
            assert len(loaded.db.messages) == len(cantools.database.load_file(str(path)).messages)
    else:
        with pytest.raises(DatabaseError, match=re.escape(str(path))):
            load_database(path, tolerant=False)
        try:  # tolerant: repaired (with a report) or still a DatabaseError, never another exception
            loaded = load_database(path, tolerant=True)
        except DatabaseError:
            return
        assert loaded.repairs, f"{path} loaded tolerantly without reporting a repair"


# file, tolerant repair kinds expected, messages after repair (= BO_ lines in the file)
PRODUCTION = [
    (("kona-ev", "dbc", "pcan.dbc"), {"missing_bu", "missing_bs"}, 107),
    (("kona-ev", "dbc", "ccan.dbc"), {"missing_bu", "missing_bs"}, 2),
    (("opendbc", "opendbc", "dbc", "tesla_can.dbc"), {"unused_val"}, 44),
    (("opendbc", "opendbc", "dbc", "rivian_primary_actuator.dbc"), {"unused_val"}, 67),
    (("opendbc", "opendbc", "dbc", "gwm_haval_h6_phev_2024.dbc"), {"signal_overlap"}, 27),
    (("model3dbc", "Model3CAN.dbc"), {"signal_outside", "unused_val"}, 148),
    (("opendbc", "opendbc", "dbc", "tesla_powertrain.dbc"), set(), 6),
    (("opendbc", "opendbc", "dbc", "tesla_model3_party.dbc"), set(), 21),
]


@pytest.mark.parametrize(("parts", "kinds", "messages"), PRODUCTION, ids=lambda v: "/".join(v) if
                         isinstance(v, tuple) else None)
def test_production_dbcs(parts: tuple[str, ...], kinds: set[str], messages: int) -> None:
    path = shared_file(*parts)
    loaded = load_database(path)
    assert {r.kind for r in loaded.repairs} == kinds
    assert len(loaded.db.messages) == messages
    text = path.read_text(encoding="utf-8").splitlines()
    for r in loaded.repairs:
        assert r.line is not None and 1 <= r.line <= len(text) + 1
        if r.kind == "unused_val":
            assert text[r.line - 1].startswith("VAL_"), r
        if r.kind in ("signal_outside", "signal_overlap"):
            assert text[r.line - 1].lstrip().startswith("SG_"), r
    if kinds:
        with pytest.raises(DatabaseError, match=r":\d+: cannot load DBC"):
            load_database(path, tolerant=False)


def test_kona_missing_sections_reported_at_first_message(tmp_path: Path) -> None:
    loaded = load_database(shared_file("kona-ev", "dbc", "pcan.dbc"))
    assert [(r.kind, r.line) for r in loaded.repairs] == [("missing_bu", 6), ("missing_bs", 6)]
    assert loaded.db.get_message_by_name("VCU_291").get_signal_by_name("Speed_signed").unit == "rpm"


def _dbc(tmp_path: Path, body: str, name: str = "t.dbc", encoding: str = "utf-8") -> Path:
    path = tmp_path / name
    path.write_bytes(body.encode(encoding))
    return path


HEADER = 'VERSION ""\n\nNS_ :\n\tCM_\n\nBS_:\n\nBU_: A\n\n'
MSG = 'BO_ 256 Foo: 8 A\n SG_ Bar : 0|8@1+ (1,0) [0|255] "" A\n\n'


def test_val_for_unknown_message_and_signal(tmp_path: Path) -> None:
    body = HEADER + MSG + 'VAL_ 256 Bar 1 "One" ;\nVAL_ 999 Bar 1 "One" ;\nVAL_ 256 Nope 2 "Two" ;\n'
    loaded = load_database(_dbc(tmp_path, body))
    assert [(r.kind, r.line) for r in loaded.repairs] == [("unused_val", 14), ("unused_val", 15)]
    assert "999" in loaded.repairs[0].message and "Nope" in loaded.repairs[1].message
    assert loaded.db.get_message_by_name("Foo").get_signal_by_name("Bar").choices == {1: "One"}
    with pytest.raises(DatabaseError, match=r"t\.dbc:14: .*unused VAL_"):
        load_database(_dbc(tmp_path, body), tolerant=False)


def test_syntax_error_names_original_line(tmp_path: Path) -> None:
    body = 'VERSION ""\n\nNS_ :\n\nBO_ 256 Foo: 8 A\n SG_ Bar : 0|8@1+ (1,0) [0|255] "" A\n SG_ Broken : x|y\n'
    with pytest.raises(DatabaseError, match=r"t\.dbc:7: cannot load DBC: .*line 7"):
        load_database(_dbc(tmp_path, body))


def test_cp1252_text_loads(tmp_path: Path) -> None:
    body = HEADER + MSG + 'CM_ SG_ 256 Bar "Drehzahl \u00b0C \u00e4\u00f6\u00fc";\n'
    loaded = load_database(_dbc(tmp_path, body, encoding="cp1252"))
    assert loaded.encoding == "cp1252"
    comment = loaded.db.get_message_by_name("Foo").get_signal_by_name("Bar").comment
    assert comment == "Drehzahl \u00b0C \u00e4\u00f6\u00fc"


@pytest.mark.parametrize(("name", "content", "match"), [
    ("missing.dbc", None, "cannot read"),
    ("random.bin", b"\x00\x01garbage\xff" * 20, "not a DBC, KCD, SYM or ARXML"),
    ("binary.dbc", bytes(range(256)) * 4, "cannot load DBC"),
    ("bad.kcd", b"<NetworkDefinition><Bus", "cannot load KCD"),
    ("bad.arxml", b"<?xml version='1.0'?><AUTOSAR>", "cannot load ARXML"),
])
def test_bad_files_give_database_error(tmp_path: Path, name: str, content: bytes | None, match: str) -> None:
    path = tmp_path / name
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(DatabaseError, match=match):
        load_database(path)


def test_format_from_content_when_suffix_is_unknown(tmp_path: Path) -> None:
    path = tmp_path / "vehicle.txt"
    path.write_text(HEADER + MSG)
    loaded = load_database(path)
    assert loaded.format == "dbc" and loaded.db.get_message_by_name("Foo").frame_id == 256


def test_reference_dbc_loads_strictly() -> None:
    loaded = load_database(Path(__file__).resolve().parents[2] / "dbc" / "lashscope_ev.dbc", tolerant=False)
    assert {m.name for m in loaded.db.messages} >= {"MCU_Torque", "MCU_Speed", "MCU_Fast", "VCU_Pedal"}
    assert loaded.db.get_message_by_name("MCU_Fast").cycle_time == 1


def _candb_export() -> str:
    """A DBC shaped like a CANdb++ export: signals no message carries sit in VECTOR__INDEPENDENT_SIG_MSG."""
    return (HEADER
            + 'BO_ 3221225472 VECTOR__INDEPENDENT_SIG_MSG: 0 Vector__XXX\n'
            + ' SG_ Spare_Current : 0|16@1- (0.1,0) [-2000|2000] "current:A" Vector__XXX\n\n'
            + 'BO_ 2365565953 MC_Torque_And_Timer_Info: 8 A\n'
            + ' SG_ INV_Torque_Feedback : 16|16@1- (0.1,0) [-3276.8|3276.7] "torque:N.m" A\n'
            + ' SG_ INV_State : 0|3@1+ (1,0) [0|7] "" A\n\n'
            + 'BO_ 2147483648 VECTOR__INDEPENDENT_SIG_MSG: 0 Vector__XXX\n'
            + ' SG_ StateContactorPositive : 0|3@1- (1,0) [0|0] "" Vector__XXX\n\n'
            + 'CM_ BO_ 3221225472 "This is a message for not used signals, created by Vector CANdb++ DBC OLE DB '
              'Provider.";\n'  # line 20
            + 'CM_ SG_ 2147483648 StateContactorPositive "state; see\nthe contactor spec";\n'  # lines 21-22
            + 'CM_ SG_ 2365565953 INV_Torque_Feedback "Estimated motor torque";\n'
            + 'VAL_ 2147483648 StateContactorPositive 0 "INVALID" 1 "OPEN" 2 "CLOSED" ;\n'  # line 24
            + 'VAL_ 2365565953 INV_State 0 "Off" 1 "On" ;\n')


def test_candb_pseudo_message_statements_dropped_and_reported(tmp_path: Path) -> None:
    path = _dbc(tmp_path, _candb_export(), name="candb.dbc")
    loaded = load_database(path)
    assert [(r.kind, r.line) for r in loaded.repairs] == [
        ("unused_comment", 20), ("unused_comment", 21), ("unused_val", 24)]
    assert "VECTOR__INDEPENDENT_SIG_MSG (ID 2147483648)" in loaded.repairs[2].message
    assert "StateContactorPositive" in loaded.repairs[2].message
    assert [m.name for m in loaded.db.messages] == ["MC_Torque_And_Timer_Info"]
    msg = loaded.db.get_message_by_name("MC_Torque_And_Timer_Info")
    assert msg.frame_id == 0x0CFFAC01 and msg.is_extended_frame
    assert msg.get_signal_by_name("INV_State").choices == {0: "Off", 1: "On"}  # a real message's VAL_ stays
    assert msg.get_signal_by_name("INV_Torque_Feedback").comment == "Estimated motor torque"
    with pytest.raises(DatabaseError, match=r"candb\.dbc:24: .*unused VAL_.*StateContactorPositive"):
        load_database(path, tolerant=False)


def test_unclosed_pseudo_message_comment_stops_at_next_statement(tmp_path: Path) -> None:
    body = _candb_export().replace('the contactor spec";', 'the contactor spec')
    loaded = load_database(_dbc(tmp_path, body))
    assert [(r.kind, r.line) for r in loaded.repairs][1:] == [("unused_comment", 21), ("unused_val", 24)]
    assert loaded.db.get_message_by_name("MC_Torque_And_Timer_Info").get_signal_by_name(
        "INV_Torque_Feedback").comment == "Estimated motor torque"


@pytest.mark.parametrize("body", ["", "\n\n   \n", "\ufeff"])
def test_empty_file_is_refused_not_repaired(tmp_path: Path, body: str) -> None:
    for tolerant in (True, False):
        with pytest.raises(DatabaseError) as err:
            load_database(_dbc(tmp_path, body), tolerant=tolerant)
        assert err.value.code == "empty_database" and "the database file is empty" in str(err.value)


def test_messageless_dbc_needing_repairs_is_refused(tmp_path: Path) -> None:
    with pytest.raises(DatabaseError) as err:
        load_database(_dbc(tmp_path, "notes\n"))
    assert err.value.code == "empty_database" and "defines no messages" in str(err.value)
    assert len(load_database(_dbc(tmp_path, HEADER)).db.messages) == 0  # valid as written: loaded, nothing invented


def test_duplicate_frame_id_is_reported_not_printed(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    second = MSG.replace("Foo", "Baz").replace("Bar", "Qux")
    loaded = load_database(_dbc(tmp_path, HEADER + MSG + second))
    out, err = capfd.readouterr()
    assert out == "" and err == ""  # cantools' own warning line never reaches the terminal
    assert loaded.repairs == []  # nothing was changed
    assert [(r.kind, r.message) for r in loaded.notes] == [
        ("duplicate_id", "messages Foo and Baz have the same frame ID 0x100; its frames decode as Baz (the later "
                         "one, as in cantools)")]
    assert loaded.db.get_message_by_frame_id(256).name == "Baz"
    from app.cli.decode import format_report
    from app.ingest.stats import DecodeReport

    text = format_report(DecodeReport(database_notes=loaded.notes))
    assert "  database note: duplicate_id: messages Foo and Baz have the same frame ID 0x100" in text


def test_duplicate_message_name_is_reported_not_printed(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    second = MSG.replace("BO_ 256", "BO_ 257").replace("Bar", "Qux")
    loaded = load_database(_dbc(tmp_path, HEADER + MSG + second))
    assert capfd.readouterr() == ("", "")
    assert [(r.kind, r.message) for r in loaded.notes] == [
        ("duplicate_name", "two messages are named Foo; looking it up by name finds the later one (as in cantools)")]
