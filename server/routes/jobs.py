"""Jobs: submit (POST /v1/jobs), list, get one, cancel."""

from __future__ import annotations

import contextlib
from typing import Annotated

import anyio
from fastapi import APIRouter, Depends, Header, Query, Request, Response

from owcsim.schemas.errors import ProblemField
from owcsim.schemas.jobs import JobListPublic, JobPublic, JobStatus

from ..auth import NO_AUTH_OWNER, current_owner
from ..deps import get_dispatcher, get_settings, get_store, owned_job
from ..dispatcher import Dispatcher
from ..problems import ProblemError
from ..settings import Settings
from ..store import IdempotencyConflict, JobRow, JobStore, QueueFull
from ..submission import admit, check_runnable, read_body
from ..views import API_PREFIX, job_public, job_url
from .docs import JOB_LINKS, SCENE_BODY, problems

router = APIRouter(prefix="/jobs", tags=["jobs"])

IdempotencyKey = Annotated[
    str | None,
    Header(
        alias="Idempotency-Key",
        min_length=1,
        max_length=255,
        pattern=r"^[\x21-\x7e]+$",
        description="any unique string (e.g. a UUID): a retried submission with the same key (and the same "
        "document) returns the first job instead of queueing a duplicate",
    ),
]


class BodyBudget:
    """Bytes of request bodies held in memory, all submissions together (counted on the event loop).

    A body is counted as it arrives and until its submission is answered; one whose next bytes would pass
    `cap` is refused with 503 and Retry-After (the others go on: no request waits for another's body)."""

    def __init__(self, cap: int, retry_after_s: int = 5):
        self.cap, self.used, self.retry_after_s = cap, 0, retry_after_s

    def counted(self, receive, held: list[int]):
        """`receive`, counting the body bytes of each message into `held[0]` and `used`."""

        async def counted_receive():
            message = await receive()
            size = len(message.get("body", b"")) if message["type"] == "http.request" else 0
            if size and self.used + size > self.cap:
                raise ProblemError(
                    503,
                    "server-busy",
                    f"the server holds {self.cap:,d} bytes of request bodies already (setting body_memory_bytes): "
                    "try again in a few seconds",
                    headers={"Retry-After": str(self.retry_after_s)},
                )
            self.used += size
            held[0] += size
            return message

        return counted_receive

    def release(self, held: list[int]) -> None:
        self.used -= held[0]
        held[0] = 0


@router.post(
    "",
    status_code=202,
    operation_id="submit_job",
    response_model=JobPublic,
    summary="Submit a scene document as a job",
    responses={
        **problems(400, 401, 408, 413, 415, 422, 429, 503, 507),
        202: {
            "description": "queued (or, with a known Idempotency-Key, the first job)",
            "headers": {"Location": {"description": "the job's URL", "schema": {"type": "string"}}},
            "links": JOB_LINKS,
        },
    },
    openapi_extra={"requestBody": SCENE_BODY},
)
async def submit_job(
    request: Request,
    response: Response,
    idempotency_key: IdempotencyKey = None,
    owner: str | None = Depends(current_owner),
    store: JobStore = Depends(get_store),
    settings: Settings = Depends(get_settings),
    dispatcher: Dispatcher = Depends(get_dispatcher),
) -> JobPublic:
    """Validate the scene (the document `owcsim run` takes), check the server's limits, pre-flight it in
    the engine, and queue it. Answers 202 with the job and its URL in `Location`."""
    # the body first, without a slot (a slow sender holds none: issue 25, item 4), its bytes counted against
    # body_memory_bytes; then a slot to check it: a few at a time (no limit if the app runs without its lifespan)
    budget: BodyBudget = request.app.state.bodies
    held = [0]
    try:
        body = await read_body(Request(request.scope, budget.counted(request.receive, held)), settings.max_body_bytes)
        async with request.app.state.submissions or contextlib.nullcontext():
            job, created = await anyio.to_thread.run_sync(
                _submit,
                body,
                owner,
                idempotency_key,
                store,
                settings,
                request.app.state.preflighter,
                limiter=request.app.state.heavy,
            )
    finally:
        budget.release(held)
    if created:
        dispatcher.wake()
    else:
        response.headers["Idempotent-Replayed"] = "true"
    response.headers["Location"] = job_url(job.id)
    return job_public(job)


