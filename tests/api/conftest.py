"""A real server for the API tests: ``lashscope serve`` in a subprocess on a free loopback port."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.conftest import REPO


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Server:
    def __init__(self, data_dir: Path, max_upload_mb: float = 4.0, extra_args: tuple[str, ...] = ()) -> None:
        self.data_dir = data_dir
        self.max_upload_mb = max_upload_mb
        self.extra_args = extra_args
        self.proc: subprocess.Popen[bytes] | None = None
        self.url = ""

    def start(self, timeout: float = 90.0) -> Server:
        port = free_port()
        self.url = f"http://127.0.0.1:{port}"
        env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONPATH": str(REPO)}
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "app", "serve", "--host", "127.0.0.1", "--port", str(port), "--data-dir",
             str(self.data_dir), "--max-upload-mb", str(self.max_upload_mb), "--log-level", "warning",
             *self.extra_args],
            cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                err = self.proc.stderr.read().decode() if self.proc.stderr else ""
                raise RuntimeError(f"server exited with {self.proc.returncode}: {err[-2000:]}")
            try:
                if httpx.get(f"{self.url}/health", timeout=1.0).status_code == 200:
                    return self
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        self.stop()
        raise RuntimeError(f"server at {self.url} did not come up in {timeout} s")

    def stop(self, sig: int = signal.SIGTERM) -> None:
        if self.proc is None:
            return
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.proc.stderr:
            self.proc.stderr.close()
        self.proc = None

    @property
    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None


@pytest.fixture
def server(tmp_path: Path) -> Iterator[Server]:
    srv = Server(tmp_path / "data", extra_args=("--cors-origin", "http://dashboard.test")).start()
    yield srv
    srv.stop()


@pytest.fixture(scope="session")
def demo_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 40 s scripted drive written as BLF through the project DBC (built once per session)."""
    from app.demo.build import build_demo_log
    from app.demo.scenario import Scenario
    from app.settings import default_dbc_dir

    path = tmp_path_factory.mktemp("demo") / "drive.blf"
    dbc = default_dbc_dir()
    build_demo_log(path, dbc / "lashscope_ev.dbc", dbc / "lashscope_ev.map.toml",
                   Scenario(duration_s=40.0, brake_cycle=3))
    return path


def wait_for(client: httpx.Client, analysis_id: str, timeout: float = 120.0) -> dict[str, object]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        body: dict[str, object] = client.get(f"/analyses/{analysis_id}").json()
        if body["status"] in ("done", "failed"):
            return body
        time.sleep(0.2)
    raise AssertionError(f"analysis {analysis_id} did not finish in {timeout} s")


def create_vehicle(client: httpx.Client, name: str = "ev") -> dict[str, object]:
    r = client.post("/vehicles", data={"name": name, "preset": "paper"})
    assert r.status_code in (200, 201), r.text
    body: dict[str, object] = r.json()
    return body


def upload(client: httpx.Client, path: Path) -> httpx.Response:
    with path.open("rb") as fh:
        return client.post("/logs", files={"file": (path.name, fh, "application/octet-stream")})


def analysed(client: httpx.Client, log: Path, vehicle: str = "ev") -> tuple[str, str]:
    """Register ``vehicle``, upload ``log``, analyse it and wait until done; (log id, analysis id)."""
    create_vehicle(client, vehicle)
    log_id = upload(client, log).json()["id"]
    analysis_id = str(client.post("/analyses", json={"log_id": log_id, "vehicle": vehicle}).json()["id"])
    assert wait_for(client, analysis_id)["status"] == "done"
    return str(log_id), analysis_id


def worker_pids(parent: int) -> list[int]:
    """Job worker processes (spawned interpreters) whose parent is ``parent``."""
    found = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            ppid = int((proc / "stat").read_text().rsplit(")", 1)[1].split()[1])
            cmd = (proc / "cmdline").read_bytes()
        except (OSError, IndexError, ValueError):
            continue
        if ppid == parent and b"spawn_main" in cmd and b"resource_tracker" not in cmd:
            found.append(int(proc.name))
    return found


def alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def assert_gone(workers: list[int] | set[int], why: str, timeout: float = 15.0) -> None:
    """Wait up to ``timeout`` s for every pid in ``workers`` to exit; fail with ``why`` if one still runs."""
    deadline = time.monotonic() + timeout
    while any(alive(p) for p in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(alive(p) for p in workers), why


def running_worker(c: httpx.Client, srv: Server, url: str, timeout: float = 90.0) -> list[int]:
    """Wait until the job behind ``url`` reports progress from its worker; return the worker pids."""
    assert srv.proc is not None
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        body = c.get(url).json()
        job = body.get("job", body)
        pids = worker_pids(srv.proc.pid)
        if job["status"] == "running" and job["stage"] not in ("starting", "queued") and pids:
            return pids
        assert job["status"] in ("queued", "running"), body
        time.sleep(0.05)
    raise AssertionError(f"no running worker for {url}")
