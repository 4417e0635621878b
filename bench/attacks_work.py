"""Work attacks: small requests that ask the server for a lot of work or a lot of disk.

Each attack runs against a real ``lashscope serve`` while a thread polls ``/health`` and samples the
server's memory; per attack it prints the answer (status and code), the server's CPU seconds, the CPU
seconds of the child processes it waited for meanwhile (reads within limits, job workers), its
peak RSS, its open file handles, the temporary files left in ``<data>/tmp``, the files the server
wrote outside the data directory (in the system temp folder) and the slowest ``/health``; then the
worst of each column and whether the targets were met.

Run alone: ``.venv/bin/python bench/attacks_work.py [--only NAME]`` (a few minutes; the attacks'
bytes come from ``tests/api/attacks.py``), ending with kill -9 of the server mid-upload and while a
child process reads a log, each followed by a restart; ``bench/fuzz_api.py`` runs the same attacks
after its fuzzed requests, without the kills.

Targets (issue 27): server RSS under 1 GiB and ``/health`` within 1 s through every attack; 0 files
written outside the data directory; 0 temporary files left after any attack or kill -9 plus restart;
at most 10 s of server CPU per request.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import socket
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from urllib.parse import urlsplit

import httpx

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from app.tempfiles import owner_tag  # noqa: E402
from tests.api.attacks import (  # noqa: E402
    backtracking_log,
    blf_bomb,
    damaged_bomb,
    described_format,
    gzip_bomb,
    many_stage_driveline,
    overlapping_dbc,
)
from tests.api.conftest import Server  # noqa: E402

BOMB_BYTES = 1 << 30  # what each compression bomb inflates to uncapped (twice that for candump)
TICK = os.sysconf("SC_CLK_TCK")


@dataclass
class Watch:
    """What the server did while one attack ran."""

    cpu_s: float = 0.0
    child_cpu_s: float = 0.0  # of the child processes the server waited for meanwhile (bounded reads, job workers)
    peak_rss_mib: float = 0.0
    health_max_ms: float = 0.0
    health_failures: int = 0
    answers: list[str] = field(default_factory=list)


def cpu_seconds(pid: int) -> float:
    """User + system CPU of the server process (its threads), from /proc."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK


def child_cpu_seconds(pid: int) -> float:
    """User + system CPU of the server's children it has waited for (bounded reads, job workers), from /proc."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[13]) + int(fields[14])) / TICK


def rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return 0.0


def handles(pid: int) -> int:
    return len(list(Path(f"/proc/{pid}/fd").iterdir()))


def outside_files(pid: int) -> set[str]:
    """Files in the system temp folder that name the server process as their writer."""
    mine = f"{owner_tag().split('-', 1)[0]}-{pid}-"
    return {p.name for p in Path(tempfile.gettempdir()).iterdir() if p.name.startswith(mine)}


@contextmanager
def watched(srv: Server) -> Iterator[Watch]:
    """Poll /health (every 0.2 s, 1 s timeout) and the server's RSS while the block runs."""
    assert srv.proc is not None
    pid, w, stop = srv.proc.pid, Watch(), threading.Event()

    def poll() -> None:
        with httpx.Client(base_url=srv.url, timeout=1.0) as c:
            while not stop.is_set():
                w.peak_rss_mib = max(w.peak_rss_mib, rss_mib(pid))
                t0 = time.perf_counter()
                try:
                    c.get("/health").raise_for_status()
                except httpx.HTTPError:
                    w.health_failures += 1
                w.health_max_ms = max(w.health_max_ms, (time.perf_counter() - t0) * 1e3)
                stop.wait(0.2)

    cpu0, child0 = cpu_seconds(pid), child_cpu_seconds(pid)
    w.peak_rss_mib = rss_mib(pid)
    t = threading.Thread(target=poll, daemon=True)
    t.start()
    try:
        yield w
    finally:
        stop.set()
        t.join()
        w.cpu_s = cpu_seconds(pid) - cpu0
        w.child_cpu_s = child_cpu_seconds(pid) - child0
        w.peak_rss_mib = max(w.peak_rss_mib, rss_mib(pid))


