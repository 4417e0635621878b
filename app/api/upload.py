"""Request bodies streamed to disk with a size cap, hashing on the way.

Two request shapes are accepted: ``multipart/form-data`` with one file part (``-F
file=@drive.blf``; other non-file fields are collected as small text values), or the raw
bytes as the body (``--data-binary @drive.blf`` with ``?filename=drive.blf``). Nothing is
held in memory beyond one network chunk. Over the cap, the partial file is deleted, up to
``drain_bytes`` of the rest of the body are read and dropped (so the client gets to read
the 413 response instead of a reset connection) and :class:`UploadTooLargeError` is raised.

Every malformed body is a 400 with a code and leaves nothing behind (partial files are
deleted, handles closed): a multipart body the parser rejects (wrong boundary, garbage:
``multipart_error``), one that ends inside a part (no closing boundary: ``multipart_incomplete``),
a part header over :data:`MAX_HEADER_BYTES` (``multipart_header_too_large``), more than
:data:`MAX_PARTS` parts (``too_many_parts``), a file field given twice (``repeated_field``) or more
file parts than the route takes (``too_many_files``), a file name over :data:`MAX_FILENAME_CHARS`
(``filename_too_long``). A body that sends nothing for ``idle_s`` seconds is dropped with 408
``upload_timeout``, so stalled clients cannot hold files and handles open.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import hashlib
import tomllib
from collections.abc import AsyncIterator, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO
from urllib.parse import parse_qsl

from python_multipart.exceptions import FormParserError
from python_multipart.multipart import MultipartParser, MultipartState, parse_options_header
from starlette.requests import ClientDisconnect, Request

from app.errors import AppError, InputError, StorageError, StorageFullError, UploadTimeoutError, UploadTooLargeError

MAX_FIELD_BYTES = 64 * 1024
MAX_HEADER_BYTES = 16 * 1024  # all header lines of one part together
MAX_PARTS = 16
MAX_FILENAME_CHARS = 255  # what a file system accepts for one name


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
        with _storage_errors():
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
        with _storage_errors():
            self.fh.write(data)

    def close(self) -> UploadedFile:
        if self.fh is not None:
            fh, self.fh = self.fh, None
            with _storage_errors():
                fh.close()
        return UploadedFile(self.path, self.filename, self.size, self.hash.hexdigest(), self.head, self.field_name)

    def discard(self) -> None:
        if self.fh is not None:
            fh, self.fh = self.fh, None
            with contextlib.suppress(OSError):  # a full disk fails the flush; the handle is closed anyway
                fh.close()
        self.path.unlink(missing_ok=True)


@contextlib.contextmanager
def _storage_errors() -> Iterator[None]:
    """Writing an upload fails: 507 on a full volume, 500 ``storage_error`` otherwise -- never the path."""
    try:
        yield
    except OSError as exc:
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            raise StorageFullError("the server's data volume is full; the upload was not stored") from exc
        raise StorageError(f"cannot store the upload: {exc.strerror or type(exc).__name__}") from exc


def _safe_name(name: str) -> str:
    if len(name) > MAX_FILENAME_CHARS:
        raise InputError(f"file name of {len(name)} characters is longer than {MAX_FILENAME_CHARS}",
                         code="filename_too_long")
    base = name.replace("\\", "/").rsplit("/", 1)[-1].strip() or "upload"
    return "".join(c for c in base if c.isprintable())[:200]


def _suffix(filename: str) -> str:
    """The extension kept on the temporary file (readers sniff content, but ``.gz`` matters): short and plain."""
    suffix = Path(filename).suffix.lower()
    return suffix if len(suffix) <= 12 and suffix[1:].isalnum() else ""


class _Multipart:
    def __init__(self, boundary: bytes, new_path: object, cap: int, result: UploadResult, max_files: int,
                 file_fields: tuple[str, ...] | None = None) -> None:
        self.new_path, self.cap, self.result, self.max_files = new_path, cap, result, max_files
        self.file_fields = file_fields
        self.sinks: list[_Sink] = []
        self.parts = 0
        self.open_part = False
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
        self.open_part = True

    def _header_room(self, more: int) -> None:
        used = sum(len(k) + len(v) for k, v in self._headers.items()) + len(self._hname) + len(self._hvalue)
        if used + more > MAX_HEADER_BYTES:
            raise InputError(f"a multipart part's headers are longer than {MAX_HEADER_BYTES} bytes",
                             code="multipart_header_too_large")

    def _hf(self, data: bytes, start: int, end: int) -> None:
        self._header_room(end - start)
        self._hname += data[start:end]

    def _hv(self, data: bytes, start: int, end: int) -> None:
        self._header_room(end - start)
        self._hvalue += data[start:end]

    def _hend(self) -> None:
        self._headers[self._hname.lower()] = self._hvalue
        self._hname, self._hvalue = b"", b""

    def _hdone(self) -> None:
        self.parts += 1
        if self.parts > MAX_PARTS:
            raise InputError(f"more than {MAX_PARTS} parts in a multipart upload", code="too_many_parts")
        _, opts = parse_options_header(self._headers.get(b"content-disposition", b""))
        name = opts.get(b"name", b"").decode("utf-8", "replace")[:MAX_FILENAME_CHARS]
        if b"filename" in opts:
            if any(sink.field_name == (name or "file") for sink in self.sinks):
                raise InputError(f"file field {name or 'file'!r} given more than once; send each file once",
                                 code="repeated_field")
            if self.file_fields is not None and (name or "file") not in self.file_fields:
                raise InputError(f"file field {name or 'file'!r} is not one this upload takes "
                                 f"({', '.join(self.file_fields)})", code="too_many_files")
            if len(self.sinks) >= self.max_files:
                raise InputError(f"more than {self.max_files} file(s) in the upload", code="too_many_files")
            filename = _safe_name(opts[b"filename"].decode("utf-8", "replace"))
            path = self.new_path(_suffix(filename))  # type: ignore[operator]
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
        self.open_part = False
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


def check_toml(path: Path, shown: str) -> None:
    """400 ``invalid_toml`` for a TOML file no loader should be handed: not UTF-8 (a binary file) or
    nested past Python's recursion limit. Syntax errors are left to the loaders, which name the line."""
    try:
        tomllib.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise InputError(f"{shown}: not a TOML text file (byte {exc.start} is not UTF-8)",
                         code="invalid_toml") from None
    except RecursionError:
        raise InputError(f"{shown}: tables or arrays nested too deeply", code="invalid_toml") from None
    except tomllib.TOMLDecodeError:
        return


