"""A job's result: the result document (JSON), the CIR as CSV and .npz, h(t) as PNG.

Served once the job has succeeded, and for a cancelled job that stopped with a partial
result (its `run.stop_reason` is `cancelled`). Otherwise 409 with the job's status.
"""
from __future__ import annotations

import json
from typing import Annotated

from fastapi import APIRouter, Depends, Query, Response

from owcsim.schemas.results import SimulationResultPublic

from ..deps import get_store, owned_job
from ..formats import cir_csv, cir_npz, cir_png
from ..problems import ProblemError
from ..store import JobRow, JobStore
from .docs import problems

router = APIRouter(prefix="/jobs/{job_id}", tags=["results"])


def _result_bytes(job: JobRow, store: JobStore) -> bytes:
    if job.has_result:
        body = store.result_json(job.id)
        if body is not None:
            return body
    why = {"queued": "is queued", "running": "is running", "failed": f"failed: {job.error}",
           "cancelled": "was cancelled before it produced a result"}.get(job.status, f"is {job.status}")
    raise ProblemError(409, "result-not-ready", f"job {job.id} has no result: it {why}", job_status=job.status)


def _download(name: str) -> dict:
    return {"Content-Disposition": f'attachment; filename="{name}"'}


@router.get("/result", operation_id="get_result", summary="The result document (the command line's result.json)",
            responses={200: {"model": SimulationResultPublic, "description": "the result document"},
                       **problems(401, 404, 409)})
def get_result(job: JobRow = Depends(owned_job), store: JobStore = Depends(get_store)) -> Response:
    return Response(_result_bytes(job, store), media_type="application/json")


@router.get("/result.csv", operation_id="get_result_csv", summary="Binned CIR of every link, long format (the columns of cir.csv)",
            response_class=Response, responses={200: {"content": {"text/csv": {"schema": {"type": "string"}}},
                                                       "description": "CSV"}, **problems(401, 404, 409)})
def get_result_csv(job: JobRow = Depends(owned_job), store: JobStore = Depends(get_store)) -> Response:
    result = json.loads(_result_bytes(job, store))
    return Response(cir_csv(result), media_type="text/csv; charset=utf-8", headers=_download(f"{job.id}-cir.csv"))


@router.get("/result.npz", operation_id="get_result_npz", summary="numpy arrays: t_edges_s, cir, cir_stderr, by_reflection_order, dc_gain, ...",
            response_class=Response,
            responses={200: {"content": {"application/octet-stream": {"schema": {"type": "string",
                                                                                 "format": "binary"}}},
                             "description": "numpy .npz archive (numpy.load)"}, **problems(401, 404, 409)})
def get_result_npz(job: JobRow = Depends(owned_job), store: JobStore = Depends(get_store)) -> Response:
    result = json.loads(_result_bytes(job, store))
    return Response(cir_npz(result), media_type="application/octet-stream", headers=_download(f"{job.id}-cir.npz"))


@router.get("/plot.png", operation_id="get_plot", summary="h(t) per reflection order and total (up to 6 links, or the one asked)",
            response_class=Response,
            responses={200: {"content": {"image/png": {"schema": {"type": "string", "format": "binary"}}},
                             "description": "PNG"}, **problems(401, 404, 409, 422)})
def get_plot(link: Annotated[int | None, Query(ge=0, description="index in the result's `links`")] = None,
             job: JobRow = Depends(owned_job), store: JobStore = Depends(get_store)) -> Response:
    result = json.loads(_result_bytes(job, store))
    if link is not None and link >= len(result["links"]):
        raise ProblemError(422, "invalid-parameter", f"link {link} does not exist: the result has "
                           f"{len(result['links'])} links", errors=[{"loc": "query.link", "msg": "no such link"}])
    return Response(cir_png(result, link), media_type="image/png")
