"""Errors as problem details (RFC 9457, `application/problem+json`), never a stack trace.

Route code raises `ProblemError`; the handlers here turn it, FastAPI's own errors
(unknown route, wrong method, a bad query parameter) and any unexpected exception
into a problem document. Field locations are dotted: `body.receivers.0.fov_deg`,
`query.limit`, `header.Idempotency-Key`.
"""

from __future__ import annotations

import logging
import re
import sqlite3
import uuid
from collections.abc import Mapping, Sequence
from http import HTTPStatus

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

from owcsim.schemas.errors import PROBLEM_MEDIA_TYPE, Problem, ProblemField, located

from .job_rows import is_disk_full

_HTTP_METHODS = {"GET", "PUT", "POST", "DELETE", "OPTIONS", "HEAD", "PATCH", "TRACE"}
log = logging.getLogger("owcsim.server")

URN = "urn:owcsim:problem:"
#: Most located errors a problem document lists; `error_count` counts them all.
MAX_LISTED_ERRORS = 20


class ProblemError(Exception):
    """An error answer: status, kind (`urn:owcsim:problem:<kind>`), what happened, wrong fields."""

    def __init__(
        self,
        status: int,
        kind: str,
        detail: str,
        *,
        errors: Sequence[ProblemField] = (),
        headers: dict[str, str] | None = None,
        **extensions,
    ):
        super().__init__(detail)
        self.status, self.kind, self.detail = status, kind, detail
        self.errors, self.headers, self.extensions = list(errors), headers or {}, extensions


def field_errors(errors: Sequence[Mapping], prefix: tuple = ()) -> list[ProblemField]:
    """pydantic errors -> located fields, e.g. body.receivers.0.fov_deg."""
    return [
        ProblemField(loc=loc or "body", msg=msg, type=e.get("type", "value_error"))
        for (loc, msg), e in zip(located(errors, prefix), errors)
    ]


def problem_response(
    request: Request,
    status: int,
    kind: str,
    detail: str | None,
    *,
    errors: Sequence[ProblemField] = (),
    headers: dict | None = None,
    title: str | None = None,
    **extensions,
) -> JSONResponse:
    body = Problem(
        type=URN + kind if kind else "about:blank",
        title=title or HTTPStatus(status).phrase,
        status=status,
        detail=detail,
        instance=request.url.path,
        errors=list(errors),
        **extensions,
    )
    return JSONResponse(
        body.model_dump(mode="json", exclude_none=True),
        status_code=status,
        headers=headers,
        media_type=PROBLEM_MEDIA_TYPE,
    )


_KIND_BY_STATUS = {
    400: "bad-request",
    401: "unauthorized",
    404: "not-found",
    405: "method-not-allowed",
    413: "body-too-large",
    415: "unsupported-media-type",
    429: "too-many-requests",
}


def _documented_methods(request: Request) -> set[str]:
    """Methods the OpenAPI document gives the request's path (routers included under a prefix
    do not show their routes in app.routes)."""
    out: set[str] = set()
    for template, operations in request.app.openapi().get("paths", {}).items():
        parts = re.split(r"(\{[^/}]+\})", template)
        pattern = "".join("[^/]+" if part.startswith("{") else re.escape(part) for part in parts)
        if re.fullmatch(pattern, request.url.path):
            out |= {m.upper() for m in operations if m.upper() in _HTTP_METHODS}
    return out | ({"HEAD"} if "GET" in out else set())


def install(app: FastAPI) -> None:
    """Register the handlers on the app."""

    @app.exception_handler(ProblemError)
    async def _problem(request: Request, exc: ProblemError):
        return problem_response(
            request, exc.status, exc.kind, exc.detail, errors=exc.errors, headers=exc.headers, **exc.extensions
        )

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError):
        every = list(exc.errors())
        errors = field_errors(every[:MAX_LISTED_ERRORS])  # the first few, and how many there are
        detail = "; ".join(f"{e.loc}: {e.msg}" for e in errors[:5])
        return problem_response(request, 422, "invalid-parameter", detail, errors=errors, error_count=len(every))

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException):
        detail = exc.detail if isinstance(exc.detail, str) else None
        headers = dict(getattr(exc, "headers", None) or {})
        if exc.status_code == 404 and detail == "Not Found":
            detail = f"no such resource: {request.method} {request.url.path}"
        if exc.status_code == 405:  # every method of the path, not only those of the first route matched
            allowed = sorted(
                {
                    m
                    for r in request.app.routes
                    if r.matches(request.scope)[0] != Match.NONE
                    for m in getattr(r, "methods", None) or ()
                }
                | _documented_methods(request)
            )
            headers["Allow"] = ", ".join(allowed)
            detail = f"{request.method} is not allowed on {request.url.path}; allowed: {headers['Allow']}"
        return problem_response(
            request, exc.status_code, _KIND_BY_STATUS.get(exc.status_code, ""), detail, headers=headers
        )

    @app.exception_handler(sqlite3.OperationalError)
    async def _store(request: Request, exc: sqlite3.OperationalError):
        """Disk full: 507; the store busy (locked past the timeout): 503. Both retryable."""
        if is_disk_full(exc):
            log.error("job store: disk full on %s %s", request.method, request.url.path)
            return problem_response(
                request,
                507,
                "insufficient-storage",
                "the server's disk is full: nothing was changed; try again later",
                headers={"Retry-After": "30"},
            )
        log.warning("job store busy on %s %s: %s", request.method, request.url.path, exc)
        return problem_response(
            request,
            503,
            "store-busy",
            "the job store is busy: nothing was changed; try again later",
            headers={"Retry-After": "5"},
        )

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception):
        ref = uuid.uuid4().hex[:12]
        log.error("internal error %s on %s %s", ref, request.method, request.url.path, exc_info=exc)
        return problem_response(
            request,
            500,
            "internal-error",
            f"the server failed to answer this request; the server log has the details under reference {ref}",
            reference=ref,
        )
