"""STAND-IN of branch webresult for the `webjobs` branch's page router (drop at merge, keep theirs): the
result page at /ui/jobs/{id} and the static files at /ui/static/*, all the result page's tests need."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import FileResponse

from ..problems import ProblemError

STATIC = Path(__file__).resolve().parent / "static"
router = APIRouter(include_in_schema=False)


@router.get("/ui/jobs/{job_id}")
def result_page(job_id: str) -> FileResponse:
    return FileResponse(STATIC / "result.html", media_type="text/html")


@router.get("/ui/static/{name}")
def static_file(name: str) -> FileResponse:
    path = STATIC / name
    if "/" in name or not path.is_file():
        raise ProblemError(404, "not-found", f"no file {name!r}")
    return FileResponse(path)
