"""The application's exception tree.

Every error a user can meet derives from :class:`AppError`; it carries a stable
machine-readable ``code`` and the HTTP ``status`` the API maps it to. Leaves also
subclass the matching builtin so generic callers can catch ``ValueError`` etc.::

    AppError
     +-- IngestError                      (422)
     |    +-- UnsupportedFormatError      (415)  no reader recognises the content
     |    +-- LogNotFoundError (FileNotFoundError) (404)  no log file at the given path
     |    +-- LogFormatError (ValueError) (422)  corrupt or unreadable log content
     |    |    +-- TruncatedLogError             the log ends inside a record
     |    +-- InflatedTooLargeError       (413)  a compressed log inflates past the cap
     |    +-- DatabaseError (ValueError)  (422)  DBC/KCD/SYM/ARXML cannot be loaded
     |    +-- DecodeError (ValueError)    (422)  frames cannot be decoded
     |    +-- SignalMapError (ValueError) (422)  signal map invalid or does not fit the DBC
     |    +-- MissingSignalError (KeyError)(422) required canonical channels absent
     |    +-- FormatFileError (ValueError)(422)  a log format description (TOML) is wrong
     +-- AnalysisError                    (422)
     |    +-- InsufficientDataError       (422)
     |    +-- ImplausibleSignalError      (422)  most of a channel beyond what the vehicle can do (wrong DBC)
     |    +-- WorkLimitError              (422)  a request would cost more than its limit (decided before the work)
     +-- InputError (ValueError)          (400)  absurd parameters, bad request values
     +-- UploadTooLargeError              (413)
     +-- UploadTimeoutError (TimeoutError)(408)  an upload stalled longer than the idle limit
     +-- QueueFullError                   (429)  too many jobs waiting
     +-- ForbiddenError (PermissionError) (403)  the operator has not allowed this (e.g. a live bus)
     +-- NotFoundError (LookupError)      (404)
     +-- ConflictError                    (409)
     +-- StorageError (OSError)           (500)
     |    +-- StorageFullError            (507)  the data volume is full (ENOSPC, EDQUOT)
     +-- LiveBusError (ConnectionError)   (503)

Simulator errors (``sim.errors.SimError``) are mapped by the API as well.
"""

from __future__ import annotations


class AppError(Exception):
    """Base of every lashscope error a user can meet."""

    code: str = "app_error"
    status: int = 500

    def __init__(self, detail: str, *, code: str | None = None) -> None:
        super().__init__(detail)
        self.detail = detail
        if code is not None:
            self.code = code

    def __str__(self) -> str:
        return self.detail


class IngestError(AppError):
    code = "ingest_error"
    status = 422


class UnsupportedFormatError(IngestError):
    code = "unsupported_format"
    status = 415


class LogNotFoundError(IngestError, FileNotFoundError):
    code = "file_not_found"
    status = 404


class LogFormatError(IngestError, ValueError):
    code = "log_format"


class TruncatedLogError(LogFormatError):
    code = "log_truncated"


class InflatedTooLargeError(IngestError):
    """A gzip-compressed log that must be inflated to disk (MF4) decompresses past the configured cap."""

    code = "inflated_too_large"
    status = 413


class DatabaseError(IngestError, ValueError):
    code = "database_error"


class DecodeError(IngestError, ValueError):
    code = "decode_error"


class SignalMapError(IngestError, ValueError):
    code = "signal_map_error"


class MissingSignalError(IngestError, KeyError):
    code = "missing_signal"

    def __str__(self) -> str:  # KeyError would quote the message
        return self.detail


class AnalysisError(AppError):
    code = "analysis_error"
    status = 422


class InsufficientDataError(AnalysisError):
    code = "insufficient_data"


class NotIdentifiableError(AnalysisError):
    """The log cannot pin down what was asked of it (a parameter, or anything of the vehicle)."""

    code = "not_identifiable"


class ImplausibleSignalError(AnalysisError):
    """Most of a decoded channel is beyond what the vehicle can do: the log was decoded with the wrong DBC
    version or scaling (:mod:`app.analysis.logchecks`)."""

    code = "implausible_signal"


class WorkLimitError(AnalysisError):
    """The work a request asks for, estimated before it starts, is past its limit (the message names it)."""

    code = "work_limit"


class InputError(AppError, ValueError):
    code = "invalid_input"
    status = 400


class UploadTooLargeError(AppError):
    code = "upload_too_large"
    status = 413


class UploadTimeoutError(AppError, TimeoutError):
    code = "upload_timeout"
    status = 408


class QueueFullError(AppError):
    code = "queue_full"
    status = 429


class ForbiddenError(AppError, PermissionError):
    code = "forbidden"
    status = 403


class NotFoundError(AppError, LookupError):
    code = "not_found"
    status = 404


class ConflictError(AppError):
    code = "conflict"
    status = 409


class StorageError(AppError, OSError):
    code = "storage_error"
    status = 500


class StorageFullError(StorageError):
    code = "storage_full"
    status = 507


class LiveBusError(AppError, ConnectionError):
    code = "live_bus_error"
    status = 503


class FormatFileError(IngestError, ValueError):
    """A log format description (TOML, ``--format-file``) is wrong; the message names the file and field."""

    code = "format_file"
