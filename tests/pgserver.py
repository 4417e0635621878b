"""A real PostgreSQL server for the tests: ``initdb`` into a temporary directory, ``postgres`` on 127.0.0.1.

The server listens on a free loopback port (its unix socket stays in its own directory), trusts
local connections of the role ``lashscope`` and runs without fsync (the tests never need the data
after a crash of the machine). PostgreSQL refuses to run as root, so under root it runs as the
``postgres`` user Debian's package creates. The binaries are those of Debian's ``postgresql``
package (``/usr/lib/postgresql/<version>/bin``, installed by ``.ci/run``) or ``LASHSCOPE_PG_BINDIR``;
without them the tests that need the server are skipped with that reason.
"""

from __future__ import annotations

import os
import pwd
import shutil
import signal
import subprocess
import tempfile
import time
import uuid
from pathlib import Path

from tests.api.conftest import free_port

ROLE = "lashscope"


def find_bindir() -> Path | None:
    """The directory of ``initdb`` and ``postgres``, or None when PostgreSQL is not installed."""
    named = os.environ.get("LASHSCOPE_PG_BINDIR")
    candidates = [Path(named)] if named else []
    candidates += sorted(Path("/usr/lib/postgresql").glob("*/bin"), key=lambda p: int(p.parent.name)
                         if p.parent.name.isdigit() else 0, reverse=True)
    on_path = shutil.which("initdb")
    if on_path:
        candidates.append(Path(on_path).parent)
    for d in candidates:
        if (d / "initdb").is_file() and (d / "postgres").is_file():
            return d
    return None


def unavailable_reason() -> str | None:
    """Why no test server can be started here (None: it can)."""
    if find_bindir() is None:
        return ("PostgreSQL binaries not found (Debian package 'postgresql', or set LASHSCOPE_PG_BINDIR): "
                "the PostgreSQL store tests are skipped")
    try:
        import psycopg  # noqa: F401
    except ImportError:
        return "the psycopg driver is not installed (pip install -e '.[dev]')"
    if os.geteuid() == 0:
        try:
            pwd.getpwnam("postgres")
        except KeyError:
            return "running as root and there is no 'postgres' user to run the server as"
    return None


class PgServer:
    """One ``postgres`` process for a test session; :meth:`database` hands out fresh databases."""

    def __init__(self) -> None:
        bindir = find_bindir()
        assert bindir is not None
        self.bindir = bindir
        self.dir = Path(tempfile.mkdtemp(prefix="lashscope-pg-"))
        self.port = 0
        self.proc: subprocess.Popen[bytes] | None = None
        self._as_user: list[str] = []
        if os.geteuid() == 0:  # postgres refuses root
            shutil.chown(self.dir, "postgres", "postgres")
            self._as_user = ["runuser", "-u", "postgres", "--"]
        self.dir.chmod(0o700)

    def _run(self, *args: str) -> None:
        subprocess.run([*self._as_user, *args], check=True, capture_output=True, timeout=300)

    def start(self, timeout_s: float = 120.0) -> PgServer:
        data = self.dir / "data"
        self._run(str(self.bindir / "initdb"), "-D", str(data), "-U", ROLE, "--auth=trust", "-E", "UTF8",
                  "--no-sync", "--locale=C")
        for _ in range(3):  # a free port may be taken between finding it and binding it
            self.port = free_port()
            log = (self.dir / "server.log").open("wb")
            self.proc = subprocess.Popen(
                [*self._as_user, str(self.bindir / "postgres"), "-D", str(data), "-p", str(self.port),
                 "-k", str(self.dir), "-c", "listen_addresses=127.0.0.1", "-c", "fsync=off",
                 "-c", "synchronous_commit=off", "-c", "full_page_writes=off", "-c", "max_connections=300",
                 "-c", "shared_buffers=16MB"],
                stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
            log.close()
            if self._wait_ready(timeout_s):
                return self
        self.stop()
        raise RuntimeError(f"postgres did not start: {(self.dir / 'server.log').read_text()[-2000:]}")

    def _wait_ready(self, timeout_s: float) -> bool:
        import psycopg

        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            assert self.proc is not None
            if self.proc.poll() is not None:
                return False
            try:
                with psycopg.connect(self.url("postgres"), connect_timeout=2):
                    return True
            except psycopg.OperationalError:
                time.sleep(0.2)
        return False

    def url(self, database: str) -> str:
        return f"postgresql://{ROLE}@127.0.0.1:{self.port}/{database}"

    def database(self) -> str:
        """A new empty database; returns its URL."""
        import psycopg

        name = f"t_{uuid.uuid4().hex[:12]}"
        with psycopg.connect(self.url("postgres"), autocommit=True) as db:
            db.execute(f"CREATE DATABASE {name}")
        return self.url(name)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGINT)  # "fast shutdown": ends the sessions, then exits
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
        self.proc = None
        shutil.rmtree(self.dir, ignore_errors=True)
