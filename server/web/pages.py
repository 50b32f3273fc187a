"""The pages: GET / and /ui (the jobs list), /ui/submit, /ui/jobs/{job_id} (the result page), and their
files at /ui/static/*.

The pages are static files: they hold no data and need no API key. Their scripts ask the JSON API
(/v1/...) for everything, sending the key the user typed (`Authorization: Bearer`, static/api.js), so a
key sees exactly what it sees through the API. `install(app)` registers the routes and the files
(no /v1 prefix: these are pages, not the API; left out of the OpenAPI document).
"""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, FastAPI
from fastapi.responses import FileResponse, HTMLResponse
from fastapi.staticfiles import StaticFiles

#: The pages' files (HTML, JS modules, CSS), served at STATIC_URL.
STATIC = Path(__file__).resolve().parent / "static"
STATIC_URL = "/ui/static"

router = APIRouter(include_in_schema=False)

#: Until the result page exists: a page that says so and links to the job's JSON.
_NO_RESULT_PAGE = """<!doctype html><html lang="en"><head><meta charset="utf-8"><title>owcsim job</title>
<link rel="stylesheet" href="/ui/static/base.css"></head><body><main>
<p>This build has no result page. <a href="/ui">Jobs</a></p></main></body></html>"""


def _page(name: str) -> FileResponse:
    # no-cache: a browser asks again (and gets 304 if unchanged), so an upgraded server's pages are used at once
    return FileResponse(STATIC / name, media_type="text/html", headers={"Cache-Control": "no-cache"})


@router.get("/")
@router.get("/ui")
def jobs_page() -> FileResponse:
    return _page("jobs.html")


@router.get("/ui/submit")
def submit_page() -> FileResponse:
    return _page("submit.html")


@router.get("/ui/jobs/{job_id}", response_model=None)
def result_page(job_id: str) -> FileResponse | HTMLResponse:
    """The same file for every job: its script reads the id from the address and the job from the API."""
    if (STATIC / "result.html").is_file():
        return _page("result.html")
    return HTMLResponse(_NO_RESULT_PAGE)


def install(app: FastAPI) -> None:
    """Register the pages and their static files on the app."""
    app.include_router(router)
    app.mount(STATIC_URL, StaticFiles(directory=STATIC), name="ui-static")
