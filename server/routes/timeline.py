"""A timeline job's files (issue 26): the timeline as CSV and netCDF, and its plot (SVG).

Rendered once by the job's worker (server.formats.render_all) when the result has a `timeline`;
`GET /jobs/{id}/timeline` lists them. A job without a timeline answers 404.
"""

from __future__ import annotations

import anyio
from fastapi import APIRouter, Depends, Request, Response

from ..deps import get_store, owned_job
from ..problems import ProblemError
from ..store import JobRow, JobStore
from ..views import job_url
from .docs import problems
from .results import _download, _ensure_renders, _send

router = APIRouter(prefix="/jobs/{job_id}", tags=["results"])

#: file name in the URL -> the stored render
FILES = {"timeline.csv": "timeline.csv.gz", "timeline.nc": "timeline.nc", "timeline.svg": "timeline.svg"}


async def _has_timeline(request: Request, job: JobRow, store: JobStore) -> None:
    await _ensure_renders(request, job, store)
    if "timeline.nc" not in await anyio.to_thread.run_sync(store.render_names, job.id):
        raise ProblemError(404, "no-timeline", f"job {job.id} has no timeline: its scene has no `timeline` section")


@router.get(
    "/timeline",
    operation_id="get_timeline_files",
    summary="The timeline's files (a scene with a `timeline`): their URLs",
    responses={200: {"description": "{'files': {name: url}}"}, **problems(401, 404, 409)},
)
async def get_timeline_files(
    request: Request, job: JobRow = Depends(owned_job), store: JobStore = Depends(get_store)
) -> dict:
    await _has_timeline(request, job, store)
    return {"files": {name: f"{job_url(job.id)}/{name}" for name in FILES}}


async def _file(request: Request, job: JobRow, store: JobStore, name: str) -> Response:
    await _has_timeline(request, job, store)
    return await _send(request, job, store, FILES[name], _download(f"{job.id}-{name}"))


@router.get(
    "/timeline.csv",
    operation_id="get_timeline_csv",
    summary="The timeline: one row per link and time (the command line's timeline.csv)",
    response_class=Response,
    responses={200: {"content": {"text/csv": {"schema": {"type": "string"}}}}, **problems(401, 404, 409)},
)
async def get_timeline_csv(
    request: Request, job: JobRow = Depends(owned_job), store: JobStore = Depends(get_store)
) -> Response:
    return await _file(request, job, store, "timeline.csv")


@router.get(
    "/timeline.nc",
    operation_id="get_timeline_netcdf",
    summary="The timeline as netCDF3: dims (link, time) (the command line's timeline.nc)",
    response_class=Response,
    responses={
        200: {"content": {"application/x-netcdf": {"schema": {"type": "string", "format": "binary"}}}},
        **problems(401, 404, 409),
    },
)
async def get_timeline_netcdf(
    request: Request, job: JobRow = Depends(owned_job), store: JobStore = Depends(get_store)
) -> Response:
    return await _file(request, job, store, "timeline.nc")


@router.get(
    "/timeline.svg",
    operation_id="get_timeline_plot",
    summary="H0 and BER against time with the outage bands (SVG)",
    response_class=Response,
    responses={200: {"content": {"image/svg+xml": {"schema": {"type": "string"}}}}, **problems(401, 404, 409)},
)
async def get_timeline_plot(
    request: Request, job: JobRow = Depends(owned_job), store: JobStore = Depends(get_store)
) -> Response:
    return await _file(request, job, store, "timeline.svg")
