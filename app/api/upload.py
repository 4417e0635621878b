"""Request bodies streamed to disk with a size cap, hashing on the way.

Two request shapes are accepted: ``multipart/form-data`` with one file part (``-F
file=@drive.blf``; other non-file fields are collected as small text values), or the raw
bytes as the body (``--data-binary @drive.blf`` with ``?filename=drive.blf``). Nothing is
held in memory beyond one network chunk. Over the cap, the partial file is deleted, up to
``drain_bytes`` of the rest of the body are read and dropped (so the client gets to read
the 413 response instead of a reset connection) and :class:`UploadTooLargeError` is raised.
"""

from __future__ import annotations

import contextlib
import hashlib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO
from urllib.parse import parse_qsl

from python_multipart.multipart import MultipartParser, parse_options_header
from starlette.requests import ClientDisconnect, Request

from app.errors import AppError, InputError, UploadTooLargeError

MAX_FIELD_BYTES = 64 * 1024


@dataclass
class UploadedFile:
    path: Path
    filename: str
    size: int
    sha256: str
    head: bytes  # first bytes, for format sniffing
    field_name: str = "file"


@dataclass
class UploadResult:
    files: list[UploadedFile] = field(default_factory=list)
    fields: dict[str, str] = field(default_factory=dict)


class _Sink:
    """One file being written: size-capped, hashed, head kept."""

    def __init__(self, path: Path, filename: str, field_name: str, cap: int) -> None:
        self.path, self.filename, self.field_name, self.cap = path, filename, field_name, cap
        self.size = 0
        self.hash = hashlib.sha256()
        self.head = b""
        self.fh: IO[bytes] | None = path.open("wb")

    def write(self, data: bytes) -> None:
        self.size += len(data)
        if self.size > self.cap:
            raise UploadTooLargeError(f"upload {self.filename!r} is larger than the {self.cap / 2**20:g} MiB cap "
                                      "(LASHSCOPE_MAX_UPLOAD_MB)")
        if len(self.head) < 4096:
            self.head += data[: 4096 - len(self.head)]
        self.hash.update(data)
        assert self.fh is not None
        self.fh.write(data)

    def close(self) -> UploadedFile:
        if self.fh is not None:
            self.fh.close()
            self.fh = None
        return UploadedFile(self.path, self.filename, self.size, self.hash.hexdigest(), self.head, self.field_name)

    def discard(self) -> None:
        if self.fh is not None:
            self.fh.close()
            self.fh = None
        self.path.unlink(missing_ok=True)


def _safe_name(name: str) -> str:
    base = name.replace("\\", "/").rsplit("/", 1)[-1].strip() or "upload"
    return "".join(c for c in base if c.isprintable())[:200]


class _Multipart:
    def __init__(self, boundary: bytes, new_path: object, cap: int, result: UploadResult) -> None:
        self.new_path, self.cap, self.result = new_path, cap, result
        self.sinks: list[_Sink] = []
        self._hname = b""
        self._hvalue = b""
        self._headers: dict[bytes, bytes] = {}
        self._sink: _Sink | None = None
        self._field: tuple[str, bytearray] | None = None
        self.parser = MultipartParser(boundary, {
            "on_part_begin": self._begin, "on_header_field": self._hf, "on_header_value": self._hv,
            "on_header_end": self._hend, "on_headers_finished": self._hdone, "on_part_data": self._data,
            "on_part_end": self._end,
        })

    def _begin(self) -> None:
        self._headers, self._sink, self._field = {}, None, None

    def _hf(self, data: bytes, start: int, end: int) -> None:
        self._hname += data[start:end]

    def _hv(self, data: bytes, start: int, end: int) -> None:
        self._hvalue += data[start:end]

    def _hend(self) -> None:
        self._headers[self._hname.lower()] = self._hvalue
        self._hname, self._hvalue = b"", b""

    def _hdone(self) -> None:
        _, opts = parse_options_header(self._headers.get(b"content-disposition", b""))
        name = opts.get(b"name", b"").decode("utf-8", "replace")
        if b"filename" in opts:
            filename = _safe_name(opts[b"filename"].decode("utf-8", "replace"))
            path = self.new_path(Path(filename).suffix)  # type: ignore[operator]
            self._sink = _Sink(path, filename, name or "file", self.cap)
            self.sinks.append(self._sink)
        else:
            self._field = (name, bytearray())

    def _data(self, data: bytes, start: int, end: int) -> None:
        if self._sink is not None:
            self._sink.write(data[start:end])
        elif self._field is not None:
            self._field[1].extend(data[start:end])
            if len(self._field[1]) > MAX_FIELD_BYTES:
                raise InputError(f"form field {self._field[0]!r} is longer than {MAX_FIELD_BYTES} bytes")

    def _end(self) -> None:
        if self._sink is not None:
            self.result.files.append(self._sink.close())
        elif self._field is not None:
            self.result.fields[self._field[0]] = self._field[1].decode("utf-8", "replace")


