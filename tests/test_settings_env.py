"""Settings read outside the server's cached settings come from the same Settings class, read when used."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.fleet.hook import store_dir
from app.settings import Settings


def test_live_interfaces_are_a_comma_separated_list(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("LASHSCOPE_LIVE_INTERFACES", " virtual, socketcan ,,")
    assert Settings().live_interfaces == ["virtual", "socketcan"]
    monkeypatch.delenv("LASHSCOPE_LIVE_INTERFACES")
    assert Settings().live_interfaces == []


@pytest.mark.parametrize(("value", "expected"), [("", None), ("off", None), ("False", None), (" none ", None),
                                                 ("/srv/events", Path("/srv/events"))])
def test_event_store_is_read_when_used(monkeypatch: pytest.MonkeyPatch, value: str, expected: Path | None) -> None:
    monkeypatch.setenv("LASHSCOPE_EVENT_STORE", value)
    assert store_dir() == expected


def test_mf4_native_switch(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("LASHSCOPE_MF4_NATIVE", raising=False)
    assert Settings().mf4_native is True
    monkeypatch.setenv("LASHSCOPE_MF4_NATIVE", "false")
    assert Settings().mf4_native is False
