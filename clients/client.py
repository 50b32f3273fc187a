"""The Python client of the owcsim service (httpx). `AsyncClient` in clients.aio is its async twin.

    from owcsim.clients import Client
    with Client("http://127.0.0.1:8000", api_key=None) as owc:
        job = owc.submit("examples/barry_config_a.json")
        job.wait(progress=True)
        result = job.result()              # schemas.results.SimulationResultPublic (clients.Result)
        arrays = result.arrays()           # numpy: t_edges_s, cir, cir_stderr, by_reflection_order, ...
        result.plot("cir.png")

Connection errors and 429/503 answers are retried with backoff (RetryPolicy); other
error answers raise an ApiError subclass carrying the server's problem document.
"""

from __future__ import annotations

import io
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import httpx

from owcsim.schemas import SceneSpec
from owcsim.schemas.jobs import TERMINAL_STATUSES, HealthPublic, JobListPublic, JobPublic, VersionPublic

from .errors import ConnectionFailed, JobFailed
from .http import (
    API,
    LAST_POLL_S,
    RetryPolicy,
    attempt_timeout,
    check,
    headers,
    retry_delay,
    submission_lost,
    unreachable,
)
from .progress import ProgressBar
from .result import Result
from .scene import scene_document

#: Polling of a job: first interval, growth per poll, longest interval [s].
POLL = (0.1, 1.5, 2.0)


def job_path(job_id: str, suffix: str = "") -> str:
    return f"{API}/jobs/{job_id}{suffix}"


class Job:
    """A job on the server. Attributes of schemas.jobs.JobPublic (status, progress, error, ...) as of
    the latest `refresh()`; `wait()` refreshes until the job ends."""

    def __init__(self, client: "Client", info: JobPublic):
        self.client, self.info = client, info

    def __getattr__(self, name):
        if name == "info":
            raise AttributeError(name)
        return getattr(self.info, name)

    def __repr__(self) -> str:
        return f"<Job {self.info.id} {self.info.status} {100 * self.info.progress.fraction:.0f}%>"

    @property
    def done(self) -> bool:
        return self.info.status in TERMINAL_STATUSES

    def refresh(self, deadline: float | None = None) -> "Job":
        """The job's current state; `deadline` (time.monotonic) bounds the request and its retries."""
        response = self.client._request("GET", job_path(self.info.id), deadline=deadline)
        self.info = JobPublic.model_validate(response.json())
        return self

    def wait(self, progress: bool = False, timeout: float | None = None, stream=None) -> "Job":
        """Until the job ends; raises JobFailed if it failed, TimeoutError after `timeout` seconds.

        `progress=True` draws a progress bar on stderr (or `stream`)."""
        bar = ProgressBar(stream) if progress else None
        deadline = None if timeout is None else time.monotonic() + timeout
        interval = POLL[0]
        try:
            while True:
                self.refresh(deadline=None if deadline is None else deadline + LAST_POLL_S)
                if bar:
                    bar.update(self.info, force=self.done)
                if self.done:
                    break
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    raise TimeoutError(f"job {self.info.id} is still {self.info.status} after {timeout} s")
                time.sleep(interval if left is None else min(interval, left))  # the last poll is at the deadline
                interval = min(interval * POLL[1], POLL[2])
        finally:
            if bar:
                bar.close()
        if self.info.status == "failed":
            raise JobFailed(self)
        return self

    def result(self, wait: bool = True, timeout: float | None = None) -> Result:
        """The result document (waiting for the job first, unless `wait=False`). A cancelled job that had
        started gives its partial result (`run.stop_reason` is `cancelled`)."""
        if wait and not self.done:
            self.wait(timeout=timeout)
        elif self.info.status == "failed":
            raise JobFailed(self)
        return Result.from_document(self.client._request("GET", job_path(self.info.id, "/result")).json())

    def cancel(self) -> "Job":
        self.info = JobPublic.model_validate(self.client._request("POST", job_path(self.info.id, "/cancel")).json())
        return self

    def csv(self) -> str:
        """The binned CIR of every link as CSV text (the columns of cir.csv)."""
        return self.client._request("GET", job_path(self.info.id, "/result.csv")).text

    def npz(self) -> dict:
        """The server's .npz arrays (see Result.arrays)."""
        import numpy as np

        data = self.client._request("GET", job_path(self.info.id, "/result.npz")).content
        with np.load(io.BytesIO(data)) as z:
            return {k: z[k] for k in z.files}

    def plot_png(self, link: int | None = None) -> bytes:
        params = {"link": link} if link is not None else None
        return self.client._request("GET", job_path(self.info.id, "/plot.png"), params=params).content

    def timeline_file(self, name: str) -> bytes:
        """A timeline job's file as served: "timeline.csv", "timeline.nc" or "timeline.svg" (docs/fire-timeline.md)."""
        if name not in ("timeline.csv", "timeline.nc", "timeline.svg"):
            raise ValueError(f"no timeline file {name!r}: timeline.csv, timeline.nc or timeline.svg")
        return self.client._request("GET", job_path(self.info.id, f"/{name}")).content