def rename_paths(message: str, names: Mapping[Path, str]) -> str:
    """``message`` with every stored file path (full or bare name) replaced by the name the user uploaded."""
    for path, shown in names.items():
        message = message.replace(str(path), shown).replace(path.name, shown)
    return message


@contextlib.contextmanager
def user_file_names(names: Mapping[Path, str]) -> Iterator[None]:
    """Errors raised inside name the user's uploaded files, never the store's internal temp names."""
    try:
        yield
    except Exception as exc:
        if isinstance(exc, AppError):
            exc.detail = rename_paths(exc.detail, names)
        elif exc.args and isinstance(exc.args[0], str):
            exc.args = (rename_paths(exc.args[0], names), *exc.args[1:])
        raise


async def _drain(request: Request, limit: int) -> None:
    seen = 0
    with contextlib.suppress(ClientDisconnect):
        async for chunk in request.stream():
            seen += len(chunk)
            if seen > limit:
                return


async def receive_upload(request: Request, new_path: object, cap: int, drain_bytes: int,
                         raw_filename: str | None = None, urlencoded_form: bool = False) -> UploadResult:
    """Stream the request body into files created by ``new_path(suffix)``; see the module docstring.

    With ``urlencoded_form``, an ``application/x-www-form-urlencoded`` body is read as form
    fields (no files); otherwise such a body is the raw file (curl ``--data-binary`` sends
    that content type by default).
    """
    ctype = request.headers.get("content-type", "")
    result = UploadResult()
    if urlencoded_form and ctype.startswith("application/x-www-form-urlencoded"):
        body = b""
        async for chunk in request.stream():
            body += chunk
            if len(body) > MAX_FIELD_BYTES:
                raise InputError(f"form is longer than {MAX_FIELD_BYTES} bytes")
        result.fields = dict(parse_qsl(body.decode("utf-8", "replace"), keep_blank_values=True))
        return result
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > cap + drain_bytes + MAX_FIELD_BYTES:
        raise UploadTooLargeError(f"upload of {int(declared) / 2**20:.1f} MiB is larger than the "
                                  f"{cap / 2**20:g} MiB cap (LASHSCOPE_MAX_UPLOAD_MB)")
    sinks: list[_Sink] = []
    try:
        if ctype.startswith("multipart/form-data"):
            _, opts = parse_options_header(ctype)
            boundary = opts.get(b"boundary")
            if not boundary:
                raise InputError("multipart upload without a boundary in Content-Type")
            mp = _Multipart(boundary, new_path, cap, result)
            sinks = mp.sinks
            async for chunk in request.stream():
                mp.parser.write(chunk)
            mp.parser.finalize()
        else:
            name = _safe_name(raw_filename or "upload.log")
            sink = _Sink(new_path(Path(name).suffix), name, "file", cap)  # type: ignore[operator]
            sinks = [sink]
            async for chunk in request.stream():
                sink.write(chunk)
            result.files.append(sink.close())
    except UploadTooLargeError:
        for s in sinks:
            s.discard()
        await _drain(request, drain_bytes)
        raise
    except ClientDisconnect as exc:
        for s in sinks:
            s.discard()
        raise InputError("the client disconnected before the upload was complete") from exc
    except BaseException:
        for s in sinks:
            s.discard()
        raise
    return result
