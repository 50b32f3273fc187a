"""The job store's tables: the SQL schema and its migrations, a job's row (`JobRow`), the store's errors.

A job's scene document and result are stored zlib-compressed (`pack`); its renders gzip-compressed,
read back CHUNK_BYTES at a time (store.py).
"""

from __future__ import annotations

import errno
import json
import sqlite3
import zlib
from dataclasses import dataclass, field

__all__ = [
    "CHUNK_BYTES",
    "COLUMNS",
    "SCHEMA",
    "SCHEMA_2",
    "SCHEMA_VERSION",
    "IdempotencyConflict",
    "JobRow",
    "QueueFull",
    "StoreError",
    "is_disk_full",
    "pack",
]

SCHEMA_VERSION = 2

SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    id TEXT NOT NULL UNIQUE,
    owner TEXT NOT NULL,
    idempotency_key TEXT,
    request_hash TEXT NOT NULL,
    name TEXT,
    status TEXT NOT NULL,
    created_at REAL NOT NULL,
    started_at REAL,
    finished_at REAL,
    fraction REAL NOT NULL DEFAULT 0,
    paths INTEGER NOT NULL DEFAULT 0,
    batches INTEGER NOT NULL DEFAULT 0,
    rel_stderr REAL,
    elapsed_s REAL NOT NULL DEFAULT 0,
    cancel_requested INTEGER NOT NULL DEFAULT 0,
    attempts INTEGER NOT NULL DEFAULT 0,
    crashes INTEGER NOT NULL DEFAULT 0,
    run_token INTEGER NOT NULL DEFAULT 0,
    worker_pid INTEGER,
    error TEXT,
    warnings TEXT NOT NULL DEFAULT '[]',
    has_result INTEGER NOT NULL DEFAULT 0,
    UNIQUE (owner, idempotency_key)
);
CREATE INDEX IF NOT EXISTS jobs_by_status ON jobs (status, seq);
CREATE INDEX IF NOT EXISTS jobs_by_owner ON jobs (owner, seq);
CREATE TABLE IF NOT EXISTS job_documents (
    job_id TEXT PRIMARY KEY REFERENCES jobs (id),
    scene BLOB NOT NULL,
    result BLOB
);
"""

#: Version 1 -> 2: per-job memory estimate, stored renders, owners' dispatch turns.
SCHEMA_2 = """
ALTER TABLE jobs ADD COLUMN memory_bytes INTEGER NOT NULL DEFAULT 0;
CREATE TABLE IF NOT EXISTS job_renders (
    job_id TEXT NOT NULL REFERENCES jobs (id),
    name TEXT NOT NULL,
    data BLOB NOT NULL,
    PRIMARY KEY (job_id, name)
);
CREATE TABLE IF NOT EXISTS owner_turns (
    owner TEXT PRIMARY KEY,
    last_turn INTEGER NOT NULL
);
"""

#: Bytes read from a stored render at a time.
CHUNK_BYTES = 256 * 1024

COLUMNS = (
    "seq, id, owner, name, status, created_at, started_at, finished_at, fraction, paths, batches, "
    "rel_stderr, elapsed_s, cancel_requested, attempts, crashes, run_token, worker_pid, error, warnings, "
    "has_result, idempotency_key, request_hash, memory_bytes"
)


class QueueFull(Exception):
    """The queue holds `max_queued_jobs` jobs already (`per_owner`: this owner's quota is used up)."""

    def __init__(self, per_owner: bool = False):
        super().__init__("queue full")
        self.per_owner = per_owner


class StoreError(Exception):
    """The job store file cannot be used (damaged, not a database, locked by another server)."""


def is_disk_full(exc: BaseException) -> bool:
    """An SQLite error that means the disk (or the database's size cap) is full."""
    if isinstance(exc, OSError):
        return exc.errno in (errno.ENOSPC, errno.EDQUOT)
    code = getattr(exc, "sqlite_errorcode", None)
    return isinstance(exc, sqlite3.Error) and (code == sqlite3.SQLITE_FULL or "disk is full" in str(exc))


class IdempotencyConflict(Exception):
    """An Idempotency-Key was used before with a different request."""

    def __init__(self, job_id: str):
        super().__init__(job_id)
        self.job_id = job_id


@dataclass
class JobRow:
    """One row of the jobs table, as the routes, the dispatcher and the workers read it (times in s since the epoch)."""

    seq: int
    id: str
    owner: str
    name: str | None
    status: str
    created_at: float
    started_at: float | None
    finished_at: float | None
    fraction: float
    paths: int
    batches: int
    rel_stderr: float | None
    elapsed_s: float
    cancel_requested: bool
    attempts: int
    crashes: int
    run_token: int
    worker_pid: int | None
    error: str | None
    warnings: list[str] = field(default_factory=list)
    has_result: bool = False
    idempotency_key: str | None = None
    request_hash: str = ""
    memory_bytes: int = 0

    @classmethod
    def from_db(cls, r: tuple) -> "JobRow":
        vals = list(r)
        vals[13] = bool(vals[13])
        vals[19] = json.loads(vals[19])
        vals[20] = bool(vals[20])
        return cls(*vals)


def pack(text: str | bytes) -> bytes:
    """A document as stored: zlib level 6."""
    return zlib.compress(text.encode() if isinstance(text, str) else text, 6)


def unpack_chunks(packed: bytes, size: int = 1 << 20):
    """A stored document decompressed piece by piece (at most `size` bytes each): never whole in memory."""
    inflate = zlib.decompressobj()
    while packed:
        out = inflate.decompress(packed, size)
        packed = inflate.unconsumed_tail
        if out:
            yield out
    if tail := inflate.flush():
        yield tail
