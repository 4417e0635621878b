"""Seeded random requests for fuzzing the API: malformed multipart uploads, hostile driveline
TOML, odd JSON bodies and query parameters. The same seed gives the same requests, so a 500 found
by ``bench/fuzz_api.py`` is replayed by its seed.

The generator knows nothing of the server's internals: it mutates what a client would send
(a valid multipart upload, the paper preset's TOML, a valid analysis request) and adds the
classic hostile inputs (mismatched boundaries, truncation, huge headers and names, binary
files, deep nesting, NaN and huge numbers).
"""

from __future__ import annotations

import json
import random
from dataclasses import dataclass, field
from typing import Any

NASTY = ["nan", "NaN", "inf", "-inf", "1e309", "-1", "0", "1", "2.5", "9" * 40, "", " ", "%00", "\u00e9\u4e2d",
         "0x10", "1e-320", "true", "null", "[]", "-0", "+3", "1_000", "../../etc/passwd", "a" * 3000]

TOML_VALUES = [*NASTY, "-1e6", "1e12", "1e-12", "3", "[1, 2]", '"x"', "{}"]


@dataclass
class FuzzRequest:
    method: str
    path: str
    params: dict[str, str] = field(default_factory=dict)
    headers: dict[str, str] = field(default_factory=dict)
    content: bytes | None = None

    def describe(self) -> str:
        size = 0 if self.content is None else len(self.content)
        return f"{self.method} {self.path} params={self.params} headers={list(self.headers)} body={size} B"


def _bytes(rng: random.Random, n: int) -> bytes:
    return rng.randbytes(n)


def _name(rng: random.Random) -> str:
    kind = rng.randrange(6)
    if kind == 0:
        return "a" * rng.choice([0, 1, 254, 255, 256, 5000])
    if kind == 1:
        return rng.choice(["../../x.blf", "x\x00y.blf", "\u00e9t\u00e9.asc", "C:\\logs\\d.blf", "d.blf.gz", ".blf",
                           "x." + "g" * 300, "a\r\nb.blf", "\"q\".blf"])
    return f"drive{rng.randrange(100)}." + rng.choice(["blf", "asc", "log", "trc", "csv", "mf4", "gz", "toml"])


def _part(rng: random.Random, boundary: bytes, field_name: str, filename: str | None, data: bytes) -> bytes:
    disp = f'form-data; name="{field_name}"' + (f'; filename="{filename}"' if filename is not None else "")
    head = b"Content-Disposition: " + disp.encode("utf-8", "replace") + b"\r\n"
    if rng.random() < 0.2:
        head += b"X-Pad: " + b"p" * rng.choice([10, 5000, 20000, 2_000_000]) + b"\r\n"
    if rng.random() < 0.1:
        head += b"no colon header line\r\n"
    return b"--" + boundary + b"\r\n" + head + b"\r\n" + data + b"\r\n"


def _multipart(rng: random.Random, fields: list[tuple[str, str | None, bytes]]) -> tuple[bytes, str]:
    boundary = rng.choice([b"XyZ", b"----lashscope" + str(rng.randrange(10**6)).encode(), b"a" * 70, b"b" * 300])
    body = b"".join(_part(rng, boundary, f, n, d) for f, n, d in fields)
    if rng.random() < 0.8:
        body += b"--" + boundary + b"--\r\n"
    mutation = rng.randrange(8)
    if mutation == 0 and body:
        body = body[: rng.randrange(len(body))]  # cut anywhere: no closing boundary, half a header
    elif mutation == 1:
        boundary = boundary[::-1] + b"Q"  # the header names another boundary than the body uses
    elif mutation == 2 and body:
        i = rng.randrange(len(body))
        body = body[:i] + _bytes(rng, rng.randrange(1, 64)) + body[i:]
    ctype = rng.choice([f"multipart/form-data; boundary={boundary.decode()}",
                        f'multipart/form-data; boundary="{boundary.decode()}"', "multipart/form-data",
                        "multipart/form-data; boundary=", f"multipart/mixed; boundary={boundary.decode()}"])
    if rng.random() < 0.75:
        ctype = f"multipart/form-data; boundary={boundary.decode()}"
    return body, ctype


