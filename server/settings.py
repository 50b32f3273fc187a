"""Settings of the HTTP service, read from `OWCSIM_*` environment variables (or given in code).

Every limit has a default that suits one machine; the README lists them all.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="OWCSIM_", extra="ignore", frozen=True)

    db: Path = Field(Path("owcsim-jobs.sqlite"), description="the SQLite job store (one file, created if missing)")
    max_concurrent_jobs: int = Field(2, ge=1, le=256, description="jobs running at once (one process each)")
    workers_per_job: int = Field(1, ge=1, le=256, description="engine worker processes per job")
    max_queued_jobs: int = Field(1000, ge=1, description="queued jobs; a submission beyond this gets 429")
    retry_after_s: int = Field(5, ge=1, description="Retry-After [s] sent with 429 when the queue is full")
    max_body_bytes: int = Field(32 * 2**20, ge=1024, description="largest request body [bytes]")
    max_triangles: int = Field(1_000_000, ge=12, description="most triangles in a scene")
    max_receivers: int = Field(
        100_000, ge=1, description="most receivers in a scene, grids, orientation samples and photodiodes included"
    )
    max_paths_per_job: int = Field(10**9, ge=1, description="most paths of a fixed-budget job, all sources")
    max_wall_time_s: float = Field(3600.0, gt=0, description="longest run of one job [s]")
    api_keys: str = Field("", description="comma-separated bearer tokens; empty (and no file) = no auth")
    api_keys_file: Path | None = Field(None, description="file with one bearer token per line (# comments)")
    crash_retries: int = Field(1, ge=0, le=10, description="times a job whose worker process died is requeued")
    cancel_grace_s: float = Field(5.0, gt=0, description="a stopped job's worker still alive after this is killed")
    stall_timeout_s: float = Field(
        900.0,
        ge=0,
        description="a running job's worker that writes no progress for "
        "this long is killed and the job failed [s] (0: never)",
    )
    progress_interval_s: float = Field(0.5, gt=0, description="least time between progress writes of a job [s]")
    max_queued_per_key: int = Field(
        200,
        ge=1,
        description="queued jobs of one API key (one owner without keys); "
        "beyond this that key gets 429, the others are not affected",
    )
    max_attempts: int = Field(
        5, ge=1, le=100, description="starts of a job (restarts and crash retries) before it is failed"
    )
    memory_budget_bytes: int = Field(
        default_factory=lambda: _default_memory_budget(),
        ge=2**26,
        description="memory of all running jobs together [bytes] (estimated from "
        "their settings); default 3/4 of the machine's RAM",
    )
    max_job_memory_bytes: int | None = Field(
        None,
        ge=2**26,
        description="memory estimate of one job [bytes]; more is refused at submission (default: memory_budget_bytes)",
    )
    worker_memory_headroom_bytes: int = Field(
        1 << 30,
        ge=0,
        description="address space a worker may map beyond "
        "its job's estimate (thread stacks, allocator arenas) [bytes]",
    )
    preflight_memory_bytes: int = Field(
        2 << 30, ge=2**26, description="memory of one submission's pre-flight (mesh decoding, scene build) [bytes]"
    )
    preflight_timeout_s: float = Field(60.0, gt=0, description="longest pre-flight of one submission [s]")
    preflight_concurrency: int = Field(
        2, ge=1, le=64, description="pre-flights at once (one process each); submissions beyond wait"
    )
    max_text_chars: int = Field(
        256, ge=16, le=65536, description="longest text field or id of a document (mesh data excepted) [characters]"
    )
    header_timeout_s: float = Field(10.0, gt=0, description="time a client has to send a request's headers [s]")
    body_timeout_s: float = Field(30.0, gt=0, description="time a client has to send a request's body [s]")
    keep_alive_s: float = Field(5.0, gt=0, description="idle keep-alive connections are closed after this [s]")
    max_connections: int = Field(200, ge=1, description="open connections; a request beyond gets 503")
    max_transmitters: int = Field(
        10_000, ge=1, le=10_000, description="most transmitters in a scene (at most the schema's MAX_TRANSMITTERS)"
    )
    inprocess_body_bytes: int = Field(
        256 << 10,
        ge=0,
        description="largest body validated and pre-flighted in the server's process [bytes]; a larger one is "
        "parsed, validated and pre-flighted in a pre-flight process (preflight_memory_bytes, preflight_timeout_s)",
    )
    scheduler: str | None = Field(
        None,
        description="Dask scheduler address (tcp://host:8786): jobs run their "
        "batches on its cluster instead of workers_per_job local processes",
    )
    max_connections_per_client: int = Field(
        50,
        ge=0,
        description="open connections from one client address (the TCP peer's: behind a reverse proxy, the "
        "proxy's); a connection beyond gets 503 with Retry-After and is closed (0: no limit)",
    )
    body_memory_bytes: int | None = Field(
        None,
        ge=1024,
        description="request bodies held in memory at once, all submissions together [bytes]; a submission "
        "whose body would pass it gets 503 with Retry-After (default 4 x max_body_bytes)",
    )

    @field_validator("scheduler", mode="after")
    @classmethod
    def _scheduler(cls, v: str | None) -> str | None:
        if v is None or not v.strip():
            return None
        v = v.strip()
        if "://" not in v:
            raise ValueError(f"a Dask scheduler address looks like tcp://host:8786, not {v!r}")
        try:
            import distributed  # noqa: F401
        except ImportError:
            raise ValueError("a Dask scheduler needs the cluster extra: pip install 'owcsim[cluster]'") from None
        return v

    @field_validator("db", mode="after")
    @classmethod
    def _absolute(cls, v: Path) -> Path:
        try:
            return v.expanduser().resolve()
        except (RuntimeError, OSError) as exc:  # a loop of symbolic links (RuntimeError before Python 3.13)
            raise ValueError(f"{str(v)!r} cannot be resolved: {exc} (a loop of symbolic links?)") from None

    @property
    def body_memory_cap(self) -> int:
        """Request bodies held in memory at once [bytes]: never less than one body of max_body_bytes."""
        return max(self.body_memory_bytes or 4 * self.max_body_bytes, self.max_body_bytes)

    @property
    def job_memory_cap(self) -> int:
        """Largest memory estimate of one job [bytes]."""
        cap = self.max_job_memory_bytes or self.memory_budget_bytes
        return min(cap, self.memory_budget_bytes)

    def key_owners(self) -> dict[str, str]:
        """{sha256 of a token: owner id}. Empty when auth is off. Tokens themselves are not kept."""
        tokens = [t.strip() for t in self.api_keys.split(",")]
        if self.api_keys_file is not None:
            try:
                lines = self.api_keys_file.read_text().splitlines()
            except OSError as exc:
                raise ValueError(f"api_keys_file {str(self.api_keys_file)!r}: {exc.strerror}") from None
            from_file = [ln.strip() for ln in lines if ln.strip() and not ln.strip().startswith("#")]
            if not from_file:  # a key file that turns nothing on would leave the server open, silently
                raise ValueError(f"api_keys_file {str(self.api_keys_file)!r} holds no key (one token per line)")
            tokens += from_file
        out = {}
        for t in tokens:
            if t:
                digest = hashlib.sha256(t.encode()).hexdigest()
                out[digest] = digest[:16]
        return out


def _default_memory_budget() -> int:
    """3/4 of the memory this server may use [bytes]: the machine's, or its container's (cgroup) limit
    if lower (8 GiB if neither is known)."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        total = 8 << 30
    for limit_file in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(limit_file).read_text().strip()
        except OSError:
            continue
        if text.isdigit():
            total = min(total, int(text))
        break
    return int(0.75 * total)
