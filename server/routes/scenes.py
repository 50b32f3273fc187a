"""What the web pages need beyond jobs and results: the example scenes this service knows (GET /v1/examples),
the pre-flight of a scene without queueing it (POST /v1/preflight: the same checks and limits as a
submission, its memory and time estimate and what the job will model), and deleting a finished job
(DELETE /v1/jobs/{job_id}).
"""

from __future__ import annotations

import contextlib
import copy
import statistics
from typing import Any

import anyio
from fastapi import APIRouter, Depends, Request, Response
from pydantic import BaseModel, Field

from ..auth import current_owner
from ..deps import get_settings, get_store, owned_job
from ..problems import ProblemError
from ..settings import Settings
from ..store import JobRow, JobStore
from ..submission import estimate, read_body
from .docs import EXAMPLE_SCENE, SCENE_BODY, problems
from .jobs import BodyBudget

router = APIRouter(tags=["scenes"])

#: A work-plane map: Barry's room and source, a 5 x 5 grid of upward receivers at 0.85 m, K = 1, few paths.
MAP_SCENE: dict[str, Any] = {
    "name": "Work-plane map, 5 x 5 points (Barry et al. 1993 room)",
    "room": EXAMPLE_SCENE["room"],
    "transmitters": EXAMPLE_SCENE["transmitters"],
    "receiver_grids": [
        {
            "id_prefix": "plane",
            "origin": [0.5, 0.5, 0.85],
            "size": [4.0, 4.0],
            "spacing": 1.0,
            "normal": [0, 0, 1],
            "area": 1e-4,
            "fov_deg": 85,
        }
    ],
    "simulation": {"max_reflections": 1, "time_bin_s": 5e-10, "t_max_s": 5e-8, "paths": 2000, "seed": 1},
}

#: The examples (id -> document): small enough to run in seconds on any server.
EXAMPLES: dict[str, dict[str, Any]] = {"barry-config-a": EXAMPLE_SCENE, "work-plane-map": MAP_SCENE}


class ExamplePublic(BaseModel):
    id: str = Field(description="the example's id")
    name: str = Field(description="what it is")
    document: dict = Field(description="the scene document, ready to submit to POST /v1/jobs")


class ExampleListPublic(BaseModel):
    items: list[ExamplePublic]


class PreflightPublic(BaseModel):
    """What a submission of the scene would run: its estimates, and what it will model (docs/modeled.md)."""

    ok: bool = Field(True, description="the scene passed every check a submission makes")
    memory_bytes: int = Field(description="the job's memory estimate [B] (the one the server's limits use)")
    triangles: int = Field(description="triangles of the built scene")
    receivers: int = Field(description="receivers, grids expanded")
    paths: int | None = Field(description="paths the job traces in all (fixed-budget jobs; null: until accuracy)")
    time_s: float | None = Field(description="rough wall time [s] (null: this server has no measure yet)")
    time_basis: str = Field(description="how `time_s` was estimated")
    modeled: dict[str, str] = Field(description="what the job will model and which settings it will choose")


@router.get(
    "/examples",
    operation_id="list_examples",
    response_model=ExampleListPublic,
    summary="The example scenes this service knows",
)
def list_examples() -> ExampleListPublic:
    """Small documents to start from (the web page's "start from an example"); open without an API key."""
    return ExampleListPublic(
        items=[ExamplePublic(id=k, name=d["name"], document=copy.deepcopy(d)) for k, d in EXAMPLES.items()]
    )


@router.post(
    "/preflight",
    operation_id="preflight",
    response_model=PreflightPublic,
    summary="Check a scene document and estimate its job, without queueing it",
    responses=problems(400, 401, 408, 413, 415, 422, 503),
    openapi_extra={"requestBody": SCENE_BODY},
)
async def preflight(
    request: Request,
    owner: str | None = Depends(current_owner),
    store: JobStore = Depends(get_store),
    settings: Settings = Depends(get_settings),
) -> PreflightPublic:
    """The checks of POST /v1/jobs (schema, the server's limits, the engine's pre-flight, the memory cap), with
    the same refusals (422 problem documents naming the field); nothing is stored."""
    # as a submission: the body first, without a slot, counted against body_memory_bytes; then a slot; a body
    # over inprocess_body_bytes is parsed and checked in a pre-flight process (submission.estimate)
    budget: BodyBudget = request.app.state.bodies
    held = [0]
    try:
        body = await read_body(Request(request.scope, budget.counted(request.receive, held)), settings.max_body_bytes)
        async with request.app.state.submissions or contextlib.nullcontext():
            return await anyio.to_thread.run_sync(
                _preflight, body, owner, store, settings, request.app.state.preflighter, limiter=request.app.state.heavy
            )
    finally:
        budget.release(held)


def _preflight(body: bytes, owner: str | None, store: JobStore, settings: Settings, preflighter) -> PreflightPublic:
    out = estimate(body, settings, preflighter)
    time_s, basis = _time_estimate(out["paths"], out.pop("time_budget_s"), store, owner)
    return PreflightPublic(**out, time_s=time_s, time_basis=basis)


#: Finished jobs whose rate (paths per second) estimates a new job's time.
RATE_JOBS = 20


def _time_estimate(paths: int | None, budget_s: float, store: JobStore, owner: str | None) -> tuple[float | None, str]:
    """(seconds or None, how): a job until accuracy stops at its time budget; a fixed-budget one takes its paths
    at the median rate of the caller's last finished jobs on this server (rough: the rate depends on K, the
    medium and the receivers)."""
    if paths is None:
        return budget_s, f"at most the time budget (simulation.time_budget_s = {budget_s:g} s)"
    rows, _ = store.list(owner, ["succeeded"], RATE_JOBS, None)
    rates = [r.paths / r.elapsed_s for r in rows if r.paths > 0 and r.elapsed_s > 0]
    if not rates:
        return None, "unknown until a job has finished on this server (no measured rate yet)"
    rate = statistics.median(rates)
    return paths / rate, (
        f"rough: {paths:,d} paths at {rate:,.0f} paths/s, the median rate of your last {len(rates)} finished "
        "job(s) on this server (the rate depends on the reflection order, the medium and the receivers)"
    )


#: States a job can be deleted in (a queued or running one is cancelled first).
DELETABLE = ("succeeded", "failed", "cancelled")


@router.delete(
    "/jobs/{job_id}",
    operation_id="delete_job",
    status_code=204,
    tags=["jobs"],
    summary="Delete a finished job and its result",
    responses=problems(401, 404, 409),
)
def delete_job(
    job: JobRow = Depends(owned_job),
    owner: str | None = Depends(current_owner),
    store: JobStore = Depends(get_store),
) -> Response:
    """A succeeded, failed or cancelled job is deleted with its document and result (204); a queued or running
    one is 409 (cancel it first)."""
    if job.status not in DELETABLE or not store.delete(job.id, owner, DELETABLE):
        now = store.get(job.id, owner)
        if now is None:
            raise ProblemError(404, "job-not-found", f"no job {job.id!r}")
        raise ProblemError(
            409, "job-not-finished", f"job {job.id} is {now.status}: cancel it first", job_status=now.status
        )
    return Response(status_code=204)
