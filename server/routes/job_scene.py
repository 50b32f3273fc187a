"""A job's scene document, as the service validated and stored it (read-only).

GET /v1/jobs/{id}/scene returns the canonical document the job runs (defaults filled in), in any state:
the web pages draw the scene preview from it before a result exists. A job another API key owns is
'not found', as for every job route.
"""

from __future__ import annotations

import anyio
from fastapi import APIRouter, Depends, Response

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
    try:
        text = await anyio.to_thread.run_sync(store.scene_json, job.id)
    except TypeError:  # the job was deleted between the owner check and this read: its document is gone
        raise ProblemError(404, "job-not-found", f"no job {job.id!r}") from None
    return Response(text, media_type="application/json")
