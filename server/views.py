"""How a stored job looks on the wire (schemas.jobs.JobPublic), and its URLs."""

from __future__ import annotations

from datetime import UTC, datetime

from owcsim.schemas.jobs import JobProgress, JobPublic, JobUrls

from .store import JobRow

API_PREFIX = "/v1"


def job_url(job_id: str) -> str:
    return f"{API_PREFIX}/jobs/{job_id}"


def _time(t: float | None) -> datetime | None:
    return datetime.fromtimestamp(t, UTC) if t is not None else None


def job_public(row: JobRow) -> JobPublic:
    url = job_url(row.id)
    return JobPublic(
        id=row.id,
        url=url,
        status=row.status,
        name=row.name,
        progress=JobProgress(
            fraction=row.fraction,
            paths=row.paths,
            batches=row.batches,
            dc_gain_rel_stderr=row.rel_stderr,
            elapsed_s=row.elapsed_s,
        ),
        cancel_requested=row.cancel_requested,
        error=row.error,
        warnings=row.warnings,
        attempts=row.attempts,
        created_at=_time(row.created_at),
        started_at=_time(row.started_at),
        finished_at=_time(row.finished_at),
        urls=JobUrls(
            self=url,
            result=f"{url}/result",
            result_csv=f"{url}/result.csv",
            result_npz=f"{url}/result.npz",
            plot=f"{url}/plot.png",
            cancel=f"{url}/cancel",
        ),
    )