def _toml(rng: random.Random, preset: str) -> bytes:
    kind = rng.randrange(7)
    if kind == 0:
        return _bytes(rng, rng.randrange(1, 4096))
    if kind == 1:
        depth = rng.choice([100, 1000, 50_000])
        return b"a = " + b"[" * depth + b"]" * rng.choice([0, depth])
    if kind == 2:
        return b"".join(b"[" + b".".join([b"t"] * rng.randrange(1, 400)) + b"]\nx = 1\n" for _ in range(3))
    lines = preset.splitlines()
    for _ in range(rng.randrange(1, 8)):
        i = rng.randrange(len(lines))
        if "=" in lines[i] and rng.random() < 0.7:
            key = lines[i].split("=", 1)[0]
            lines[i] = f"{key}= {rng.choice(TOML_VALUES)}"
        elif rng.random() < 0.5:
            del lines[i]
        else:
            lines.insert(i, rng.choice(["[stage]", "[[stage]]", "kind = \"chain\"", "[gaps.x]", "x = ", "]]"]))
    return "\n".join(lines).encode("utf-8", "surrogatepass")


def _query(rng: random.Random, names: list[str]) -> dict[str, str]:
    return {n: rng.choice([*NASTY, str(rng.randrange(-5, 3000)), str(rng.uniform(-100, 1000))])
            for n in names if rng.random() < 0.7}


def _json_body(rng: random.Random, log_id: str) -> bytes:
    kind = rng.randrange(6)
    if kind == 0:
        return b"[" * rng.choice([10, 10_000, 100_000])
    if kind == 1:
        return _bytes(rng, rng.randrange(1, 512))
    options: dict[str, Any] = {k: json.loads(rng.choice(["1e308", "-1", "0", "true", "null", "\"x\"", "[]", "2.5"]))
                               for k in rng.sample(["whole_log", "min_dwell_s", "torque_band", "model", "dt",
                                                    "post_window_s", "x"], rng.randrange(0, 4))}
    body = {"log_id": rng.choice([log_id, "log_nope", "", 5]), "vehicle": rng.choice(["ev", "nope", None]),
            "options": rng.choice([options, [], "x", None])}
    return json.dumps(body).encode()


FORMAT_KEYS = ["name", "regex", "separator", "columns", "data_to_end", "time_unit", "time_encoding", "id_encoding",
               "data_encoding", "skip_lines", "comment", "extended", "extended_values", "tx_values", "channel_base",
               "x"]
FRAME_REGEX = r"^(?P<time>[0-9.]+);(?P<id>[0-9A-F]+);(?P<data>[0-9A-F ]*)$"
REGEXES = [FRAME_REGEX, "(", "^(?P<time>.*)$", "(?P<time>)(?P<id>)(?P<data>)", "[" * 300, "(?P<time>\\d+)" * 3,
           "(?P<x>a)", "\\", "(?P<time>a{1,65535}){1,65535}", "(?P<id>.)(?P<time>.)(?P<data>.)(?P=id)", "\x00"]


def _description(rng: random.Random) -> bytes:
    """A format description of a text log (``format_file`` of ``POST /logs``): one in twenty as documented, the
    rest with hostile values, unknown keys, broken TOML or binary bytes (none whose regex backtracks: that is
    ``tests/api/attacks.py``'s)."""
    kind = rng.randrange(20)
    if kind == 0:
        return f"regex = '{FRAME_REGEX}'\nskip_lines = 1\n".encode()
    if kind == 1:
        return _bytes(rng, rng.randrange(1, 2048))
    if kind == 2:
        return b"name = " + b"[" * rng.choice([100, 5000, 40_000])
    columns = "separator = ';'\ncolumns = {time = 0, id = 1, data = 2}"
    lines = [rng.choice([f"regex = '{rng.choice(REGEXES)}'", columns])]
    for key in rng.sample(FORMAT_KEYS, rng.randrange(0, 6)):
        value = rng.choice([*TOML_VALUES, '"whitespace"', '"\\t"', '";;"', '"ms"', '"hex"', '"field"', "{time = 999}",
                            '["x", 1]', '"../../etc/passwd"', "{" + ", ".join(f"c{i} = {i}" for i in range(300)) + "}"])
        lines.append(f"{key} = {value}")
    return "\n".join(lines).encode("utf-8", "surrogatepass")


