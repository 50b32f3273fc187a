"""A job's result: the result document (JSON), the CIR as CSV and .npz, h(t) as PNG.

Served once the job has succeeded, and for a cancelled job that stopped with a partial
result (its `run.stop_reason` is `cancelled`). Otherwise 409 with the job's status.

Nothing is rendered per request: the job's worker rendered the JSON, CSV and NPZ once when
the job ended (server.formats.render_all) and the store keeps them compressed; an answer
streams the stored bytes in chunks (as gzip with `Content-Encoding: gzip` to a client that
accepts it, decompressed on the way otherwise), so serving any result takes bounded memory.
A plot is drawn from the rows of its links in the stored .npz (at most 6), in the threads
for heavy work; the default plot is stored once drawn.
"""

from __future__ import annotations

import zlib
from typing import Annotated

import anyio
from fastapi import APIRouter, Depends, Query, Request, Response
from fastapi.responses import StreamingResponse

from owcsim.schemas.errors import ProblemField
from owcsim.schemas.results import SimulationResultPublic

from ..deps import get_store, owned_job
from ..formats import RENDERS, npz_link_count, npz_png, render_all
from ..problems import ProblemError
from ..store import JobRow, JobStore
from .docs import problems

router = APIRouter(prefix="/jobs/{job_id}", tags=["results"])


def _not_ready(job: JobRow) -> ProblemError:
    why = {
        "queued": "is queued",
        "running": "is running",
        "failed": f"failed: {job.error}",
        "cancelled": "was cancelled before it produced a result",
    }.get(job.status, f"is {job.status}")
    return ProblemError(409, "result-not-ready", f"job {job.id} has no result: it {why}", job_status=job.status)


def _render_legacy(job: JobRow, store: JobStore) -> None:
    """Render a result stored by an older server (without renders), once, and keep the renders."""
    import tempfile
    from pathlib import Path

    text = store.result_json(job.id)
    if text is None:
        raise _not_ready(job)
    with tempfile.TemporaryDirectory(prefix="owcsim-render-", dir=store.path.parent) as tmp:
        result = SimulationResultPublic.model_validate_json(text)
        store.put_renders(job.id, render_all(result, text.decode(), Path(tmp)))


async def _ensure_renders(request: Request, job: JobRow, store: JobStore) -> None:
    if not job.has_result:
        raise _not_ready(job)
    if not await anyio.to_thread.run_sync(store.render_names, job.id):
        await anyio.to_thread.run_sync(_render_legacy, job, store, limiter=request.app.state.heavy)


def _gunzip(chunks):
    d = zlib.decompressobj(wbits=31)
    for chunk in chunks:
        while chunk:
            out = d.decompress(chunk, 1 << 20)
            if out:
                yield out
            chunk = d.unconsumed_tail
    tail = d.flush()
    if tail:
        yield tail


async def _send(request: Request, job: JobRow, store: JobStore, name: str, headers: dict | None = None) -> Response:
    await _ensure_renders(request, job, store)
    chunks = store.render_chunks(job.id, name)
    if chunks is None:
        raise _not_ready(job)
    media_type, gzipped = RENDERS[name]
    headers = dict(headers or {})
    if gzipped:
        headers["Vary"] = "Accept-Encoding"
        if "gzip" in request.headers.get("accept-encoding", "").lower():
            headers["Content-Encoding"] = "gzip"
        else:
            chunks = _gunzip(chunks)
    return StreamingResponse(chunks, media_type=media_type, headers=headers)


def _download(name: str) -> dict:
    return {"Content-Disposition": f'attachment; filename="{name}"'}


@router.get(
    "/result",
    operation_id="get_result",
    summary="The result document (the command line's result.json)",
    responses={200: {"model": SimulationResultPublic, "description": "the result document"}, **problems(401, 404, 409)},
)
async def get_result(
    request: Request, job: JobRow = Depends(owned_job), store: JobStore = Depends(get_store)
) -> Response:
    return await _send(request, job, store, "result.json.gz")


@router.get(
    "/result.csv",
    operation_id="get_result_csv",
    summary="Binned CIR of every link, long format (the columns of cir.csv)",
    response_class=Response,
    responses={
        200: {"content": {"text/csv": {"schema": {"type": "string"}}}, "description": "CSV"},
        **problems(401, 404, 409),
    },
)
async def get_result_csv(
    request: Request, job: JobRow = Depends(owned_job), store: JobStore = Depends(get_store)
) -> Response:
    return await _send(request, job, store, "result.csv.gz", _download(f"{job.id}-cir.csv"))


@router.get(
    "/result.npz",
    operation_id="get_result_npz",
    summary="numpy arrays: t_edges_s, cir, cir_stderr, by_reflection_order, dc_gain, ...",
    response_class=Response,
    responses={
        200: {
            "content": {"application/octet-stream": {"schema": {"type": "string", "format": "binary"}}},
            "description": "numpy .npz archive (numpy.load)",
        },
        **problems(401, 404, 409),
    },
)
async def get_result_npz(
    request: Request, job: JobRow = Depends(owned_job), store: JobStore = Depends(get_store)
) -> Response:
    return await _send(request, job, store, "result.npz", _download(f"{job.id}-cir.npz"))


def _plot(store: JobStore, job_id: str, link: int | None) -> bytes:
    with store.open_render(job_id, "result.npz") as npz:
        n = npz_link_count(npz)
        if link is not None and link >= n:
            raise ProblemError(
                422,
                "invalid-parameter",
                f"link {link} does not exist: the result has {n} links",
                errors=[ProblemField(loc="query.link", msg="no such link", type="value_error")],
            )
        npz.seek(0)
        try:
            png = npz_png(npz, link)
        except KeyError as exc:  # the link exists but asked for no binned CIR (a grid point, by default)
            raise ProblemError(
                422,
                "invalid-parameter",
                str(exc.args[0]),
                errors=[ProblemField(loc="query.link", msg="no binned CIR for this link", type="value_error")],
            ) from None
    if link is None:
        store.put_renders(job_id, {"plot.png": png})
    return png


@router.get(
    "/plot.png",
    operation_id="get_plot",
    summary="h(t) per reflection order and total (up to 6 links, or the one asked)",
    response_class=Response,
    responses={
        200: {"content": {"image/png": {"schema": {"type": "string", "format": "binary"}}}, "description": "PNG"},
        **problems(401, 404, 409, 422),
    },
)
async def get_plot(
    request: Request,
    link: Annotated[int | None, Query(ge=0, description="index in the result's `links`")] = None,
    job: JobRow = Depends(owned_job),
    store: JobStore = Depends(get_store),
) -> Response:
    await _ensure_renders(request, job, store)
    if link is None and "plot.png" in await anyio.to_thread.run_sync(store.render_names, job.id):
        return await _send(request, job, store, "plot.png")
    png = await anyio.to_thread.run_sync(_plot, store, job.id, link, limiter=request.app.state.heavy)
    return Response(png, media_type="image/png")
