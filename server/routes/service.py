"""The service itself: health (can it take and run jobs?) and version. Open without an API key."""
from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from fastapi import APIRouter, Depends
from fastapi.responses import JSONResponse

from owcsim.schemas.jobs import HealthPublic, VersionPublic

from ..deps import get_dispatcher, get_settings, get_store
from ..dispatcher import Dispatcher
from ..settings import Settings
from ..store import JobStore

router = APIRouter(tags=["service"])


@router.get("/health", operation_id="health", response_model=HealthPublic, summary="Health: the store answers, the dispatcher runs",
            responses={503: {"model": HealthPublic, "description": "the service cannot run jobs now"}})
def health(store: JobStore = Depends(get_store), dispatcher: Dispatcher = Depends(get_dispatcher),
           settings: Settings = Depends(get_settings)):
    try:
        counts, store_ok = store.counts(), True
    except Exception:
        counts, store_ok = {}, False
    ok = store_ok and dispatcher.alive
    body = HealthPublic(status="ok" if ok else "unavailable", store=store_ok, dispatcher=dispatcher.alive,
                        queued=counts.get("queued", 0), running=counts.get("running", 0),
                        max_concurrent_jobs=settings.max_concurrent_jobs, max_queued_jobs=settings.max_queued_jobs)
    return body if ok else JSONResponse(body.model_dump(), status_code=503, headers={"Retry-After": "5"})


def owcsim_version() -> str:
    try:
        return version("owcsim")
    except PackageNotFoundError:
        return "0+unknown"


@router.get("/version", operation_id="version", response_model=VersionPublic, summary="Version of owcsim and of the API")
def get_version() -> VersionPublic:
    return VersionPublic(owcsim_version=owcsim_version())
