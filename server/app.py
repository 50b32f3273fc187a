"""The FastAPI application: routes under /v1, problem answers, the job store and the dispatcher.

`create_app(settings)` builds it; the dispatcher thread runs between the app's startup
and shutdown (uvicorn's lifespan). The OpenAPI document is generated from schemas/.
"""

from __future__ import annotations

import logging
from contextlib import asynccontextmanager

import anyio
from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi
from starlette.concurrency import run_in_threadpool

from owcsim.schemas import SceneSpec
from owcsim.schemas.errors import PROBLEM_MEDIA_TYPE

from . import faults, problems
from .dispatcher import Dispatcher, start_forkserver
from .limits import RequestLimits
from .preflight import Preflighter
from .routes import docs, jobs, results, scenes, service, timeline
from .routes.job_scene import router as job_scene_router  # GET /v1/jobs/{id}/scene (issue 27: scene preview)
from .routes.service import owcsim_version
from .settings import Settings
from .store import JobStore
from .views import API_PREFIX
from .web import pages

log = logging.getLogger("owcsim.server")

DESCRIPTION = """Monte Carlo simulation of indoor optical wireless channels, as jobs.

POST a scene document (the JSON `owcsim run` takes) to `/v1/jobs`, follow the job at the URL
in `Location` until its status is `succeeded`, then GET its `result` (JSON), `result.csv`,
`result.npz` or `plot.png`. Errors are `application/problem+json` documents naming the wrong
field. With API keys on, send `Authorization: Bearer <key>`; a key sees only its own jobs."""


def create_app(settings: Settings | None = None, *, run_jobs: bool = True) -> FastAPI:
    """The service. `run_jobs=False` keeps the dispatcher off (jobs stay queued): for API tests."""
    settings = settings or Settings()
    owners = settings.key_owners()
    store = JobStore(settings.db, server=True)
    dispatcher = Dispatcher(store, settings)
    preflighter = Preflighter(
        concurrency=settings.preflight_concurrency,
        timeout_s=settings.preflight_timeout_s,
        memory_bytes=settings.preflight_memory_bytes,
        max_triangles=settings.max_triangles,
        workers=settings.workers_per_job,
    )

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        # Heavy request work (validation, waiting for a pre-flight, drawing a plot) has its own threads,
        # so that health and status requests never queue behind it in the default pool.
        app.state.heavy = anyio.CapacityLimiter(settings.preflight_concurrency + 2)
        # Submissions check their bodies a few at a time, once the body has arrived (a slow sender holds no
        # slot); the bodies held in memory meanwhile are bounded by app.state.bodies (body_memory_bytes).
        app.state.submissions = anyio.Semaphore(2 * settings.preflight_concurrency + 2)
        await run_in_threadpool(start_forkserver)  # pre-flights and workers start from it, engine imported
        if run_jobs:
            await run_in_threadpool(dispatcher.start)
        log.info(
            "owcsim service: job store %s, %d job(s) at once, API keys %s",
            settings.db,
            settings.max_concurrent_jobs,
            "on" if owners else "off",
        )
        try:
            yield
        finally:
            if run_jobs:
                await run_in_threadpool(dispatcher.stop)
            store.close()  # checkpoint: the store is one self-contained file again

    app = FastAPI(
        title="owcsim",
        version=owcsim_version,
        description=DESCRIPTION,
        lifespan=lifespan,
        docs_url=None,
        redoc_url=None,
        openapi_url=f"{API_PREFIX}/openapi.json",
    )  # docs: routes/docs.py
    app.state.settings, app.state.store, app.state.dispatcher, app.state.owners = settings, store, dispatcher, owners
    app.state.preflighter = preflighter
    app.state.heavy = app.state.submissions = None  # set at startup (they belong to the running event loop)
    app.state.bodies = jobs.BodyBudget(settings.body_memory_cap, settings.retry_after_s)
    problems.install(app)
    faults.install(app)  # a store overwritten or damaged while running: 503, not 500
    app.add_middleware(RequestLimits, body_timeout_s=settings.body_timeout_s)
    for module in (jobs, results, service, docs, timeline):
        app.include_router(module.router, prefix=API_PREFIX)
    app.include_router(scenes.router, prefix=API_PREFIX)  # examples, pre-flight, delete (the web pages use them)
    app.include_router(job_scene_router, prefix=API_PREFIX)  # the stored scene document (the scene preview)
    pages.install(app)  # the web pages: /, /ui, /ui/submit, /ui/jobs/{id}, /ui/static/* (server/web)
    app.openapi = lambda: _openapi(app)  # type: ignore[method-assign]  # FastAPI's documented way to customise it
    return app


def _openapi(app: FastAPI) -> dict:
    """FastAPI's document, plus the scene body schema; every 422 and error answer is a problem document."""
    if app.openapi_schema:
        return app.openapi_schema
    doc = get_openapi(title=app.title, version=app.version, description=app.description, routes=app.routes)
    comps = doc.setdefault("components", {}).setdefault("schemas", {})
    scene = SceneSpec.model_json_schema(ref_template="#/components/schemas/{model}", mode="validation")
    for name, schema in scene.pop("$defs", {}).items():
        comps.setdefault(name, schema)
    comps["SceneSpec"] = scene
    for path in doc["paths"].values():
        for op in path.values():
            for code, resp in op.get("responses", {}).items():
                content = resp.get("content", {})
                if code == "422" or PROBLEM_MEDIA_TYPE in content:
                    resp["content"] = {PROBLEM_MEDIA_TYPE: {"schema": {"$ref": "#/components/schemas/Problem"}}}
                    resp["description"] = resp.get("description") or "problem"
    for name in ("HTTPValidationError", "ValidationError"):
        comps.pop(name, None)
    if not app.state.owners:  # no API keys: no operation asks for one
        doc["components"].pop("securitySchemes", None)
        for path in doc["paths"].values():
            for op in path.values():
                op.pop("security", None)
    app.openapi_schema = doc
    return doc
