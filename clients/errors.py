"""Exceptions of the Python client. An answer of the server carries its problem document."""

from __future__ import annotations

from owcsim.schemas.errors import Problem, ProblemField


class OwcsimError(Exception):
    """Base class of the client's errors."""


class ConnectionFailed(OwcsimError):
    """The server could not be reached (after the retries). For a submission, `idempotency_key`
    is the key it was sent with: submitting again with it returns the job if the server made one."""

    def __init__(self, message: str, idempotency_key: str | None = None):
        super().__init__(message)
        self.idempotency_key = idempotency_key


class ApiError(OwcsimError):
    """The server refused the request: `status`, and `problem` (RFC 9457) with the wrong fields."""

    def __init__(self, status: int, problem: Problem):
        self.status, self.problem = status, problem
        super().__init__(str(self))

    @property
    def errors(self) -> list[ProblemField]:
        return self.problem.errors

    def __str__(self) -> str:
        head = f"{self.status} {self.problem.title}: {self.problem.detail or ''}".rstrip(": ")
        lines = [f"  {e.loc}: {e.msg}" for e in self.problem.errors]
        return "\n".join([head] + lines) if len(lines) > 1 else head


class InvalidRequest(ApiError):
    """400, 413, 415, 422: the document or a parameter is wrong (see `errors`)."""


class Unauthorized(ApiError):
    """401/403: no API key, or one the server does not know."""


class NotFound(ApiError):
    """404: no such job (or it belongs to another API key)."""


class Conflict(ApiError):
    """409: e.g. the result of a job that has not succeeded, or cancelling a finished job."""


class QueueFull(ApiError):
    """429: the server's queue stayed full through the retries."""


class ServerError(ApiError):
    """5xx: the server failed."""


class JobFailed(OwcsimError):
    """The job ended in `failed`; `job.error` says why."""

    def __init__(self, job):
        self.job = job
        super().__init__(f"job {job.id} failed: {job.error}")


def error_for(status: int, problem: Problem) -> ApiError:
    cls: type[ApiError]
    if status in (401, 403):
        cls = Unauthorized
    elif status == 404:
        cls = NotFound
    elif status == 409:
        cls = Conflict
    elif status == 429:
        cls = QueueFull
    elif status >= 500:
        cls = ServerError
    else:
        cls = InvalidRequest
    return cls(status, problem)