async def _drain(request: Request, limit: int) -> None:
    seen = 0
    with contextlib.suppress(ClientDisconnect):
        async for chunk in request.stream():
            seen += len(chunk)
            if seen > limit:
                return


async def _chunks(request: Request, idle_s: float | None) -> AsyncIterator[bytes]:
    """The body's chunks; :class:`UploadTimeoutError` when none arrives for ``idle_s`` seconds."""
    stream = request.stream().__aiter__()
    while True:
        try:
            async with asyncio.timeout(idle_s):
                chunk = await anext(stream)
        except StopAsyncIteration:
            return
        except TimeoutError:
            raise UploadTimeoutError(f"the upload sent nothing for {idle_s:g} s (LASHSCOPE_UPLOAD_IDLE_S); "
                                     "it was dropped") from None
        yield chunk


async def receive_upload(request: Request, new_path: object, cap: int, drain_bytes: int,
                         raw_filename: str | None = None, urlencoded_form: bool = False,
                         idle_s: float | None = None, max_files: int = 1,
                         file_fields: tuple[str, ...] | None = None) -> UploadResult:
    """Stream the request body into files created by ``new_path(suffix)``; see the module docstring.

    A multipart body may carry at most ``max_files`` file parts, each under its own field name; a
    repeated one or one too many is refused when its headers arrive, before any of it is written;
    so is one under a field name not in ``file_fields`` (when given).

    With ``urlencoded_form``, an ``application/x-www-form-urlencoded`` body is read as form
    fields (no files); otherwise such a body is the raw file (curl ``--data-binary`` sends
    that content type by default).
    """
    ctype = request.headers.get("content-type", "")
    result = UploadResult()
    if urlencoded_form and ctype.startswith("application/x-www-form-urlencoded"):
        body = b""
        async for chunk in _chunks(request, idle_s):
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
            if len(boundary) > 200:
                raise InputError("multipart boundary longer than 200 bytes", code="multipart_error")
            mp = _Multipart(boundary, new_path, cap, result, max_files, file_fields)
            sinks = mp.sinks
            async for chunk in _chunks(request, idle_s):
                mp.parser.write(chunk)
            mp.parser.finalize()
            if mp.open_part or (mp.parts and mp.parser.state != MultipartState.END):
                raise InputError("the multipart body ended before its closing boundary (upload cut off?)",
                                 code="multipart_incomplete")
        else:
            name = _safe_name(raw_filename or "upload.log")
            sink = _Sink(new_path(_suffix(name)), name, "file", cap)  # type: ignore[operator]
            sinks = [sink]
            async for chunk in _chunks(request, idle_s):
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
    except FormParserError as exc:
        for s in sinks:
            s.discard()
        raise InputError(f"malformed multipart body: {exc}", code="multipart_error") from exc
    except BaseException:
        for s in sinks:
            s.discard()
        raise
    return result
