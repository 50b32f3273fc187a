"""Request dependencies: the app's store, settings and dispatcher, and the caller's job."""

from __future__ import annotations

from fastapi import Depends, Path, Request

from .auth import current_owner
from .dispatcher import Dispatcher
from .problems import ProblemError
from .settings import Settings
from .store import JobRow, JobStore


def get_store(request: Request) -> JobStore:
    return request.app.state.store


def get_settings(request: Request) -> Settings:
    return request.app.state.settings


def get_dispatcher(request: Request) -> Dispatcher:
    return request.app.state.dispatcher


def owned_job(
    job_id: str = Path(description="the job's id"),
    owner: str | None = Depends(current_owner),
    store: JobStore = Depends(get_store),
) -> JobRow:
    """The job, if it exists and the caller may see it (another key's job is 'not found')."""
    job = store.get(job_id, owner)
    if job is None:
        raise ProblemError(404, "job-not-found", f"no job {job_id!r}" + (" for this API key" if owner else ""))
    return job
