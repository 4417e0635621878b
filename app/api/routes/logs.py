"""Logs: streamed upload with a size cap and content-hash de-duplication, list, status, delete."""

from __future__ import annotations

import os
from typing import Annotated

from fastapi import APIRouter, Query, Request, Response, status
from fastapi.concurrency import run_in_threadpool
from pydantic import BaseModel

from app.api.deps import SettingsDep, StoreDep
from app.api.routes.analyses import deleted
from app.api.schemas import ERRORS, LogOut
from app.api.timezones import TZ_DOC, time_zone, zoned_start
from app.api.upload import UploadedFile, receive_upload, user_file_names
from app.bounded import run_bounded
from app.errors import FormatFileError, InputError
from app.ingest.inspect import inspect_log
from app.ingest.readers.described import MAX_DESCRIPTION_BYTES, parse_layout
from app.log_formats import LOG_FORMATS, formats_sentence, sidecar_of

router = APIRouter(prefix="/logs", tags=["logs"], responses=ERRORS)

UPLOAD_DOC = {
    "requestBody": {
        "content": {
            "multipart/form-data": {"schema": {"type": "object", "properties": {
                "file": {"type": "string", "format": "binary"},
                "format_file": {"type": "string", "format": "binary", "description":
                                "TOML description of a text log format (docs/ingest-readers.md); the log is read "
                                "with it now and whenever it is analysed"},
                "tz": {"type": "string", "description": "as the tz query parameter"}}, "required": ["file"]}},
            "application/octet-stream": {"schema": {"type": "string", "format": "binary"}},
        },
        "required": True,
    }
}


@router.post("", status_code=status.HTTP_201_CREATED, response_model=LogOut, openapi_extra=UPLOAD_DOC,
             summary=f"Upload a CAN log ({formats_sentence()})")
async def upload_log(request: Request, response: Response, store: StoreDep, settings: SettingsDep,
                     filename: Annotated[str | None, Query(description="name for a raw-body upload")] = None,
                     tz: Annotated[str | None, Query(max_length=64, description=TZ_DOC)] = None) -> LogOut:
    """The body is streamed to disk and hashed; the log is read once to validate it.

    Same content as an existing log: 200 with that log and ``duplicate: true`` (its start time as
    first stored: ``tz`` is not applied again).
    """
    up = await receive_upload(request, store.temp_path, settings.max_upload_bytes,
                              int(settings.upload_drain_mb * 2**20), filename, idle_s=settings.upload_idle_s,
                              max_files=2, file_fields=("file", "format_file"))
    described = [f for f in up.files if f.field_name == "format_file"]
    up.files = [f for f in up.files if f.field_name != "format_file"]
    try:
        layout_text = await run_in_threadpool(_format_file, described)
    except BaseException:
        for f in up.files:
            f.path.unlink(missing_ok=True)
        raise
    tz = tz or up.fields.get("tz") or None
    try:
        zone = time_zone(tz) if tz else None
    except InputError:
        for f in up.files:
            f.path.unlink(missing_ok=True)
        raise
    multipart = request.headers.get("content-type", "").startswith("multipart/form-data")
    if len(up.files) != 1:
        for f in up.files:
            f.path.unlink(missing_ok=True)
        if not up.files:
            raise InputError("missing multipart field 'file' (send the log as -F file=@drive.blf)",
                             code="missing_file")
        raise InputError(f"expected one file in the upload, got {len(up.files)}")
    f = up.files[0]
    if f.size == 0 and not multipart and filename is None:  # a bare POST: no file at all
        f.path.unlink(missing_ok=True)
        raise InputError("missing multipart field 'file' (send the log as -F file=@drive.blf, or the raw bytes "
                         "as the body with ?filename=drive.blf)", code="missing_file")
    existing = store.find_log_by_hash(f.sha256)
    if existing is not None:
        f.path.unlink(missing_ok=True)
        response.status_code = status.HTTP_200_OK
        return LogOut.of(existing, duplicate=True)
    side = sidecar_of(f.path)
    try:
        if f.size == 0:
            raise InputError(f"upload {f.filename!r} is empty")
        if layout_text is not None:
            side.write_text(layout_text, encoding="utf-8")  # read by open_log beside the log
        with user_file_names({f.path: f.filename}):
            if layout_text is None:
                info = await run_in_threadpool(inspect_log, f.path, cpu_s=settings.validate_cpu_s)
            else:  # the client's regular expression may backtrack for hours on one line: read in a child process
                info = await run_in_threadpool(
                    run_bounded, "app.ingest.inspect:inspect_log", f.path, root=store.root,
                    what=f"reading {f.filename}",
                    setting="LASHSCOPE_VALIDATE_CPU_S", cpu_s=settings.validate_cpu_s,
                    memory_mb=settings.bounded_memory_mb, code="validation_limit",
                    kwargs={"cpu_s": settings.validate_cpu_s})
    except BaseException:
        f.path.unlink(missing_ok=True)
        side.unlink(missing_ok=True)
        raise
    rec, created = await run_in_threadpool(
        store.add_log, f.path, sha256=f.sha256, filename=f.filename, fmt=info["format"], frames=info["frames"],
        duration_s=info["duration_s"], start_time=zoned_start(info["start_time"], zone), issues=info["issues"],
        meta={"start_clock": info["start_clock"], "channels": info["channels"], "tz": tz})
    if layout_text is not None:
        if created:
            os.replace(side, sidecar_of(rec.path))
        side.unlink(missing_ok=True)
    if not created:
        response.status_code = status.HTTP_200_OK
    return LogOut.of(rec, duplicate=not created)


def _format_file(parts: list[UploadedFile]) -> str | None:
    """The text of an uploaded format description, validated (FormatFileError names the field); the parts
    are removed."""
    try:
        if not parts:
            return None
        part = parts[0]
        if part.size > MAX_DESCRIPTION_BYTES:
            raise FormatFileError(f"{part.filename}: a format description is at most 64 kB")
        try:
            text = part.path.read_bytes().decode("utf-8")
        except UnicodeDecodeError:
            raise FormatFileError(f"{part.filename}: not UTF-8 text") from None
        parse_layout(text, part.filename)
        return text
    finally:
        for p in parts:
            p.path.unlink(missing_ok=True)


@router.get("", response_model=list[LogOut], summary="List logs, newest first")
def list_logs(store: StoreDep, limit: Annotated[int, Query(ge=1, le=1000)] = 100,
              offset: Annotated[int, Query(ge=0, le=2**62)] = 0) -> list[LogOut]:
    return [LogOut.of(r) for r in store.list_logs(limit, offset)]


class LogFormatOut(BaseModel):
    name: str  # a stored log's "format"
    label: str  # what a user calls it


@router.get("/formats", response_model=list[LogFormatOut],
            summary="The log formats the service reads (name, label), from app/log_formats.py")
def log_formats() -> list[LogFormatOut]:
    return [LogFormatOut(name=f.name, label=f.label) for f in LOG_FORMATS]


@router.get("/{log_id}", response_model=LogOut, summary="One log: format, frames, duration, read problems")
def get_log(log_id: str, store: StoreDep) -> LogOut:
    return LogOut.of(store.get_log(log_id))


@router.delete("/{log_id}", status_code=status.HTTP_204_NO_CONTENT, summary="Delete a log and its analyses")
def delete_log(log_id: str, store: StoreDep) -> Response:
    deleted(store.delete_log(log_id))
    return Response(status_code=status.HTTP_204_NO_CONTENT)
