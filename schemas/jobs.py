"""Jobs of the HTTP service: a submitted scene document, its state, its progress, its result.

A job goes queued -> running -> succeeded | failed | cancelled (a queued job may be
cancelled directly). The scene document a job runs is the one `owcsim run` reads
(schemas.SceneSpec); its result is schemas.results.SimulationResultPublic.
"""

from __future__ import annotations

from datetime import datetime
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

JobStatus = Literal["queued", "running", "succeeded", "failed", "cancelled"]
#: States a job never leaves.
TERMINAL_STATUSES: frozenset[str] = frozenset({"succeeded", "failed", "cancelled"})


class JobProgress(BaseModel):
    """How far a running job is: the engine's report after its latest batch."""

    model_config = ConfigDict(extra="ignore")

    fraction: float = Field(0.0, ge=0.0, le=1.0, description="estimated fraction done, 0..1")
    paths: int = Field(0, ge=0, description="Monte Carlo paths traced so far (the busiest link)")
    batches: int = Field(0, ge=0, description="batches merged so far")
    dc_gain_rel_stderr: float | None = Field(None, description="current worst relative standard error of H0")
    elapsed_s: float = Field(0.0, ge=0.0, description="time since the run started [s]")


class JobUrls(BaseModel):
    """Where to find the job and its outputs (paths relative to the server's base URL)."""

    model_config = ConfigDict(extra="ignore")

    self: str
    result: str = Field(description="result document (JSON), once the job has succeeded")
    result_csv: str = Field(description="binned CIR of every link, long format (the columns of cir.csv)")
    result_npz: str = Field(description="numpy arrays: t_edges_s, cir, cir_stderr, by_reflection_order, ...")
    plot: str = Field(description="h(t) per reflection order (PNG)")
    cancel: str


class JobPublic(BaseModel):
    """A job as the API shows it."""

    model_config = ConfigDict(extra="ignore")

    id: str
    url: str = Field(description="the job's URL, relative to the server's base URL")
    status: JobStatus
    name: str | None = Field(None, description="the scene's `name`")
    progress: JobProgress = Field(default_factory=JobProgress)
    cancel_requested: bool = False
    error: str | None = Field(None, description="why the job failed (or why it was retried)")
    warnings: list[str] = Field(default_factory=list, description="engine warnings, e.g. dropped triangles")
    attempts: int = Field(0, ge=0, description="times a worker process started the job")
    created_at: datetime
    started_at: datetime | None = None
    finished_at: datetime | None = None
    urls: JobUrls


class JobListPublic(BaseModel):
    """One page of jobs, newest first. Pass `next_cursor` as `cursor` for the next page."""

    model_config = ConfigDict(extra="ignore")

    items: list[JobPublic]
    next_cursor: str | None = Field(None, description="cursor of the next page; null on the last page")
    next: str | None = Field(None, description="URL of the next page; null on the last page")


class HealthPublic(BaseModel):
    """Whether the service can take and run jobs."""

    model_config = ConfigDict(extra="ignore")

    status: Literal["ok", "unavailable"]
    store: bool = Field(description="the job store answers")
    dispatcher: bool = Field(description="the dispatcher that starts jobs is alive")
    queued: int
    running: int
    max_concurrent_jobs: int
    max_queued_jobs: int


class VersionPublic(BaseModel):
    model_config = ConfigDict(extra="ignore")

    owcsim_version: str
    api_version: str = "v1"