def _text_log(rng: random.Random) -> bytes:
    rows = [f"{i / 100:.3f};{rng.choice(['123', '7FF', '1FFFFFFF', 'x', ''])};{rng.choice(['00 11', '', 'zz'])}"
            for i in range(rng.randrange(0, 50))]
    return ("t;id;data\n" + "\n".join(rows)).encode() + (_bytes(rng, 64) if rng.random() < 0.2 else b"")


def _override_lines(rng: random.Random) -> str:
    roles = ["motor_speed_rpm", "motor_torque_nm", "brake_pressed", "x", ""]
    return "\n".join(rng.choice([f"{rng.choice(roles)}=MCU_Speed.MotorSpeed", f"{rng.choice(roles)}=-",
                                  f"invert {rng.choice(roles)}", f"keep {rng.choice(roles)}", "=", "a" * 500,
                                  f"{rng.choice(roles)}={rng.choice(NASTY)}"]) for _ in range(rng.randrange(0, 6)))


def _small_dbc(rng: random.Random) -> bytes:
    lines = ["VERSION \"\"", "", "BU_: ECU", f"BO_ {rng.choice(['291', '-1', '99999999999', 'x'])} M: "
             f"{rng.choice(['8', '64', '0', '-3'])} ECU"]
    lines += [f" SG_ S{i} : {rng.randrange(-8, 70)}|{rng.randrange(-1, 70)}@{rng.choice('01x')}{rng.choice('+-')} "
              f"({rng.choice(NASTY[:8])},0) [0|1] \"\" ECU" for i in range(rng.randrange(0, 5))]
    return "\n".join(lines).encode()


def _id_json(rng: random.Random, log_id: str) -> bytes:
    """An identification request that never queues one (an unknown log, a repeated one or a bad field, at least)."""
    if rng.random() < 0.2:
        return _json_body(rng, log_id)
    unknown = f"log_{rng.randrange(16**16):016x}"
    body: dict[str, Any] = {
        "log_ids": rng.choice([[log_id, unknown], [unknown], [log_id, log_id], [], [log_id] * 60, "x", [5]]),
        "vehicle": rng.choice(["ev", "nope", "", None, "../x"]),
        "validate_log_ids": rng.choice([[], [log_id], [unknown] * 11, None]),
        "params": rng.choice([["stiffness"], ["x"], [], ["lash", "lash"], None]),
        "seed": rng.choice([0, -1, 2**40, "x", 1.5]), "vehicle_version": rng.choice([None, 0, 1, 10**30, "x"])}
    for key in rng.sample(list(body), rng.randrange(0, 3)):
        del body[key]
    return json.dumps(body).encode()