def answer(r: httpx.Response) -> str:
    try:
        return f"{r.status_code} {r.json().get('code', '')}".strip()
    except ValueError:
        return str(r.status_code)


def post_vehicle(c: httpx.Client, name: str, **files: bytes) -> str:
    form = {"name": name} if "driveline" in files else {"name": name, "preset": "paper"}
    return answer(c.post("/vehicles", data=form, files={k: (f"{k}.bin", v) for k, v in files.items()}))


def upload(c: httpx.Client, name: str, body: bytes) -> str:
    return answer(c.post("/logs", params={"filename": name}, content=body,
                         headers={"content-type": "application/octet-stream"}))


def repeated_fields(c: httpx.Client) -> str:
    toml = many_stage_driveline(4)
    files = [("driveline", (f"d{i}.toml", toml + b"#" * (200 << 10))) for i in range(4)]
    return answer(c.post("/vehicles", data={"name": "ev"}, files=files))


def concurrent_bombs(url: str, bomb: bytes, n: int) -> str:
    def one(_: int) -> str:
        with httpx.Client(base_url=url, timeout=300.0) as c:
            return upload(c, "drive.mf4.gz", bomb)

    with ThreadPoolExecutor(n) as pool:
        return ", ".join(sorted(set(pool.map(one, range(n)))))

SMALL_CANDUMP = b"".join(b"(1609459200.%06d) can0 123#0011223344556677\n" % (i * 1000) for i in range(3000))


def with_format(c: httpx.Client, log: bytes, description: bytes, log_name: str = "bench.txt",
                description_name: str = "bench.toml") -> str:
    return answer(c.post("/logs", files={"file": (log_name, log), "format_file": (description_name, description)}))


