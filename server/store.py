"""The job store: one SQLite file (WAL mode) holding jobs, their scene documents and results.

Every process and thread opens its own connection: the server's request threads, its
dispatcher, and each job's worker process. Writes that race (a worker finishing while
the dispatcher settles it, a restart requeueing a job) are decided by the job's
`run_token`, which grows each time the job is started or taken back: a write that
carries an old token changes nothing. Documents are stored zlib-compressed.
"""
from __future__ import annotations

import json
import sqlite3
import threading
import time
import uuid
import zlib
from dataclasses import dataclass, field
from pathlib import Path

SCHEMA_VERSION = 1

_SCHEMA = """
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

_COLUMNS = ("seq, id, owner, name, status, created_at, started_at, finished_at, fraction, paths, batches, "
            "rel_stderr, elapsed_s, cancel_requested, attempts, crashes, run_token, worker_pid, error, warnings, "
            "has_result, idempotency_key, request_hash")


class QueueFull(Exception):
    """The queue holds `max_queued_jobs` jobs already."""


class IdempotencyConflict(Exception):
    """An Idempotency-Key was used before with a different request."""

    def __init__(self, job_id: str):
        super().__init__(job_id)
        self.job_id = job_id


@dataclass
class JobRow:
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

    @classmethod
    def from_db(cls, r: tuple) -> "JobRow":
        vals = list(r)
        vals[13] = bool(vals[13])
        vals[19] = json.loads(vals[19])
        vals[20] = bool(vals[20])
        return cls(*vals)


def _pack(text: str | bytes) -> bytes:
    return zlib.compress(text.encode() if isinstance(text, str) else text, 6)


class JobStore:
    """Jobs in one SQLite file. Safe to share between threads (one connection per thread)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._local = threading.local()
        self._all: list[sqlite3.Connection] = []
        self._lock = threading.Lock()
        con = self._con()
        con.execute("PRAGMA journal_mode=WAL")
        if con.execute("PRAGMA user_version").fetchone()[0] == 0:
            con.executescript(_SCHEMA)
            con.execute(f"PRAGMA user_version={SCHEMA_VERSION}")

    def _con(self) -> sqlite3.Connection:
        con = getattr(self._local, "con", None)
        if con is None:
            con = sqlite3.connect(self.path, timeout=30.0, isolation_level=None, check_same_thread=False)
            con.execute("PRAGMA synchronous=FULL")
            con.execute("PRAGMA busy_timeout=30000")
            self._local.con = con
            with self._lock:
                self._all.append(con)
        return con

    def close(self) -> None:
        with self._lock:
            for con in self._all:
                con.close()
            self._all.clear()
        self._local = threading.local()

    def _tx(self):
        return _Transaction(self._con())

    # -- submission -------------------------------------------------------------------------

    def submit(self, *, owner: str, scene_json: str, name: str | None, request_hash: str,
               idempotency_key: str | None, max_queued: int) -> tuple[JobRow, bool]:
        """Queue a job; returns (job, created). With a known Idempotency-Key: the first job, not created."""
        packed = _pack(scene_json)
        with self._tx() as con:
            if idempotency_key is not None:
                first = self._idempotent(con, owner, idempotency_key, request_hash)
                if first is not None:
                    return first, False
            queued = con.execute("SELECT COUNT(*) FROM jobs WHERE status = 'queued'").fetchone()[0]
            if queued >= max_queued:
                raise QueueFull()
            job_id = uuid.uuid4().hex
            con.execute("INSERT INTO jobs (id, owner, idempotency_key, request_hash, name, status, created_at) "
                        "VALUES (?, ?, ?, ?, ?, 'queued', ?)",
                        (job_id, owner, idempotency_key, request_hash, name, time.time()))
            con.execute("INSERT INTO job_documents (job_id, scene) VALUES (?, ?)", (job_id, packed))
            row = con.execute(f"SELECT {_COLUMNS} FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return JobRow.from_db(row), True

    @staticmethod
    def _idempotent(con, owner: str, key: str, request_hash: str) -> JobRow | None:
        row = con.execute(f"SELECT {_COLUMNS} FROM jobs WHERE owner = ? AND idempotency_key = ?",
                          (owner, key)).fetchone()
        if row is None:
            return None
        job = JobRow.from_db(row)
        if job.request_hash != request_hash:
            raise IdempotencyConflict(job.id)
        return job

    def find_idempotent(self, owner: str, key: str, request_hash: str) -> JobRow | None:
        """The job first submitted with this owner's Idempotency-Key, or None; IdempotencyConflict
        if it was submitted with another document."""
        return self._idempotent(self._con(), owner, key, request_hash)

    # -- reading ----------------------------------------------------------------------------

    def get(self, job_id: str, owner: str | None = None) -> JobRow | None:
        """The job, or None if it does not exist or (with `owner`) belongs to someone else."""
        sql, args = f"SELECT {_COLUMNS} FROM jobs WHERE id = ?", [job_id]
        if owner is not None:
            sql, args = sql + " AND owner = ?", args + [owner]
        row = self._con().execute(sql, args).fetchone()
        return JobRow.from_db(row) if row else None

    def list(self, owner: str | None, statuses: list[str] | None, limit: int,
             before_seq: int | None) -> tuple[list[JobRow], int | None]:
        """Newest first; returns (page, seq to pass as `before_seq` for the next page or None)."""
        where, args = [], []
        if owner is not None:
            where.append("owner = ?")
            args.append(owner)
        if statuses:
            where.append(f"status IN ({','.join('?' * len(statuses))})")
            args += statuses
        if before_seq is not None:
            where.append("seq < ?")
            args.append(before_seq)
        sql = f"SELECT {_COLUMNS} FROM jobs" + (" WHERE " + " AND ".join(where) if where else "")
        rows = self._con().execute(sql + " ORDER BY seq DESC LIMIT ?", args + [limit + 1]).fetchall()
        jobs = [JobRow.from_db(r) for r in rows[:limit]]
        return jobs, (jobs[-1].seq if len(rows) > limit else None)

    def counts(self) -> dict[str, int]:
        rows = self._con().execute("SELECT status, COUNT(*) FROM jobs GROUP BY status").fetchall()
        return dict(rows)

    def scene_json(self, job_id: str) -> str:
        row = self._con().execute("SELECT scene FROM job_documents WHERE job_id = ?", (job_id,)).fetchone()
        return zlib.decompress(row[0]).decode()

    def result_json(self, job_id: str) -> bytes | None:
        row = self._con().execute("SELECT result FROM job_documents WHERE job_id = ?", (job_id,)).fetchone()
        return zlib.decompress(row[0]) if row and row[0] is not None else None

    # -- the dispatcher ---------------------------------------------------------------------

    def claim_next(self) -> tuple[str, int] | None:
        """Mark the oldest queued job running; returns (job id, its new run token)."""
        with self._tx() as con:
            row = con.execute("SELECT id FROM jobs WHERE status = 'queued' ORDER BY seq LIMIT 1").fetchone()
            if row is None:
                return None
            con.execute("UPDATE jobs SET status = 'running', started_at = ?, run_token = run_token + 1, "
                        "attempts = attempts + 1, fraction = 0, paths = 0, batches = 0, rel_stderr = NULL, "
                        "elapsed_s = 0, worker_pid = NULL WHERE id = ?", (time.time(), row[0]))
            token = con.execute("SELECT run_token FROM jobs WHERE id = ?", (row[0],)).fetchone()[0]
        return row[0], token

    def set_worker_pid(self, job_id: str, token: int, pid: int | None) -> None:
        self._con().execute("UPDATE jobs SET worker_pid = ? WHERE id = ? AND run_token = ?", (pid, job_id, token))

    def running_flags(self) -> dict[str, tuple[int, bool]]:
        """{job id: (run token, cancel requested)} of running jobs."""
        rows = self._con().execute("SELECT id, run_token, cancel_requested FROM jobs WHERE status = 'running'")
        return {r[0]: (r[1], bool(r[2])) for r in rows.fetchall()}

    def take_back_running(self, note: str) -> list[str]:
        """Requeue every running job (server start or stop); a job whose cancel was asked is cancelled."""
        now = time.time()
        with self._tx() as con:
            ids = [r[0] for r in con.execute("SELECT id FROM jobs WHERE status = 'running'").fetchall()]
            con.execute("UPDATE jobs SET status = 'cancelled', finished_at = ?, run_token = run_token + 1 "
                        "WHERE status = 'running' AND cancel_requested = 1", (now,))
            con.execute("UPDATE jobs SET status = 'queued', run_token = run_token + 1, started_at = NULL, "
                        "fraction = 0, paths = 0, batches = 0, rel_stderr = NULL, elapsed_s = 0, worker_pid = NULL, "
                        "error = ? WHERE status = 'running'", (note,))
        return ids

    def settle(self, job_id: str, token: int, reason: str, *, retries: int, retry: bool = True) -> str | None:
        """A worker exited without recording an outcome: cancel, requeue (crash retry) or fail the job.

        Returns the new status, or None when the run had already been settled.
        """
        now = time.time()
        with self._tx() as con:
            row = con.execute("SELECT status, run_token, cancel_requested, crashes FROM jobs WHERE id = ?",
                              (job_id,)).fetchone()
            if row is None or row[0] != "running" or row[1] != token:
                return None
            if row[2]:
                status, sql, args = "cancelled", "status = 'cancelled', finished_at = ?", [now]
            elif retry and row[3] < retries:
                status = "queued"
                sql, args = ("status = 'queued', crashes = crashes + 1, started_at = NULL, worker_pid = NULL, "
                             "error = ?"), [f"retried after a worker failure: {reason}"]
            else:
                status, sql, args = "failed", "status = 'failed', finished_at = ?, error = ?", [now, reason]
            con.execute(f"UPDATE jobs SET {sql}, run_token = run_token + 1 WHERE id = ?", args + [job_id])
        return status

    def request_cancel(self, job_id: str, owner: str | None) -> JobRow | None:
        """Cancel a queued job now; ask a running one to stop. Returns the job as it is afterwards."""
        with self._tx() as con:
            args = (job_id,) if owner is None else (job_id, owner)
            own = "" if owner is None else " AND owner = ?"
            con.execute(f"UPDATE jobs SET status = 'cancelled', finished_at = ?, cancel_requested = 1 "
                        f"WHERE id = ? AND status = 'queued'{own}", (time.time(), *args))
            con.execute(f"UPDATE jobs SET cancel_requested = 1 WHERE id = ? AND status = 'running'{own}", args)
        return self.get(job_id, owner)

    # -- a job's worker ---------------------------------------------------------------------

    def run_state(self, job_id: str, token: int) -> tuple[bool, bool]:
        """(still this run's job, cancel requested)."""
        row = self._con().execute("SELECT status, run_token, cancel_requested FROM jobs WHERE id = ?",
                                  (job_id,)).fetchone()
        mine = row is not None and row[0] == "running" and row[1] == token
        return mine, bool(row and row[2])

    def progress(self, job_id: str, token: int, fraction: float, paths: int, batches: int,
                 rel_stderr: float | None, elapsed_s: float) -> bool:
        """Write progress; False if the job is no longer this run's."""
        cur = self._con().execute(
            "UPDATE jobs SET fraction = ?, paths = ?, batches = ?, rel_stderr = ?, elapsed_s = ? "
            "WHERE id = ? AND run_token = ? AND status = 'running'",
            (min(max(fraction, 0.0), 1.0), paths, batches, rel_stderr, elapsed_s, job_id, token))
        return cur.rowcount == 1

    def finish(self, job_id: str, token: int, status: str, *, result_json: str | None = None,
               error: str | None = None, warnings: list[str] = ()) -> bool:
        """Record a run's outcome; False (nothing written) if the job is no longer this run's."""
        packed = _pack(result_json) if result_json is not None else None
        with self._tx() as con:
            cur = con.execute(
                "UPDATE jobs SET status = ?, finished_at = ?, error = COALESCE(?, error), warnings = ?, has_result = ?, "
                "fraction = CASE WHEN ? = 'succeeded' THEN 1.0 ELSE fraction END "
                "WHERE id = ? AND run_token = ? AND status = 'running'",
                (status, time.time(), error, json.dumps(list(warnings)), packed is not None, status, job_id, token))
            if cur.rowcount != 1:
                return False
            if packed is not None:
                con.execute("UPDATE job_documents SET result = ? WHERE job_id = ?", (packed, job_id))
        return True


class _Transaction:
    """BEGIN IMMEDIATE ... COMMIT (ROLLBACK on error): one writer at a time, across processes."""

    def __init__(self, con: sqlite3.Connection):
        self.con = con

    def __enter__(self) -> sqlite3.Connection:
        self.con.execute("BEGIN IMMEDIATE")
        return self.con

    def __exit__(self, exc_type, exc, tb) -> None:
        self.con.execute("COMMIT" if exc_type is None else "ROLLBACK")
