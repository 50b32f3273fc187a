"""What the sync and async clients share: retry policy, headers, turning error answers into exceptions.

Retried: connection errors (and timeouts), 429, 502/503/504 and 507 (disk full), with exponential backoff and
jitter, honouring Retry-After. A submission carries an Idempotency-Key, so a retry after a
lost answer returns the first job instead of queueing a duplicate.
"""

from __future__ import annotations

import random
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from email.utils import parsedate_to_datetime

import httpx

from owcsim.schemas.errors import Problem

from .errors import ConnectionFailed, error_for

RETRY_STATUSES = frozenset({429, 502, 503, 504, 507})  # 507: the server's disk is full for now
API = "/v1"
#: `wait(timeout=T)` may spend up to this long after T on its last status request [s].
LAST_POLL_S = 1.0


@dataclass(frozen=True)
class RetryPolicy:
    """`retries` more tries after the first; waits backoff_s * 2**attempt (jittered), at most max_backoff_s."""

    retries: int = 5
    backoff_s: float = 0.5
    max_backoff_s: float = 30.0

    def delay(self, attempt: int, response: httpx.Response | None = None) -> float:
        after = retry_after(response) if response is not None else None
        if after is not None:
            return min(after, self.max_backoff_s)
        return min(self.max_backoff_s, self.backoff_s * 2**attempt) * random.uniform(0.5, 1.0)

    def should_retry(self, attempt: int, response: httpx.Response | None) -> bool:
        """After a connection error (response None) or a retryable status, while tries remain."""
        return attempt < self.retries and (response is None or response.status_code in RETRY_STATUSES)


def retry_after(response: httpx.Response) -> float | None:
    value = response.headers.get("retry-after")
    if not value:
        return None
    try:
        return max(0.0, float(value))
    except ValueError:
        pass
    try:
        return max(0.0, (parsedate_to_datetime(value) - datetime.now(UTC)).total_seconds())
    except (TypeError, ValueError):
        return None


def headers(api_key: str | None) -> dict[str, str]:
    out = {"Accept": "application/json, application/problem+json"}
    if api_key:
        out["Authorization"] = f"Bearer {api_key}"
    return out


def problem_of(response: httpx.Response) -> Problem:
    """The answer's problem document; one made up from the status when the body is not one (a proxy's page)."""
    try:
        return Problem.model_validate(response.json())
    except Exception:
        text = response.text.strip()[:300] if response.content else None
        return Problem(title=response.reason_phrase or "error", status=response.status_code, detail=text or None)


def check(response: httpx.Response) -> httpx.Response:
    """Raise the ApiError of an error answer; return a successful one."""
    if response.is_success:
        return response
    raise error_for(response.status_code, problem_of(response))


def attempt_timeout(timeout: float, deadline: float | None) -> float:
    """Timeout of one request [s]: the client's, cut to what is left before `deadline` (time.monotonic)."""
    if deadline is None:
        return timeout
    left = deadline - time.monotonic()
    if left <= 0:
        raise TimeoutError("the deadline passed before the request was sent")
    return min(timeout, left)


def retry_delay(
    policy: RetryPolicy, attempt: int, response: httpx.Response | None, deadline: float | None
) -> float | None:
    """Seconds to wait before the next try, or None: no retries left, or the next try would end past `deadline`."""
    if not policy.should_retry(attempt, response):
        return None
    delay = policy.delay(attempt, response)
    return None if deadline is not None and time.monotonic() + delay >= deadline else delay


def unreachable(base_url: str, exc: Exception, policy: RetryPolicy, attempt: int, deadline: float | None) -> Exception:
    """The error for a request that got no answer: TimeoutError if the deadline stopped the retries."""
    if deadline is not None and policy.should_retry(attempt, None):
        return TimeoutError(f"no answer from the owcsim server at {base_url} before the deadline ({exc})")
    return ConnectionFailed(f"cannot reach the owcsim server at {base_url}: {exc}")


def submission_lost(exc: ConnectionFailed, key: str) -> ConnectionFailed:
    """A submission whose answer never came: the job may exist; its Idempotency-Key finds it."""
    return ConnectionFailed(
        f"{exc}. The server may have queued the job anyway: submit again with "
        f"idempotency_key={key!r} to get that job instead of a duplicate",
        idempotency_key=key,
    )
