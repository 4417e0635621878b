"""Key and method attacks on a real ``lashscope serve`` (run from ``bench/fuzz_api.py``, or alone).

Run: ``.venv/bin/python bench/attacks_keys.py [--flood 6000] [--huge 300]``.

A fresh server on a loopback port with one admin key, then one attack after another:

- **every method**: GET, HEAD, POST, PUT, PATCH, DELETE and OPTIONS on every route the app declares
  (walked from its routers: the OpenAPI document's and the dashboard's, docs' and static files'), with
  the key, without one and with a wrong one, then with ids of 303 characters (no answer may be 5xx);
- **wrong-key flood**: distinct wrong keys from one address as fast as one client sends them
  (they must be 401 and then 429, while another address with the right key is still served);
- **huge-token flood**: wrong keys of 1 MiB each (the server must keep none of them);
- **revoked last key**: every key revoked, then anonymous writes (all must stay 401).

After each attack it prints the statuses and, from ``/proc``, the server's peak RSS during the
attack (``VmHWM``, reset before it) and RSS after it, its open file handles, the files left in the
data directory's ``tmp/`` and the CPU seconds the server spent on the attack.
"""

from __future__ import annotations

import argparse
import os
import secrets
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from app.storage.url import open_store  # noqa: E402
from tests.api.conftest import Server  # noqa: E402

METHODS = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS")
MiB = 1 << 20


@dataclass(frozen=True)
class Usage:
    """What the server process holds and has spent, read from ``/proc/<pid>``."""

    peak_rss_mib: float
    rss_mib: float
    handles: int
    temp_files: int
    cpu_s: float


def _status_kib(pid: int, field: str) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return float(line.split()[1])
    return float("nan")


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime + stime


def _reset_peak(pid: int) -> bool:
    """Reset the process' peak RSS (``VmHWM``) so the next reading is this attack's (Linux, same user)."""
    try:
        Path(f"/proc/{pid}/clear_refs").write_text("5")
        return True
    except OSError:
        return False


def usage(srv: Server, cpu_before: float) -> Usage:
    assert srv.proc is not None
    pid = srv.proc.pid
    return Usage(peak_rss_mib=_status_kib(pid, "VmHWM") / 1024, rss_mib=_status_kib(pid, "VmRSS") / 1024,
                 handles=len(os.listdir(f"/proc/{pid}/fd")), temp_files=len(list((srv.data_dir / "tmp").iterdir())),
                 cpu_s=_cpu_s(pid) - cpu_before)


@contextmanager
def measured(srv: Server, name: str) -> Iterator[Counter[int]]:
    """Run an attack, counting statuses into the yielded counter; print them and the server's usage."""
    assert srv.proc is not None
    statuses: Counter[int] = Counter()
    peak_reset = _reset_peak(srv.proc.pid)
    cpu0 = _cpu_s(srv.proc.pid)
    t0 = time.perf_counter()
    yield statuses
    wall = time.perf_counter() - t0
    u = usage(srv, cpu0)
    peak = f"{u.peak_rss_mib:.0f} MiB" + ("" if peak_reset else " (peak since start: VmHWM not resettable)")
    print(f"{name}: {sum(statuses.values())} requests in {wall:.1f} s; statuses "
          + ", ".join(f"{k}: {v}" for k, v in sorted(statuses.items())))
    print(f"  server: peak RSS {peak}, RSS after {u.rss_mib:.0f} MiB, open handles {u.handles}, "
          f"temp files {u.temp_files}, CPU {u.cpu_s:.2f} s")


def _send(c: httpx.Client, statuses: Counter[int], method: str, path: str, headers: dict[str, str]) -> None:
    try:
        r = c.request(method, path, headers=headers)
        statuses[r.status_code] += 1
    except httpx.HTTPError:
        statuses[0] += 1  # no answer: counted as a failure


def app_routes() -> list[str]:
    """Every path template the app declares, walked from its routers (the OpenAPI document leaves out the
    dashboard, the docs and the document itself)."""
    from app.api.main import create_app
    from app.settings import Settings

    def walk(routes: list[Any], prefix: str = "") -> Iterator[str]:
        for r in routes:
            ctx = getattr(r, "include_context", None)
            if ctx is not None:
                yield from walk(ctx.included_router.routes, prefix + ctx.prefix)
            elif getattr(r, "path", None) is not None:
                yield prefix + r.path

    app = create_app(Settings(data_dir=Path(tempfile.mkdtemp(prefix="lashscope-routes-")) / "data"))
    return sorted(set(walk(app.routes)))


