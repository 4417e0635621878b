"""A real server and a real Chromium for the dashboard tests.

The browser is Debian's ``chromium`` (``.ci/run`` installs it) driven by playwright from PyPI
through its ``executable_path``; playwright's own browser downloads are never used. Without
chromium or playwright the tests skip with the reason -- except under ``CI=true``, where they fail.
Screenshots go to ``tests/artifacts/`` (git-ignored).
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any
from urllib.parse import urlparse

import httpx
import pytest

from tests.api.conftest import Server, create_vehicle, free_port
from tests.conftest import REPO

ARTIFACTS = REPO / "tests" / "artifacts"


def _missing(reason: str) -> None:
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(f"{reason} (CI=true: the browser tests must run; .ci/run installs it)")
    pytest.skip(reason)


def chromium_path() -> str:
    path = os.environ.get("LASHSCOPE_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")
    if not path:
        _missing("Debian's chromium is not installed (apt-get install chromium)")
    assert path is not None
    return path


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        _missing("playwright is not installed (pip install -e '.[dev]')")
    exe = chromium_path()
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=exe, args=["--no-sandbox", "--disable-dev-shm-usage"])
        yield b
        b.close()


@pytest.fixture(scope="module")
def hub_port() -> int:
    """The port of the loopback hub the live page test replays onto (the server allows that one)."""
    return free_port()


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory, hub_port: int) -> Iterator[Server]:
    with pytest.MonkeyPatch.context() as env:
        env.setenv("LASHSCOPE_LIVE_CHANNELS", f"tcp_loopback:127.0.0.1:{hub_port}")
        srv = Server(tmp_path_factory.mktemp("web") / "data", max_upload_mb=64.0).start()
    with httpx.Client(base_url=srv.url, timeout=30.0) as c:
        create_vehicle(c, "ev")
    yield srv
    srv.stop()


@pytest.fixture
def page(browser: Any, server: Server) -> Iterator[Any]:
    """A fresh page on the dashboard; page errors (uncaught exceptions) and console errors fail the test.

    ``pg.console_errors`` lists every console error, ``pg.hosts`` every host a request went to; a
    response the page asked for and got as an error status (a test's unknown id) is logged by the
    browser as "Failed to load resource" and is the only console error a test may cause on purpose."""
    context = browser.new_context(viewport={"width": 1400, "height": 1000}, accept_downloads=True)
    pg = context.new_page()
    errors: list[str] = []
    pg.console_errors = []
    pg.hosts = set()
    pg.on("pageerror", lambda e: errors.append(str(e)))
    pg.on("console", lambda m: pg.console_errors.append(m.text) if m.type == "error" else None)
    pg.on("request", lambda r: pg.hosts.add(urlparse(r.url).hostname or urlparse(r.url).scheme))
    pg.set_default_timeout(60_000)
    yield pg
    context.close()
    assert not errors, f"errors in the page: {errors}"
    script = [m for m in pg.console_errors if not m.startswith("Failed to load resource")]
    assert not script, f"console errors: {script}"


def screenshot(pg: Any, name: str, full_page: bool = False) -> Path:
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    path = ARTIFACTS / f"{name}.png"
    pg.screenshot(path=str(path), full_page=full_page)
    return path
