"""The API's documentation: OpenAPI pieces shared by the routes (the scene request body, the problem
answers), and the interactive pages, Swagger UI at /v1/docs and ReDoc at /v1/redoc.

The pages load their JavaScript, CSS and icon from this app (/v1/docs/assets/...), never from a CDN:
they work on a machine without internet access. The assets are the ones the fastapi-offline package
ships (a registry package that bundles Swagger UI and ReDoc for exactly this); only its files are
used, not its FastAPI wrapper, so the app keeps its own constructor.
"""

from __future__ import annotations

import importlib.util
from functools import lru_cache
from http import HTTPStatus
from pathlib import Path

from fastapi import APIRouter, Request
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html, get_swagger_ui_oauth2_redirect_html
from fastapi.responses import FileResponse, HTMLResponse

from owcsim.schemas.errors import PROBLEM_MEDIA_TYPE, Problem

from ..problems import problem_response

#: A small scene: Barry et al. 1993 configuration A at 20 000 paths (the OpenAPI example).
EXAMPLE_SCENE = {
    "name": "Barry et al. 1993, configuration A",
    "room": {"size": [5.0, 5.0, 3.0], "reflectance": {"floor": 0.3, "ceiling": 0.8, "walls": 0.8}},
    "transmitters": [{"id": "tx", "position": [2.5, 2.5, 3.0], "normal": [0, 0, -1], "lambertian_order": 1}],
    "receivers": [{"id": "rx", "position": [0.5, 1.0, 0.0], "normal": [0, 0, 1], "area": 1e-4, "fov_deg": 85}],
    "simulation": {"max_reflections": 3, "time_bin_s": 2e-10, "t_max_s": 1e-7, "paths": 20000, "seed": 1},
}

#: The body of POST /v1/jobs: read by the route itself (size-limited, validated in a thread).
SCENE_BODY = {
    "required": True,
    "description": "the scene document `owcsim run` takes (scene + medium + simulation settings); meshes inline "
    "or as base64 file content, never as a path",
    "content": {"application/json": {"schema": {"$ref": "#/components/schemas/SceneSpec"}, "example": EXAMPLE_SCENE}},
}

#: Where the job a submission answers leads (OpenAPI links: clients and fuzzers can follow them).
JOB_LINKS = {
    name: {"operationId": op, "parameters": {"job_id": "$response.body#/id"}}
    for name, op in (
        ("GetJob", "get_job"),
        ("CancelJob", "cancel_job"),
        ("GetResult", "get_result"),
        ("GetResultCsv", "get_result_csv"),
        ("GetResultNpz", "get_result_npz"),
        ("GetPlot", "get_plot"),
    )
}


def problems(*codes: int) -> dict:
    """`responses=` entries: these statuses answer a problem document."""
    return {
        c: {"description": HTTPStatus(c).phrase, "model": Problem, "content": {PROBLEM_MEDIA_TYPE: {}}} for c in codes
    }


#: The files the pages load, served from the app: {name: media type}.
ASSETS = {
    "swagger-ui-bundle.js": "text/javascript",
    "swagger-ui.css": "text/css",
    "redoc.standalone.js": "text/javascript",
    "favicon.png": "image/png",
}

router = APIRouter(include_in_schema=False)


@lru_cache(maxsize=1)
def assets_folder() -> Path:
    """The folder of the fastapi-offline package's bundled Swagger UI and ReDoc files (not imported)."""
    spec = importlib.util.find_spec("fastapi_offline")
    if spec is None or spec.origin is None:
        raise RuntimeError("the API documentation pages need fastapi-offline: pip install 'owcsim[server]'")
    return Path(spec.origin).parent / "static"


def _asset_url(request: Request, name: str) -> str:
    return str(request.url_for("docs_asset", name=name).path)


@router.get("/docs", response_class=HTMLResponse)
def swagger_ui(request: Request) -> HTMLResponse:
    app = request.app
    return get_swagger_ui_html(
        openapi_url=request.scope.get("root_path", "") + app.openapi_url,
        title=f"{app.title} - Swagger UI",
        swagger_js_url=_asset_url(request, "swagger-ui-bundle.js"),
        swagger_css_url=_asset_url(request, "swagger-ui.css"),
        swagger_favicon_url=_asset_url(request, "favicon.png"),
        oauth2_redirect_url=str(request.url_for("docs_oauth2_redirect").path),
    )


@router.get("/docs/oauth2-redirect", response_class=HTMLResponse, name="docs_oauth2_redirect")
def swagger_ui_redirect() -> HTMLResponse:
    return get_swagger_ui_oauth2_redirect_html()


@router.get("/redoc", response_class=HTMLResponse)
def redoc(request: Request) -> HTMLResponse:
    app = request.app
    return get_redoc_html(
        openapi_url=request.scope.get("root_path", "") + app.openapi_url,
        title=f"{app.title} - ReDoc",
        redoc_js_url=_asset_url(request, "redoc.standalone.js"),
        redoc_favicon_url=_asset_url(request, "favicon.png"),
        with_google_fonts=False,
    )


@router.get("/docs/assets/{name}", name="docs_asset")
def docs_asset(request: Request, name: str):
    if name not in ASSETS:  # a fixed list: no path from the request ever reaches the file system
        return problem_response(request, 404, "not-found", f"no documentation asset {name!r}")
    return FileResponse(
        assets_folder() / name, media_type=ASSETS[name], headers={"Cache-Control": "public, max-age=86400"}
    )