def _paths(c: httpx.Client, auth: dict[str, str], fill: str = "x0") -> list[str]:
    """Every route of the app with its path parameters filled in with ``fill`` (ids that do not exist); fails if
    the OpenAPI document has a route the walk did not find."""
    templates = app_routes()
    documented = set(c.get("/openapi.json", headers=auth).json()["paths"])
    assert documented <= set(templates), sorted(documented - set(templates))
    out = []
    for template in templates:
        path = template
        while "{" in path:
            a, b = path.index("{"), path.index("}")
            path = path[:a] + fill + path[b + 1:]
        out.append(path)
    return out


def every_method(srv: Server, c: httpx.Client, key: str) -> int:
    """Every method on every route with the key, without one, with a wrong one; returns the 5xx count."""
    admin = {"Authorization": f"Bearer {key}"}
    wrong = {"Authorization": f"Bearer lsk_{'0' * 12}_{secrets.token_urlsafe(32)}"}
    paths = _paths(c, admin)
    long_ids = _paths(c, admin, "id_" + "a" * 300)  # longer than a file name
    with measured(srv, f"every method ({len(METHODS)} methods x {len(paths)} routes x 3 keys, then ids of 303 "
                       "characters with the key)") as statuses:
        for headers, round_paths in ((admin, paths), ({}, paths), (wrong, paths), (admin, long_ids)):
            for path in round_paths:
                for method in METHODS:
                    _send(c, statuses, method, path, headers)
            if headers is wrong:
                time.sleep(2.5)  # the wrong keys' bucket refills before the next round
    return sum(v for k, v in statuses.items() if k >= 500 or k == 0)


def wrong_key_flood(srv: Server, c: httpx.Client, key: str, n: int) -> None:
    with measured(srv, f"wrong-key flood ({n} distinct wrong keys from one address)") as statuses:
        for _ in range(n):
            _send(c, statuses, "GET", "/logs", {"Authorization": f"Bearer lsk_{secrets.token_hex(6)}_"
                                                                 f"{secrets.token_urlsafe(32)}"})
    other_address = httpx.HTTPTransport(local_address="127.0.0.2")
    with httpx.Client(base_url=srv.url, timeout=30.0, transport=other_address) as other:
        r = other.get("/logs", headers={"Authorization": f"Bearer {key}"})
    print(f"  meanwhile the right key from another address (127.0.0.2): {r.status_code}")
    time.sleep(2.5)


def huge_token_flood(srv: Server, c: httpx.Client, n: int) -> None:
    huge = "lsk_" + "A" * MiB
    with measured(srv, f"huge-token flood ({n} wrong keys of 1 MiB)") as statuses:
        for _ in range(n):
            _send(c, statuses, "GET", "/logs", {"Authorization": f"Bearer {huge}"})
    time.sleep(2.5)


def revoked_last_key(srv: Server, c: httpx.Client, key_id: str) -> None:
    store = open_store(srv.data_dir)
    try:
        store.revoke_key(key_id)
    finally:
        store.close()
    time.sleep(1.2)  # the server re-reads its keys within a second
    writes: list[tuple[str, str, Callable[[], dict[str, object]]]] = [
        ("POST", "/vehicles", lambda: {"data": {"name": "ev", "preset": "paper"}}),
        ("POST", "/analyses", lambda: {"json": {"log_id": "log_x0", "vehicle": "ev"}}),
        ("PUT", "/vehicles", dict), ("PATCH", "/logs/x0", dict), ("DELETE", "/logs/x0", dict),
        ("GET", "/logs", dict)]
    with measured(srv, "every key revoked, anonymous reads and writes") as statuses:
        for _ in range(20):
            for method, path, extra in writes:
                try:
                    statuses[c.request(method, path, **extra()).status_code] += 1  # type: ignore[arg-type]
                except httpx.HTTPError:
                    statuses[0] += 1


def run(work: Path, flood: int, huge: int) -> int:
    """All the attacks on a fresh server in ``work``; returns the number of 5xx (or unanswered) requests."""
    data = work / "keys-data"
    store = open_store(data)
    key, token = store.create_key("admin", "attacks")
    store.close()
    srv = Server(data, max_upload_mb=16.0).start()
    try:
        with httpx.Client(base_url=srv.url, timeout=120.0) as c:
            bad = every_method(srv, c, token)
            print(f"every method: answers 500 or worse (or none): {bad}")
            wrong_key_flood(srv, c, token, flood)
            huge_token_flood(srv, c, huge)
            revoked_last_key(srv, c, key.id)
            assert c.get("/health").json()["status"] == "ok"
    finally:
        srv.stop()
    return bad


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--flood", type=int, default=6000, help="wrong keys in the flood")
    ap.add_argument("--huge", type=int, default=300, help="1 MiB wrong keys")
    args = ap.parse_args()
    return 1 if run(Path(tempfile.mkdtemp(prefix="lashscope-keys-")), args.flood, args.huge) else 0


if __name__ == "__main__":
    raise SystemExit(main())