class Client:
    """Client(base_url, api_key=None). `http` may be any httpx.Client (tests pass a TestClient)."""

    def __init__(
        self,
        base_url: str = "http://127.0.0.1:8000",
        api_key: str | None = None,
        *,
        timeout: float = 60.0,
        retry: RetryPolicy = RetryPolicy(),
        http: httpx.Client | None = None,
    ):
        self.base_url = base_url.rstrip("/")
        self.retry = retry
        self._own = http is None
        self._timeout = timeout
        self._http = http if http is not None else httpx.Client(base_url=self.base_url, timeout=timeout)
        self._headers = headers(api_key)

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self._own:
            self._http.close()

    def _request(
        self, method: str, path: str, *, answers: tuple[int, ...] = (), deadline: float | None = None, **kw
    ) -> httpx.Response:
        """Send with retries; an error answer raises its ApiError, except the statuses in `answers`.
        With `deadline` (time.monotonic), no try runs past it: TimeoutError instead."""
        extra = kw.pop("headers", {})
        attempt = 0
        while True:
            timeout = attempt_timeout(self._timeout, deadline)
            try:
                response = self._http.request(method, path, headers={**self._headers, **extra}, timeout=timeout, **kw)
            except httpx.TransportError as exc:
                delay = retry_delay(self.retry, attempt, None, deadline)
                if delay is None:
                    raise unreachable(self.base_url, exc, self.retry, attempt, deadline) from exc
                time.sleep(delay)
            else:
                if response.status_code in answers:
                    return response
                delay = retry_delay(self.retry, attempt, response, deadline)
                if delay is None:
                    return check(response)
                time.sleep(delay)
            attempt += 1

    def submit(
        self,
        scene: SceneSpec | dict | str | Path,
        *,
        base_dir: str | Path | None = None,
        idempotency_key: str | None = None,
    ) -> Job:
        """Queue a scene (a SceneSpec, a dict, or a path to a JSON file); mesh files are sent inline.
        A fresh Idempotency-Key makes the retries of this call safe."""
        doc = scene_document(scene, base_dir)
        key = idempotency_key or uuid.uuid4().hex
        try:
            response = self._request("POST", f"{API}/jobs", json=doc, headers={"Idempotency-Key": key})
        except ConnectionFailed as exc:
            raise submission_lost(exc, key) from exc
        return Job(self, JobPublic.model_validate(response.json()))

    def run(self, scene, *, progress: bool = True, timeout: float | None = None, **kw) -> Result:
        """Submit, wait (with a progress bar) and return the result."""
        return self.submit(scene, **kw).wait(progress=progress, timeout=timeout).result()

    def job(self, job_id: str) -> Job:
        return Job(self, JobPublic.model_validate(self._request("GET", job_path(job_id)).json()))

    def jobs(self, status: str | list[str] | None = None, page_size: int = 100) -> Iterator[Job]:
        """Every job visible to this key, newest first (follows the pages)."""
        params: dict = {"limit": page_size}
        if status:
            params["status"] = [status] if isinstance(status, str) else list(status)
        while True:
            page = JobListPublic.model_validate(self._request("GET", f"{API}/jobs", params=params).json())
            yield from (Job(self, j) for j in page.items)
            if page.next_cursor is None:
                return
            params["cursor"] = page.next_cursor

    def health(self) -> HealthPublic:
        """The server's health (status `unavailable` when it cannot run jobs: that is an answer, not an error)."""
        return HealthPublic.model_validate(self._request("GET", f"{API}/health", answers=(503,)).json())

    def version(self) -> VersionPublic:
        return VersionPublic.model_validate(self._request("GET", f"{API}/version").json())
