"""The service itself: health (can it take and run jobs?) and version. Open without an API key."""

from __future__ import annotations

from fastapi import APIRouter, Depends
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool

from owcsim.schemas.jobs import HealthPublic, VersionPublic
from owcsim.version import __version__ as owcsim_version  # the package's one version lookup

from ..deps import get_dispatcher, get_settings, get_store
from ..dispatcher import Dispatcher
from ..settings import Settings
from ..store import JobStore

router = APIRouter(tags=["service"])

#: Health is 503 when the dispatcher's last read of the store is older than this [s].
STALE_S = 15.0


@router.get(
    "/health",
    operation_id="health",
    response_model=HealthPublic,
    summary="Health: the store answers, the dispatcher runs",
    responses={503: {"model": HealthPublic, "description": "the service cannot run jobs now"}},
)
async def health(
    store: JobStore = Depends(get_store),
    dispatcher: Dispatcher = Depends(get_dispatcher),
    settings: Settings = Depends(get_settings),
):
    """Answered on the event loop from what the dispatcher last read (it reads the store every
    0.2 s): never queued behind pre-flights or downloads. A store error the dispatcher met (disk
    full) or a dispatcher that stopped reading for STALE_S makes it 503, with the `reason`."""
    reason = None
    if dispatcher.alive:
        counts, age, error = dispatcher.state()
        store_ok = error is None and age < STALE_S
        reason = error or (None if age < STALE_S else f"the dispatcher has not read the store for {age:.0f} s")
    else:  # no dispatcher (an app built with run_jobs=False): ask the store itself
        try:
            await run_in_threadpool(store.check)  # still the file it locked, still an SQLite file
            counts, store_ok = await run_in_threadpool(store.counts), True
        except Exception as exc:
            counts, store_ok, reason = {}, False, f"store error: {exc}"
        reason = reason or "the dispatcher is not running"
    ok = store_ok and dispatcher.alive
    body = HealthPublic(
        status="ok" if ok else "unavailable",
        store=store_ok,
        dispatcher=dispatcher.alive,
        queued=counts.get("queued", 0),
        running=counts.get("running", 0),
        max_concurrent_jobs=settings.max_concurrent_jobs,
        max_queued_jobs=settings.max_queued_jobs,
    )
    if ok:
        return body
    return JSONResponse({**body.model_dump(), "reason": reason}, status_code=503, headers={"Retry-After": "5"})


@router.get(
    "/version", operation_id="version", response_model=VersionPublic, summary="Version of owcsim and of the API"
)
def get_version() -> VersionPublic:
    return VersionPublic(owcsim_version=owcsim_version)