def requests(seed: int, n: int, preset_toml: str, analysis_id: str = "an_0000000000000000",
             log_id: str = "log_0000000000000000") -> list[FuzzRequest]:
    """``n`` requests drawn with ``seed`` (``analysis_id``/``log_id``: existing ones reach deeper code)."""
    rng = random.Random(seed)
    out: list[FuzzRequest] = []
    for _ in range(n):
        kind = rng.randrange(10)
        if kind >= 6:
            out.append(_newer_route(rng, kind, log_id))
            continue
        if kind == 0:  # log uploads
            files = [("file", _name(rng), _bytes(rng, rng.choice([0, 10, 5000, 70_000])))]
            if rng.random() < 0.2:
                files += [(rng.choice(["file", "x", ""]), rng.choice([None, _name(rng)]), b"v")] * rng.randrange(1, 20)
            body, ctype = _multipart(rng, files)
            out.append(FuzzRequest("POST", "/logs", _query(rng, ["filename"]), {"content-type": ctype}, body))
        elif kind == 1:  # vehicles with hostile TOML
            fields: list[tuple[str, str | None, bytes]] = [("name", None, rng.choice([b"ev", b"fz", b"", b"A B",
                                                                                     b"x" * 100]))]
            fields.append((rng.choice(["driveline", "signal_map", "dbc"]), _name(rng), _toml(rng, preset_toml)))
            body, ctype = _multipart(rng, fields)
            out.append(FuzzRequest("POST", "/vehicles", {}, {"content-type": ctype}, body))
        elif kind == 2:  # raw-body upload
            out.append(FuzzRequest("POST", "/logs", _query(rng, ["filename"]),
                                   {"content-type": rng.choice(["application/octet-stream", "text/plain", ""])},
                                   _bytes(rng, rng.choice([0, 1, 100, 4096]))))
        elif kind == 3:  # JSON bodies
            # diagnoses of an unknown analysis only: a valid one would queue minutes of fitting per request
            unknown = f"/analyses/an_{rng.randrange(16**16):016x}/diagnoses"
            out.append(FuzzRequest("POST", rng.choice(["/analyses", unknown, "/live/sessions"]), {},
                                   {"content-type": rng.choice(["application/json", "text/plain"])},
                                   _json_body(rng, log_id)))
        else:  # query parameters
            path, names = rng.choice([
                (f"/analyses/{analysis_id}/speed", ["t0", "t1", "max_points", "event", "format", "method"]),
                (f"/analyses/{analysis_id}/events/{rng.choice(['0', '1', '-1', '999', 'x'])}/speed",
                 ["max_points", "format", "method"]),
                (f"/analyses/{analysis_id}/signals/{rng.choice(['motor_speed', 'x', '%2e%2e'])}",
                 ["t0", "t1", "max_points", "format", "method"]),
                (f"/analyses/{analysis_id}/tolerance", ["n", "seed"]),
                (f"/analyses/{analysis_id}/events", ["included"]),
                ("/logs", ["limit", "offset"]), ("/analyses", ["limit", "offset", "log_id"]),
                (f"/vehicles/{rng.choice(['ev', 'nope', '..'])}/versions/{rng.choice(['1', '0', '-1', 'x', '99'])}",
                 []),
                (f"/logs/{rng.choice([log_id, 'x', ''])}", []),
            ])
            out.append(FuzzRequest("GET", path, _query(rng, names)))
    return out


def _newer_route(rng: random.Random, kind: int, log_id: str) -> FuzzRequest:
    """Format descriptions with a log, the signal-map proposal, the gap sensitivity and identifications."""
    if kind == 6:
        parts: list[tuple[str, str | None, bytes]] = [("file", _name(rng), _text_log(rng)),
                                                      ("format_file", _name(rng), _description(rng))]
        if rng.random() < 0.1:
            parts.append(("format_file", "again.toml", _description(rng)))
        body, ctype = _multipart(rng, parts)
        return FuzzRequest("POST", "/logs", {}, {"content-type": ctype}, body)
    if kind == 7:  # a stored log one in twenty-five times: the rest are refused before a proposal starts
        form: list[tuple[str, str | None, bytes]] = [
            ("log_id", None, (log_id if rng.random() < 0.04 else rng.choice(["log_nope", "", "../x", "a" * 300,
                                                                              "x\x00"])).encode())]
        if rng.random() < 0.6:
            form.append(("map", None, _override_lines(rng).encode()))
        if rng.random() < 0.5:
            form.append((rng.choice(["dbc", "dbc", "file"]), _name(rng), rng.choice([_small_dbc(rng),
                                                                                      _bytes(rng, 300)])))
        body, ctype = _multipart(rng, form)
        return FuzzRequest("POST", "/vehicles/signal-map-proposal", {}, {"content-type": ctype}, body)
    if kind == 8:
        name = rng.choice(["ev", "nope", "..", "a" * 300, "EV"])
        method, tail = rng.choice([("GET", ""), ("POST", ""), ("GET", "/status"), ("DELETE", ""), ("PUT", "")])
        return FuzzRequest(method, f"/vehicles/{name}/gap-sensitivity{tail}", _query(rng, ["version", "compute"]))
    if rng.random() < 0.5:
        return FuzzRequest("POST", "/identifications", {}, {"content-type": "application/json"}, _id_json(rng, log_id))
    ident = rng.choice(["id_0123456789abcdef", "id_" + "a" * 300, "id_..", "x", "id_%2e%2e", "ba_1"])
    method, tail = rng.choice([("GET", ""), ("DELETE", ""), ("GET", "/vehicle"), ("POST", "/apply"), ("PATCH", "")])
    return FuzzRequest(method, f"/identifications/{ident}{tail}")
