"""Time left on long work: one straight-line estimate for the command line and the REST job status."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest

from app.api.schemas import JobOut, JobStateOut, job_timing
from app.progress import ETA_MIN_ELAPSED_S, ETA_MIN_FRACTION, eta_seconds, eta_text
from app.storage.records import JobRecord, JobStatus

NOW = datetime(2026, 11, 27, 12, 0, 0, tzinfo=UTC)


def _job(status: JobStatus, progress: float, started_s_ago: float | None) -> JobRecord:
    started = None if started_s_ago is None else (NOW - timedelta(seconds=started_s_ago)).isoformat(
        timespec="milliseconds")
    return JobRecord(id="j1", kind="diagnosis", subject="a/diagnoses/d", status=status, progress=progress,
                     stage="fitting drag", attempts=1, created_at=NOW.isoformat(), updated_at=NOW.isoformat(),
                     started_at=started)


@pytest.mark.parametrize(("fraction", "elapsed", "left"), [
    (0.25, 10.0, 30.0),  # a quarter done in 10 s: three quarters more at that pace
    (0.5, 40.0, 40.0),
    (0.9, 90.0, 10.0),
])
def test_time_left_is_the_pace_so_far(fraction: float, elapsed: float, left: float) -> None:
    assert eta_seconds(fraction, elapsed) == pytest.approx(left)


@pytest.mark.parametrize(("fraction", "elapsed"), [
    (ETA_MIN_FRACTION / 2, 60.0),  # too little done to extrapolate
    (0.5, ETA_MIN_ELAPSED_S / 2),  # too early
    (1.0, 30.0),  # done: nothing left to estimate
    (float("nan"), 30.0),
    (0.5, float("nan")),
])
def test_no_figure_while_it_would_mean_nothing(fraction: float, elapsed: float) -> None:
    assert eta_seconds(fraction, elapsed) is None
    assert eta_text(fraction, elapsed) == ""


def test_the_text_switches_to_minutes() -> None:
    assert eta_text(0.5, 40.0) == ", about 40 s left"
    assert eta_text(0.1, 60.0) == ", about 9 min left"  # 540 s


def test_a_running_job_reports_elapsed_and_time_left() -> None:
    timing = job_timing(_job(JobStatus.RUNNING, 0.4, 20.0), now=NOW)
    assert timing == {"elapsed_s": 20.0, "eta_s": 30.0}


@pytest.mark.parametrize(("status", "progress", "started"), [
    (JobStatus.QUEUED, 0.0, None),
    (JobStatus.DONE, 1.0, 50.0),
    (JobStatus.FAILED, 0.3, 50.0),
    (JobStatus.RUNNING, 0.3, None),  # no start time on the row: nothing to measure from
])
def test_other_jobs_report_no_timing(status: JobStatus, progress: float, started: float | None) -> None:
    assert job_timing(_job(status, progress, started), now=NOW) == {"elapsed_s": None, "eta_s": None}


def test_early_in_a_run_there_is_elapsed_time_but_no_estimate() -> None:
    assert job_timing(_job(JobStatus.RUNNING, 0.01, 20.0), now=NOW) == {"elapsed_s": 20.0, "eta_s": None}


def test_the_rest_models_carry_it() -> None:
    """The job status of every long job kind (``JobOut``: analyses, identifications, batches) has the fields;
    the job state of a result computed on request (``JobStateOut``) too."""
    out = JobOut.of(_job(JobStatus.RUNNING, 0.5, 1.0e6)).model_dump()
    assert out["elapsed_s"] == pytest.approx((datetime.now(UTC) - NOW).total_seconds() + 1.0e6, abs=5.0)
    assert out["eta_s"] == pytest.approx(out["elapsed_s"], rel=1e-3)
    assert JobOut.of(_job(JobStatus.QUEUED, 0.0, None)).model_dump()["eta_s"] is None
    assert {"elapsed_s", "eta_s"} <= set(JobStateOut.model_fields)
