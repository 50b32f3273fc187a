"""A job's scene document, as the service validated and stored it (read-only).

GET /v1/jobs/{id}/scene returns the canonical document the job runs (defaults filled in), in any state, streamed:
the web pages draw the scene preview from it before a result exists. A job another API key owns is
'not found', as for every job route.
"""

from __future__ import annotations

import anyio
from fastapi import APIRouter, Depends, Response
from fastapi.responses import StreamingResponse

from owcsim.schemas import SceneSpec

from ..deps import get_store, owned_job
from ..problems import ProblemError
from ..store import JobRow, JobStore
from .docs import problems

router = APIRouter(prefix="/jobs/{job_id}", tags=["jobs"])


@router.get(
    "/scene",
    operation_id="get_job_scene",
    summary="The job's scene document (validated, defaults filled in)",
    response_class=Response,
    responses={200: {"model": SceneSpec, "description": "the scene document the job runs"}, **problems(401, 404)},
)
async def get_job_scene(job: JobRow = Depends(owned_job), store: JobStore = Depends(get_store)) -> Response:
    chunks = await anyio.to_thread.run_sync(store.scene_chunks, job.id)
    if chunks is None:  # the job was deleted between the owner check and this read: its document is gone
        raise ProblemError(404, "job-not-found", f"no job {job.id!r}")
    # streamed, decompressed a piece at a time: a large document (18 MB for 90,000 receivers) is never whole in
    # the server's memory (it was, once per request: 20 requests at once took the server +519 MB)
    return StreamingResponse(chunks, media_type="application/json")
