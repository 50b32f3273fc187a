"""Answers for a job store that cannot be read while the server runs (overwritten, damaged).

SQLite reports such a file as `sqlite3.DatabaseError` ("file is not a database", "database disk
image is malformed"); without this handler a request meeting it was a 500 "internal error". It is
a 503 `store-damaged` naming what the operator must do; health says 503 as well (the dispatcher's
`JobStore.check` sees the file replaced or overwritten). Disk full and a busy store are
`sqlite3.OperationalError`, answered by problems.py (507, 503).
"""

from __future__ import annotations

import logging
import sqlite3

from fastapi import FastAPI, Request

from .problems import problem_response

log = logging.getLogger("owcsim.server")


def install(app: FastAPI) -> None:
    @app.exception_handler(sqlite3.DatabaseError)
    async def _damaged(request: Request, exc: sqlite3.DatabaseError):
        log.error("job store cannot be read on %s %s: %s", request.method, request.url.path, exc)
        return problem_response(
            request,
            503,
            "store-damaged",
            f"the server's job store cannot be read ({exc}): nothing was changed; the operator must restore "
            "it from a backup and restart the server",
            headers={"Retry-After": "30"},
        )
