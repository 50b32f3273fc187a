"""OpenAPI pieces shared by the routes: the scene request body and the problem answers."""
from __future__ import annotations

from http import HTTPStatus

from owcsim.schemas.errors import PROBLEM_MEDIA_TYPE, Problem

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
    "content": {"application/json": {"schema": {"$ref": "#/components/schemas/SceneSpec"},
                                     "example": EXAMPLE_SCENE}},
}

#: Where the job a submission answers leads (OpenAPI links: clients and fuzzers can follow them).
JOB_LINKS = {name: {"operationId": op, "parameters": {"job_id": "$response.body#/id"}}
             for name, op in (("GetJob", "get_job"), ("CancelJob", "cancel_job"), ("GetResult", "get_result"),
                              ("GetResultCsv", "get_result_csv"), ("GetResultNpz", "get_result_npz"),
                              ("GetPlot", "get_plot"))}


def problems(*codes: int) -> dict:
    """`responses=` entries: these statuses answer a problem document."""
    return {c: {"description": HTTPStatus(c).phrase, "model": Problem,
                "content": {PROBLEM_MEDIA_TYPE: {}}} for c in codes}