def _submit(body: bytes, owner, key, store: JobStore, settings: Settings, preflighter) -> tuple[JobRow, bool]:
    owner = owner if owner is not None else NO_AUTH_OWNER
    doc = admit(body, settings, preflighter)  # a large body: validated and pre-flighted in its own process
    canonical, digest = doc.canonical, doc.digest
    try:
        if key is not None and (first := store.find_idempotent(owner, key, digest)) is not None:
            return first, False  # a retry (e.g. after a client timeout): no second pre-flight
        checked = doc.checked or check_runnable(doc.small_spec(), canonical, settings, preflighter)  # small: here
        return store.submit(
            owner=owner,
            scene_json=canonical,
            name=doc.name,
            request_hash=digest,
            idempotency_key=key,
            max_queued=settings.max_queued_jobs,
            max_queued_per_owner=settings.max_queued_per_key,
            memory_bytes=checked.memory_bytes,
        )
    except QueueFull as exc:
        what = (
            f"this API key's queue is full ({settings.max_queued_per_key} jobs, setting max_queued_per_key)"
            if exc.per_owner
            else f"the queue is full ({settings.max_queued_jobs} jobs)"
        )
        raise ProblemError(
            429, "queue-full", f"{what}: try again later", headers={"Retry-After": str(settings.retry_after_s)}
        ) from None
    except IdempotencyConflict as exc:
        raise ProblemError(
            422,
            "idempotency-key-reused",
            f"this Idempotency-Key was used for job {exc.job_id} with a different document",
            job_id=exc.job_id,
        ) from None


@router.get(
    "",
    operation_id="list_jobs",
    response_model=JobListPublic,
    summary="List jobs, newest first",
    responses=problems(401, 422),
)
def list_jobs(
    status: Annotated[list[JobStatus] | None, Query(description="only jobs in these states")] = None,
    limit: Annotated[int, Query(ge=1, le=500, description="jobs per page")] = 50,
    cursor: Annotated[
        str | None, Query(pattern=r"^[0-9a-f]{32}$", description="`next_cursor` of the previous page (opaque)")
    ] = None,
    owner: str | None = Depends(current_owner),
    store: JobStore = Depends(get_store),
) -> JobListPublic:
    """Jobs of the caller (of every caller when the server has no API keys)."""
    try:
        rows, after = store.list(owner, status, limit, cursor)
    except KeyError:
        unknown = ProblemField(loc="query.cursor", msg="unknown cursor", type="value_error")
        raise ProblemError(
            422, "invalid-parameter", "query.cursor: not a cursor of this API key's listing", errors=[unknown]
        ) from None
    nxt = None
    if after is not None:
        query = "".join(f"&status={s}" for s in status or ())
        nxt = f"{API_PREFIX}/jobs?limit={limit}&cursor={after}{query}"
    return JobListPublic(items=[job_public(r) for r in rows], next_cursor=after, next=nxt)


@router.get(
    "/{job_id}",
    operation_id="get_job",
    response_model=JobPublic,
    summary="Get a job: state, progress, timestamps",
    responses=problems(401, 404),
)
def get_job(job: JobRow = Depends(owned_job)) -> JobPublic:
    return job_public(job)


@router.post(
    "/{job_id}/cancel",
    operation_id="cancel_job",
    response_model=JobPublic,
    summary="Cancel a job",
    responses={
        **problems(401, 404, 409, 503, 507),
        202: {
            "description": "running: asked to stop (its status becomes `cancelled` within seconds)",
            "model": JobPublic,
        },
    },
)
def cancel_job(
    response: Response,
    job: JobRow = Depends(owned_job),
    owner: str | None = Depends(current_owner),
    store: JobStore = Depends(get_store),
    dispatcher: Dispatcher = Depends(get_dispatcher),
) -> JobPublic:
    """A queued job is cancelled at once (200). A running one is asked to stop (202): it stops within
    seconds and keeps its partial result. Cancelling a cancelled job is a no-op; a finished one is 409."""
    if job.status in ("succeeded", "failed"):
        raise ProblemError(409, "job-finished", f"job {job.id} has already {job.status}", job_status=job.status)
    row = store.request_cancel(job.id, owner)
    if row is None:  # deleted meanwhile
        raise ProblemError(404, "job-not-found", f"no job {job.id!r}")
    dispatcher.wake()
    if row.status == "running":
        response.status_code = 202
    elif row.status != "cancelled":  # it finished meanwhile
        raise ProblemError(409, "job-finished", f"job {job.id} has already {row.status}", job_status=row.status)
    return job_public(row)
