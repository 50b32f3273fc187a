"""The async twin of clients.client: AsyncClient and AsyncJob, on httpx.AsyncClient.

async with AsyncClient("http://127.0.0.1:8000") as owc:
    job = await owc.submit(scene)
    await job.wait(progress=True)
    result = await job.result()
"""

from __future__ import annotations

import asyncio
import io
import time
import uuid
from collections.abc import AsyncIterator
from pathlib import Path

import httpx

from owcsim.schemas import SceneSpec
from owcsim.schemas.jobs import TERMINAL_STATUSES, HealthPublic, JobListPublic, JobPublic, VersionPublic

from .client import POLL, job_path
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


class AsyncJob:
    """As clients.client.Job, with coroutines."""

    def __init__(self, client: "AsyncClient", info: JobPublic):
        self.client, self.info = client, info

    def __getattr__(self, name):
        if name == "info":
            raise AttributeError(name)
        return getattr(self.info, name)

    def __repr__(self) -> str:
        return f"<AsyncJob {self.info.id} {self.info.status} {100 * self.info.progress.fraction:.0f}%>"

    @property
    def done(self) -> bool:
        return self.info.status in TERMINAL_STATUSES

    async def refresh(self, deadline: float | None = None) -> "AsyncJob":
        """The job's current state; `deadline` (time.monotonic) bounds the request and its retries."""
        response = await self.client._request("GET", job_path(self.info.id), deadline=deadline)
        self.info = JobPublic.model_validate(response.json())
        return self

    async def wait(self, progress: bool = False, timeout: float | None = None, stream=None) -> "AsyncJob":
        bar = ProgressBar(stream) if progress else None
        deadline = None if timeout is None else time.monotonic() + timeout
        interval = POLL[0]
        try:
            while True:
                await self.refresh(deadline=None if deadline is None else deadline + LAST_POLL_S)
                if bar:
                    bar.update(self.info, force=self.done)
                if self.done:
                    break
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    raise TimeoutError(f"job {self.info.id} is still {self.info.status} after {timeout} s")
                # the last poll is at the deadline
                await asyncio.sleep(interval if left is None else min(interval, left))
                interval = min(interval * POLL[1], POLL[2])
        finally:
            if bar:
                bar.close()
        if self.info.status == "failed":
            raise JobFailed(self)
        return self

    async def result(self, wait: bool = True, timeout: float | None = None) -> Result:
        if wait and not self.done:
            await self.wait(timeout=timeout)
        elif self.info.status == "failed":
            raise JobFailed(self)
        response = await self.client._request("GET", job_path(self.info.id, "/result"))
        return Result.from_document(response.json())

    async def cancel(self) -> "AsyncJob":
        response = await self.client._request("POST", job_path(self.info.id, "/cancel"))
        self.info = JobPublic.model_validate(response.json())
        return self

    async def csv(self) -> str:
        return (await self.client._request("GET", job_path(self.info.id, "/result.csv"))).text

    async def npz(self) -> dict:
        import numpy as np

        data = (await self.client._request("GET", job_path(self.info.id, "/result.npz"))).content
        with np.load(io.BytesIO(data)) as z:
            return {k: z[k] for k in z.files}

    async def plot_png(self, link: int | None = None) -> bytes:
        params = {"link": link} if link is not None else None
        return (await self.client._request("GET", job_path(self.info.id, "/plot.png"), params=params)).content


class AsyncClient:
    """AsyncClient(base_url, api_key=None). `http` may be any httpx.AsyncClient."""

    def __init__(
        self,
        base_url: str = "http://127.0.0.1:8000",
        api_key: str | None = None,
        *,
        timeout: float = 60.0,
        retry: RetryPolicy = RetryPolicy(),
        http: httpx.AsyncClient | None = None,
    ):
        self.base_url = base_url.rstrip("/")
        self.retry = retry
        self._own = http is None
        self._timeout = timeout
        self._http = http if http is not None else httpx.AsyncClient(base_url=self.base_url, timeout=timeout)
        self._headers = headers(api_key)

    async def __aenter__(self) -> "AsyncClient":
        return self

    async def __aexit__(self, *exc) -> None:
        await self.close()

    async def close(self) -> None:
        if self._own:
            await self._http.aclose()

    async def _request(
        self, method: str, path: str, *, answers: tuple[int, ...] = (), deadline: float | None = None, **kw
    ) -> httpx.Response:
        """Send with retries; an error answer raises its ApiError, except the statuses in `answers`.
        With `deadline` (time.monotonic), no try runs past it: TimeoutError instead."""
        extra = kw.pop("headers", {})
        attempt = 0
        while True:
            timeout = attempt_timeout(self._timeout, deadline)
            try:
                response = await self._http.request(
                    method, path, headers={**self._headers, **extra}, timeout=timeout, **kw
                )
            except httpx.TransportError as exc:
                delay = retry_delay(self.retry, attempt, None, deadline)
                if delay is None:
                    raise unreachable(self.base_url, exc, self.retry, attempt, deadline) from exc
                await asyncio.sleep(delay)
            else:
                if response.status_code in answers:
                    return response
                delay = retry_delay(self.retry, attempt, response, deadline)
                if delay is None:
                    return check(response)
                await asyncio.sleep(delay)
            attempt += 1

    async def submit(
        self,
        scene: SceneSpec | dict | str | Path,
        *,
        base_dir: str | Path | None = None,
        idempotency_key: str | None = None,
    ) -> AsyncJob:
        doc = scene_document(scene, base_dir)
        key = idempotency_key or uuid.uuid4().hex
        try:
            response = await self._request("POST", f"{API}/jobs", json=doc, headers={"Idempotency-Key": key})
        except ConnectionFailed as exc:
            raise submission_lost(exc, key) from exc
        return AsyncJob(self, JobPublic.model_validate(response.json()))

    async def run(self, scene, *, progress: bool = True, timeout: float | None = None, **kw) -> Result:
        job = await self.submit(scene, **kw)
        await job.wait(progress=progress, timeout=timeout)
        return await job.result()

    async def job(self, job_id: str) -> AsyncJob:
        return AsyncJob(self, JobPublic.model_validate((await self._request("GET", job_path(job_id))).json()))

    async def jobs(self, status: str | list[str] | None = None, page_size: int = 100) -> AsyncIterator[AsyncJob]:
        params: dict = {"limit": page_size}
        if status:
            params["status"] = [status] if isinstance(status, str) else list(status)
        while True:
            page = JobListPublic.model_validate((await self._request("GET", f"{API}/jobs", params=params)).json())
            for j in page.items:
                yield AsyncJob(self, j)
            if page.next_cursor is None:
                return
            params["cursor"] = page.next_cursor

    async def health(self) -> HealthPublic:
        return HealthPublic.model_validate((await self._request("GET", f"{API}/health", answers=(503,))).json())

    async def version(self) -> VersionPublic:
        return VersionPublic.model_validate((await self._request("GET", f"{API}/version")).json())