FRAME_REGEX = r"^(?P<time>[0-9.]+);(?P<id>[0-9A-F]+);(?P<data>[0-9A-F ]*)$"
DESCRIBED_LOG = b"t;id;data\n" + b"".join(b"%d.%03d;123;00 11 22 33\n" % (i // 1000, i % 1000) for i in range(3000))


def path_names(c: httpx.Client) -> str:
    evil = Path(tempfile.gettempdir()) / "lashscope-evil"
    got = with_format(c, DESCRIBED_LOG + b"9.999;123;00\n",
                      described_format(FRAME_REGEX, name=f"'../../../..{evil}'", comment="'/etc/passwd'",
                                       skip_lines="1"), f"../../../..{evil}.txt", f"{evil}.format.toml")
    written = [p.name for p in evil.parent.iterdir() if p.name.startswith(evil.name)]
    return f"{got}; files named after the paths: {len(written)}"


def format_attacks() -> list[tuple[str, Callable[[httpx.Client], str]]]:
    """Pathological format descriptions uploaded with a log (``POST /logs``, part ``format_file``)."""
    huge = FRAME_REGEX[:-1] + "(?:x)?" * 10_000 + "$"  # 60 kB, just inside the 64 kB of a description
    columns = "separator = ';'\ncolumns = { " + ", ".join(f"c{i} = {i}" for i in range(10**6)) + " }\n"
    wide = b"t\n" + b"0.1;123;" + b"00;" * 10**6 + b"\n"  # one line of a million columns
    return [
        ("format: backtracking regex, 5 lines (gzipped)",
         lambda c: with_format(c, backtracking_log(), described_format(), "bench.txt.gz")),
        ("format: backtracking regex, 2000 lines of 24 digits",
         lambda c: with_format(c, backtracking_log(2000, 24), described_format(), "bench2.txt.gz")),
        ("format: regex of 60 kB (10 000 groups)",
         lambda c: with_format(c, DESCRIBED_LOG, described_format(huge, skip_lines="1"))),
        (f"format: 10^6 columns ({len(columns) / 1e6:.0f} MB description)",
         lambda c: with_format(c, DESCRIBED_LOG, columns.encode())),
        ("format: a line of 10^6 columns, data_to_end",
         lambda c: with_format(c, wide, b"separator = ';'\ncolumns = {time = 0, id = 1, data = 2}\n"
                                        b"data_to_end = true\nskip_lines = 1\n", "wide.txt")),
        ("format: NUL bytes in the description",
         lambda c: with_format(c, DESCRIBED_LOG, described_format(FRAME_REGEX) + b"name = '\x00'\n\x00")),
        ("format: tables nested 30 000 deep", lambda c: with_format(c, DESCRIBED_LOG, b"name = " + b"[" * 30_000)),
        ("format: path names in fields and file names", path_names),
    ]


def stored_log(c: httpx.Client) -> str:
    r = c.post("/logs", params={"filename": "small.log"}, content=SMALL_CANDUMP,
               headers={"content-type": "application/octet-stream"})
    return str(r.json()["id"])


def proposal(c: httpx.Client, dbc: bytes | None = None, **fields: str) -> str:
    form = {"log_id": stored_log(c), **fields}
    files = {"dbc": ("car.dbc", dbc, "application/octet-stream")} if dbc is not None else None
    return answer(c.post("/vehicles/signal-map-proposal", data=form, files=files))


def concurrent_proposals(url: str, n: int) -> str:
    def one(_: int) -> str:
        with httpx.Client(base_url=url, timeout=300.0) as c:
            return proposal(c)

    with ThreadPoolExecutor(n) as pool:
        got = list(pool.map(one, range(n)))
    return ", ".join(f"{k} x{got.count(k)}" for k in sorted(set(got)))


def poll_job(c: httpx.Client, path: str, timeout: float = 600.0) -> str:
    """Poll ``path`` until its job ends; its final status (and error code)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        r = c.get(path)
        if r.status_code != 202:
            body = r.json()
            job = body.get("job") if isinstance(body, dict) else None
            if isinstance(job, dict):
                if job["status"] in ("done", "failed"):
                    return f"{job['status']} {(job.get('error') or {}).get('code', '')}".strip()
            else:
                return answer(r)
        time.sleep(0.25)
    return "still running"


def gap_job(c: httpx.Client) -> str:
    post_vehicle(c, "soft2", driveline=many_stage_driveline(24))
    r = c.post("/vehicles/soft2/gap-sensitivity")
    return f"{answer(r)} -> {poll_job(c, '/vehicles/soft2/gap-sensitivity')}"


def identification_of_a_bad_log(c: httpx.Client) -> str:
    """An identification of a log without one frame of the vehicle's DBC (a job of the long lane)."""
    post_vehicle(c, "idv")
    r = c.post("/identifications", json={"log_ids": [stored_log(c)], "vehicle": "idv"})
    if r.status_code != 202:
        return answer(r)
    return f"{answer(r)} -> {poll_job(c, '/identifications/' + r.json()['id'])}"


def route_attacks(url: str) -> list[tuple[str, Callable[[httpx.Client], str]]]:
    """The signal-map proposal, the gap sensitivity job and identification with absurd input."""
    big = str(10**30)
    return [
        ("proposal: 64 KiB of map overrides", lambda c: proposal(c, map="motor_speed_rpm=A.B\n" * 4000)),
        ("proposal: DBC, 1100 signals in one message", lambda c: proposal(c, overlapping_dbc(1100))),
        ("proposal: DBC, 400 overlapping + 500 messages", lambda c: proposal(c, overlapping_dbc(400, 500))),
        ("proposal: DBC of 5 MiB", lambda c: proposal(c, b"VERSION \"\"\n" + b" " * (5 << 20))),
        ("proposal: 6 at once", lambda c: concurrent_proposals(url, 6)),
        ("gap sensitivity POST, 24 stiff stages", lambda c: answer(c.post("/vehicles/stiff/gap-sensitivity"))),
        ("gap sensitivity, version 10^30 (GET, POST, status)",
         lambda c: ", ".join(answer(c.request(m, f"/vehicles/soft/gap-sensitivity{s}", params={"version": big}))
                             for m, s in (("GET", ""), ("POST", ""), ("GET", "/status")))),
        ("gap sensitivity POST, 24 soft stages (job)", gap_job),
        ("identification, 51 logs", lambda c: answer(c.post("/identifications", json={
            "log_ids": [f"log_{i}" for i in range(51)], "vehicle": "idv"}))),
        ("identification, id of 300 characters",
         lambda c: answer(c.get("/identifications/id_" + "a" * 300))),
        ("identification of a log without the vehicle's frames (job)", identification_of_a_bad_log),
    ]


def attacks(url: str, short: bool = False) -> list[tuple[str, Callable[[httpx.Client], str]]]:
    """The attacks (``short``: the bombs a quarter the size, those of :data:`SLOW` not built)."""
    size = BOMB_BYTES // (4 if short else 1)
    bombs = {fmt: gzip_bomb(fmt, size * (2 if fmt == "candump" else 1))
             for fmt in (("candump", "mf4") if short else ("candump", "asc", "trc", "mf4"))}
    plain_text = b"(1609459200.000000) can0 123#0011223344556677\n" * 330_000  # 15 MB candump, uncompressed
    listing: list[tuple[str, Callable[[httpx.Client], str]]] = [
        ("vehicle name '../../x' (path)", lambda c: post_vehicle(c, "../../x")),
        ("vehicle name with a NUL", lambda c: post_vehicle(c, "ev\x00x")),
        ("vehicle file field x4 (200 KiB each)", repeated_fields),
        ("driveline of 10 000 stages (1 MiB)", lambda c: post_vehicle(c, "ev", driveline=many_stage_driveline(10_000))),
        ("driveline of 30 stages", lambda c: post_vehicle(c, "ev", driveline=many_stage_driveline(30))),
        ("driveline, contact_damping a 200 KiB string",
         lambda c: post_vehicle(c, "ev", driveline=b'contact_damping = "' + b"f" * (200 << 10) + b'"\n'
                                + many_stage_driveline(4))),
        ("driveline, contact_damping a table",
         lambda c: post_vehicle(c, "ev", driveline=b"contact_damping = {law = 'full'}\n" + many_stage_driveline(4))),
        ("DBC, 1100 signals in one message", lambda c: post_vehicle(c, "ev", dbc=overlapping_dbc(1100))),
        ("DBC, 400 overlapping + 500 messages (124 KB)",
         lambda c: post_vehicle(c, "ev", dbc=overlapping_dbc(400, filler_messages=500))),
        ("DBC, 1000 overlapping + 1900 messages (438 KB)",
         lambda c: post_vehicle(c, "ev", dbc=overlapping_dbc(1000, filler_messages=1900))),
        ("gap sensitivity, 24 stiff stages (read)",
         lambda c: (post_vehicle(c, "stiff", driveline=many_stage_driveline(24, stiffness=1e8)),
                    answer(c.get("/vehicles/stiff/gap-sensitivity")))[1]),
        ("gap sensitivity, 24 soft stages (read)",
         lambda c: (post_vehicle(c, "soft", driveline=many_stage_driveline(24)),
                    answer(c.get("/vehicles/soft/gap-sensitivity")))[1]),
        ("candump, 15 MB uncompressed", lambda c: upload(c, "plain.log", plain_text)),
    ]
    for fmt, bomb in bombs.items():
        listing.append((f"gzip bomb {fmt}, {len(bomb) / 2**20:.1f} MiB gzipped",
                        partial(upload, name=f"drive.{fmt}.gz", body=bomb)))
    # every line damaged: no chunk of frames ever completes, so only a limit checked as the log is read stops it
    damaged = damaged_bomb(size // 2)
    listing.append((f"gzip bomb trc, every line damaged, {len(damaged) / 2**20:.1f} MiB gzipped",
                    partial(upload, name="damaged.trc.gz", body=damaged)))
    frames = 1_000_000 if short else 3_000_000
    blf = blf_bomb(frames)
    listing.append((f"BLF of zlib containers, {len(blf) / 2**20:.1f} MiB ({frames * 48 / 1e6:.0f} MB of frames)",
                    partial(upload, name="drive.blf", body=blf)))
    listing.append(("3 mf4 gzip bombs at once", lambda c: concurrent_bombs(url, bombs["mf4"], 3)))
    return listing + format_attacks() + route_attacks(url)


def kill_mid_upload(srv: Server) -> str:
    """A server killed with kill -9 while an upload arrives, then started again: temp files left."""
    parts = urlsplit(srv.url)
    with socket.create_connection((parts.hostname or "127.0.0.1", parts.port or 80)) as s:
        s.sendall(b"POST /logs?filename=cut.log HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                  b"Content-Type: application/octet-stream\r\nContent-Length: 8000000\r\n\r\n" + b"x" * 1_000_000)
        deadline = time.monotonic() + 10
        while not any((srv.data_dir / "tmp").iterdir()) and time.monotonic() < deadline:
            time.sleep(0.05)
        before = len(list((srv.data_dir / "tmp").iterdir()))
        srv.stop(signal.SIGKILL)
    srv.start()
    return f"temp files: {before} while it arrived, {len(list((srv.data_dir / 'tmp').iterdir()))} after the restart"


def children(pid: int) -> list[int]:
    """Process ids of ``pid``'s children (every thread's), from /proc."""
    out: list[int] = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(OSError):
            out += [int(p) for p in (task / "children").read_text().split()]
    return out


def _state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return ""


def kill_mid_bounded(srv: Server) -> str:
    """kill -9 of the server while a child process reads a log with a backtracking format description: whether
    the child outlived it, and the temp files after the restart."""
    assert srv.proc is not None
    pid = srv.proc.pid

    def send() -> None:
        with contextlib.suppress(httpx.HTTPError), httpx.Client(base_url=srv.url, timeout=60.0) as c:
            with_format(c, backtracking_log(), described_format(), "killed.txt.gz")

    t = threading.Thread(target=send, daemon=True)
    t.start()
    deadline = time.monotonic() + 30
    while not children(pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    kids = children(pid)
    time.sleep(1.0)  # the child is reading (and has inflated the log into tmp/)
    before = len(list((srv.data_dir / "tmp").iterdir()))
    srv.stop(signal.SIGKILL)
    time.sleep(0.5)
    alive = [k for k in kids if _state(k) not in ("", "Z")]
    srv.start()
    t.join(60)
    return (f"children {len(kids)}, alive after the kill {len(alive)}; temp files: {before} while it read, "
            f"{len(list((srv.data_dir / 'tmp').iterdir()))} after the restart")


# left out of the short form (``short=True``): seconds of CPU each, and each limit has its test in tests/api
SLOW = ("DBC, 400 overlapping", "DBC, 1000 overlapping", "candump, 15 MB", "format: backtracking regex, 2000 lines",
        "proposal: DBC, 400 overlapping", "3 mf4 gzip bombs")


def run(srv: Server, kill: bool = True, only: str = "", short: bool = False) -> list[str]:
    """Every work attack against ``srv`` (``only``: those whose name contains it; ``short``: without
    :data:`SLOW`), one printed line each; with
    ``kill``, last, the server is killed mid-upload and while a child process reads a log, and started again each
    time (on another port: ``srv.url`` changes)."""
    assert srv.proc is not None
    lines = ["attack | answer | server CPU s | child CPU s | peak RSS MiB | handles | tmp files | outside files | "
             "/health max ms (failed)"]
    before = outside_files(srv.proc.pid)
    with httpx.Client(base_url=srv.url, timeout=600.0) as c:
        for name, attack in attacks(srv.url, short):
            if only not in name or (short and name.startswith(SLOW)):
                continue
            with watched(srv) as w:
                got = attack(c)
            pid = srv.proc.pid
            tmp = len(list((srv.data_dir / "tmp").iterdir()))
            lines.append(f"{name} | {got} | {w.cpu_s:.2f} | {w.child_cpu_s:.2f} | {w.peak_rss_mib:.0f} | "
                         f"{handles(pid)} | {tmp} | {len(outside_files(pid) - before)} | {w.health_max_ms:.0f} "
                         f"({w.health_failures})")
    if kill:
        lines.append(f"kill -9 mid-upload, restart | {kill_mid_upload(srv)}")
        lines.append(f"kill -9 while a child reads a described log, restart | {kill_mid_bounded(srv)}")
    return lines


def worst(lines: list[str]) -> dict[str, float]:
    """The worst figure of each column over the attack rows :func:`run` printed (and the kill -9 rows' temp files
    after the restart and children alive after the kill)."""
    out = {"answers >= 500": 0.0, "server CPU s": 0.0, "child CPU s": 0.0, "peak RSS MiB": 0.0, "tmp files": 0.0,
           "outside files": 0.0, "/health max ms": 0.0, "/health failed": 0.0, "temp files after restart": 0.0,
           "children alive after kill": 0.0}
    for line in lines[1:]:
        cells = [c.strip() for c in line.split("|")]
        if len(cells) == 9:
            out["answers >= 500"] += sum(a.strip()[:1] in "50" for a in cells[1].replace(";", ",").split(","))
            for key, cell in zip(("server CPU s", "child CPU s", "peak RSS MiB"), cells[2:5], strict=True):
                if key != "child CPU s" or "(job)" not in cells[0]:  # a job has its own limits
                    out[key] = max(out[key], float(cell))
            out["tmp files"] = max(out["tmp files"], float(cells[6]))
            named = cells[1].split("files named after the paths: ")[1:]  # written where a path in the input said
            out["outside files"] = max(out["outside files"], float(cells[7]), *(float(n) for n in named))
            ms, failed = cells[8].rstrip(")").split(" (")
            out["/health max ms"] = max(out["/health max ms"], float(ms))
            out["/health failed"] += float(failed)
        elif "after the restart" in line:
            after = line.rsplit(", ", 1)[1].split()[0]
            out["temp files after restart"] = max(out["temp files after restart"], float(after))
            if "alive after the kill" in line:
                alive = line.split("alive after the kill ")[1].split(";")[0]
                out["children alive after kill"] = max(out["children alive after kill"], float(alive))
    return out


def met(figures: dict[str, float]) -> bool:
    """Issue 27's targets on the work attacks: RSS < 1 GiB, /health within 1 s and never failed, 0 temp files left
    (after kill -9 and a restart too), 0 files outside the data directory, <= 10 s of CPU per request in the server
    and in a child process, no answer >= 500."""
    return (figures["peak RSS MiB"] < 1024 and figures["/health max ms"] <= 1000 and not figures["/health failed"]
            and not figures["tmp files"] and not figures["temp files after restart"] and not figures["outside files"]
            and figures["server CPU s"] <= 10 and figures["child CPU s"] <= 10 and not figures["answers >= 500"]
            and not figures["children alive after kill"])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--only", default="", help="only the attacks whose name contains this")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="lashscope-attacks-"))
    srv = Server(work / "data", max_upload_mb=16.0).start()
    try:
        lines = run(srv, only=args.only)
        for line in lines:
            print(line, flush=True)
        figures = worst(lines)
        print("worst: " + ", ".join(f"{k} {v:g}" for k, v in figures.items()))
        print(f"work targets: {'all met' if met(figures) else 'NOT MET'}")
    finally:
        srv.stop()
    return 0 if met(figures) else 1


if __name__ == "__main__":
    raise SystemExit(main())
