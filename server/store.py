"""The job store: one SQLite file (WAL mode) holding jobs, their scene documents and results.

Every process and thread opens its own connection: the server's request threads, its
dispatcher, and each job's worker process. Writes that race (a worker finishing while
the dispatcher settles it, a restart requeueing a job) are decided by the job's
`run_token`, which grows each time the job is started or taken back: a write that
carries an old token changes nothing. Documents are stored zlib-compressed; a job's renders
(result.json, CSV, NPZ, PNG, made once by its worker) gzip-compressed, read back in chunks.

The server process holds an exclusive lock on `<store>.lock` and on the store file itself (its
device and inode: a second server on the same file refuses to start, under any name or hard link),
refuses a folder or an empty file in the store's place, checks the file's integrity at start, and
checkpoints the WAL into the main file when it stops. Files are created 0600. Dispatch is fair
between owners (API keys): the next job is the oldest of the owner with the fewest running jobs, ties broken by whose
turn came longest ago; each owner has its own queue quota.
"""

from __future__ import annotations

import builtins
import contextlib
import fcntl
import json
import logging
import os
import sqlite3
import stat
import threading
import time
import uuid
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path

from .job_rows import (
    CHUNK_BYTES,
    COLUMNS,
    SCHEMA,
    SCHEMA_2,
    SCHEMA_VERSION,
    IdempotencyConflict,
    JobRow,
    QueueFull,
    StoreError,
    is_disk_full,
    pack,
    unpack_chunks,
)
from .sqlite_io import BlobFile, Transaction

log = logging.getLogger("owcsim.server")

#: The first 16 bytes of every SQLite database file.
SQLITE_MAGIC = b"SQLite format 3\x00"

#: What the store raises and returns, for its callers (server routes, dispatcher, worker, command line).
__all__ = ["CHUNK_BYTES", "IdempotencyConflict", "JobRow", "JobStore", "QueueFull", "StoreError", "is_disk_full"]


class JobStore:
    """Jobs in one SQLite file. Safe to share between threads (one connection per thread).

    `server=True` (the server process): take the exclusive lock and check the file's integrity
    first; `close()` then checkpoints the WAL. Workers open the store without either.
    """

    def __init__(self, path: str | Path, *, server: bool = False):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._local = threading.local()
        self._all: list[sqlite3.Connection] = []
        self._lock = threading.Lock()
        self._lock_fd: int | None = None
        self.server = server
        self._store_fd: int | None = None  # the server's own descriptor of the store file (its identity lock)
        self._identity: tuple[int, int] | None = None  # (device, inode) of the file the server locked
        self.broken: str | None = None  # why `check` found the file unusable (every read and write refused)
        created = False
        if server:
            created = self._check_file()
            self._take_lock()
        try:
            if not server:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o600)  # before SQLite: -wal/-shm inherit its mode
                os.close(fd)
            con = self._con()
            if server:
                self._check_integrity(con)
            con.execute("PRAGMA journal_mode=WAL")
            version = con.execute("PRAGMA user_version").fetchone()[0]
            if version == 0:
                con.executescript(SCHEMA)
                con.executescript(SCHEMA_2)
                con.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
            elif version == 1:
                with self._tx() as tx:
                    for stmt in filter(str.strip, SCHEMA_2.split(";")):
                        tx.execute(stmt)
                    tx.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
            elif version > SCHEMA_VERSION:
                raise StoreError(
                    f"job store {str(self.path)!r} was written by a newer owcsim (schema {version}, "
                    f"this one reads up to {SCHEMA_VERSION})"
                )
            if created:
                log.warning("job store %s did not exist: started an empty one", self.path)
        except sqlite3.DatabaseError as exc:
            self.close(checkpoint=False)
            raise StoreError(
                f"job store {str(self.path)!r} cannot be used: {exc} (restore it from a backup, "
                "or move it away to start with an empty store)"
            ) from None
        except BaseException:
            self.close(checkpoint=False)
            raise

    def _take_lock(self) -> None:
        lock_path = self.path.with_name(self.path.name + ".lock")
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise StoreError(
                f"job store {str(self.path)!r} is in use by another owcsim server (lock file "
                f"{str(lock_path)!r}): run one server per store file"
            ) from None
        self._lock_fd = fd
        # the file itself, whatever its name: a hard link (or another path to it) is the same store. flock
        # and SQLite's own fcntl locks do not interact; this descriptor stays open until close()
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o600)  # before SQLite: -wal/-shm inherit its mode
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            os.close(self._lock_fd)
            self._lock_fd = None
            raise StoreError(
                f"job store {str(self.path)!r} is in use by another owcsim server (the same file under "
                "another name, e.g. a hard link): run one server per store file"
            ) from None
        st = os.fstat(fd)
        self._store_fd, self._identity = fd, (st.st_dev, st.st_ino)

    def _check_file(self) -> bool:
        """Before the server opens its store: True if there is none yet (it starts an empty one);
        StoreError for something that is no store (a folder, a device, an empty file)."""
        try:
            st = os.stat(self.path)
        except FileNotFoundError:
            return True
        except OSError as exc:
            raise StoreError(f"job store {str(self.path)!r} cannot be used: {exc.strerror}") from None
        if not stat.S_ISREG(st.st_mode):
            kind = "a folder" if stat.S_ISDIR(st.st_mode) else "not a regular file"
            raise StoreError(
                f"job store {str(self.path)!r} is {kind}: give the path of the store file (setting db), "
                "or move it away to start with an empty store"
            )
        if st.st_size == 0:  # SQLite would start an empty store in it: the jobs it held would be gone silently
            raise StoreError(
                f"job store {str(self.path)!r} is an empty file (0 bytes), not a job store: restore it from a "
                "backup, or delete it to start with an empty store"
            )
        return False

    def check(self) -> None:
        """The server's store is still the file it locked, and still an SQLite file: two system calls, made
        on every pass of the dispatcher. If not, StoreError, and every read and write of this store is refused
        (sqlite3.DatabaseError, answered 503) until the file is back."""
        if self._store_fd is None:
            return
        self.broken = self._whats_wrong()
        if self.broken is not None:
            raise StoreError(self.broken)

    def _whats_wrong(self) -> str | None:
        assert self._store_fd is not None
        where = f"job store {str(self.path)!r}"
        try:
            st = os.stat(self.path)
        except OSError as exc:
            return f"{where} is gone ({exc.strerror}) while the server runs: put it back and restart the server"
        if (st.st_dev, st.st_ino) != self._identity:
            return (
                f"{where} was replaced by another file while the server runs: put the old one back, or restart "
                "the server to use the new one"
            )
        if os.pread(self._store_fd, 16, 0) != SQLITE_MAGIC:
            return (
                f"{where} was overwritten while the server runs (it is no SQLite file any more): restore it "
                "from a backup and restart the server"
            )
        return None

    def _check_integrity(self, con: sqlite3.Connection) -> None:
        rows = [r[0] for r in con.execute("PRAGMA quick_check").fetchall()]
        if rows != ["ok"]:
            raise StoreError(
                f"job store {str(self.path)!r} is damaged (SQLite quick_check: {'; '.join(rows[:3])})"
                ": restore it from a backup, or move it away to start with an empty store"
            )

    def _con(self) -> sqlite3.Connection:
        if self.broken is not None:  # found replaced or overwritten by `check`: no answer from stale pages
            raise sqlite3.DatabaseError(self.broken)
        con = getattr(self._local, "con", None)
        if con is None:
            con = sqlite3.connect(self.path, timeout=30.0, isolation_level=None, check_same_thread=False)
            con.execute("PRAGMA synchronous=FULL")
            con.execute("PRAGMA busy_timeout=30000")
            self._local.con = con
            with self._lock:
                self._all.append(con)
        return con

    def close(self, checkpoint: bool = True) -> None:
        """Close every connection; the server's store first moves the WAL into the main file."""
        with self._lock:
            if checkpoint and self.server and self._all:
                try:
                    self._all[0].execute("PRAGMA wal_checkpoint(TRUNCATE)")
                except sqlite3.Error:
                    pass  # e.g. a worker still reading: SQLite checkpoints at the next open
            for con in self._all:
                con.close()
            self._all.clear()
            if self._lock_fd is not None:
                os.close(self._lock_fd)
                self._lock_fd = None
            if self._store_fd is not None:  # after SQLite's connections: closing it would drop their locks
                os.close(self._store_fd)
                self._store_fd = None
        self._local = threading.local()

    def _tx(self):
        return Transaction(self._con())

    # -- submission -------------------------------------------------------------------------

    def submit(
        self,
        *,
        owner: str,
        scene_json: str,
        name: str | None,
        request_hash: str,
        idempotency_key: str | None,
        max_queued: int,
        max_queued_per_owner: int | None = None,
        memory_bytes: int = 0,
    ) -> tuple[JobRow, bool]:
        """Queue a job; returns (job, created). With a known Idempotency-Key: the first job, not created."""
        packed = pack(scene_json)
        with self._tx() as con:
            if idempotency_key is not None:
                first = self._idempotent(con, owner, idempotency_key, request_hash)
                if first is not None:
                    return first, False
            queued = con.execute("SELECT COUNT(*) FROM jobs WHERE status = 'queued'").fetchone()[0]
            if queued >= max_queued:
                raise QueueFull()
            if max_queued_per_owner is not None:
                mine = con.execute(
                    "SELECT COUNT(*) FROM jobs WHERE status = 'queued' AND owner = ?", (owner,)
                ).fetchone()[0]
                if mine >= max_queued_per_owner:
                    raise QueueFull(per_owner=True)
            job_id = uuid.uuid4().hex
            con.execute(
                "INSERT INTO jobs (id, owner, idempotency_key, request_hash, name, status, created_at, "
                "memory_bytes) VALUES (?, ?, ?, ?, ?, 'queued', ?, ?)",
                (job_id, owner, idempotency_key, request_hash, name, time.time(), memory_bytes),
            )
            con.execute("INSERT INTO job_documents (job_id, scene) VALUES (?, ?)", (job_id, packed))
            row = con.execute(f"SELECT {COLUMNS} FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return JobRow.from_db(row), True

    @staticmethod
    def _idempotent(con, owner: str, key: str, request_hash: str) -> JobRow | None:
        row = con.execute(
            f"SELECT {COLUMNS} FROM jobs WHERE owner = ? AND idempotency_key = ?", (owner, key)
        ).fetchone()
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
        sql, args = f"SELECT {COLUMNS} FROM jobs WHERE id = ?", [job_id]
        if owner is not None:
            sql, args = sql + " AND owner = ?", args + [owner]
        row = self._con().execute(sql, args).fetchone()
        return JobRow.from_db(row) if row else None

    def list(
        self, owner: str | None, statuses: Sequence[str] | None, limit: int, after: str | None
    ) -> tuple[list[JobRow], str | None]:
        """Newest first; returns (page, the id to pass as `after` for the next page or None).

        `after` is the last job id of the previous page: opaque (ids are random) and checked
        against the owner (another owner's id is KeyError, as an unknown one).
        """
        before_seq = None
        if after is not None:
            ref = self.get(after, owner)
            if ref is None:
                raise KeyError(after)
            before_seq = ref.seq
        where: list[str] = []
        args: list[object] = []
        if owner is not None:
            where.append("owner = ?")
            args.append(owner)
        if statuses:
            where.append(f"status IN ({','.join('?' * len(statuses))})")
            args += statuses
        if before_seq is not None:
            where.append("seq < ?")
            args.append(before_seq)
        sql = f"SELECT {COLUMNS} FROM jobs" + (" WHERE " + " AND ".join(where) if where else "")
        rows = self._con().execute(sql + " ORDER BY seq DESC LIMIT ?", args + [limit + 1]).fetchall()
        jobs = [JobRow.from_db(r) for r in rows[:limit]]
        return jobs, (jobs[-1].id if len(rows) > limit else None)

    def counts(self) -> dict[str, int]:
        rows = self._con().execute("SELECT status, COUNT(*) FROM jobs GROUP BY status").fetchall()
        return dict(rows)

    def scene_json(self, job_id: str) -> str:
        row = self._con().execute("SELECT scene FROM job_documents WHERE job_id = ?", (job_id,)).fetchone()
        return zlib.decompress(row[0]).decode()

    def scene_chunks(self, job_id: str):
        """The scene document's bytes in pieces of at most 1 MiB, decompressed as they are sent; None: no job."""
        row = self._con().execute("SELECT scene FROM job_documents WHERE job_id = ?", (job_id,)).fetchone()
        return None if row is None else unpack_chunks(row[0])

    def result_json(self, job_id: str) -> bytes | None:
        """The whole result document (for tests and small results; routes stream `render_chunks`)."""
        row = self._con().execute("SELECT result FROM job_documents WHERE job_id = ?", (job_id,)).fetchone()
        return zlib.decompress(row[0]) if row and row[0] is not None else None

    def render_names(self, job_id: str) -> set[str]:
        rows = self._con().execute("SELECT name FROM job_renders WHERE job_id = ?", (job_id,)).fetchall()
        return {r[0] for r in rows}

    def render_chunks(self, job_id: str, name: str):
        """The stored gzip bytes of a render, in chunks of CHUNK_BYTES (a fresh connection: a generator
        may be read from another thread); None if there is no such render."""
        con = sqlite3.connect(self.path, timeout=30.0, isolation_level=None, check_same_thread=False)
        row = con.execute("SELECT rowid FROM job_renders WHERE job_id = ? AND name = ?", (job_id, name)).fetchone()
        if row is None:
            con.close()
            return None

        def chunks():
            try:
                with con.blobopen("job_renders", "data", row[0], readonly=True) as blob:
                    while chunk := blob.read(CHUNK_BYTES):
                        yield chunk
            finally:
                con.close()

        return chunks()

    def put_renders(self, job_id: str, renders: Mapping[str, Path | bytes]) -> None:
        """Keep renders made after the job ended (a plot; a result stored by an older server)."""
        with self._tx() as con:
            self._write_renders(con, job_id, renders)

    @contextlib.contextmanager
    def open_render(self, job_id: str, name: str):
        """A stored render as a read-only, seekable file (an SQLite blob), e.g. for zipfile."""
        con = sqlite3.connect(self.path, timeout=30.0, isolation_level=None)
        try:
            row = con.execute("SELECT rowid FROM job_renders WHERE job_id = ? AND name = ?", (job_id, name)).fetchone()
            if row is None:
                raise FileNotFoundError(f"job {job_id} has no render {name}")
            with con.blobopen("job_renders", "data", row[0], readonly=True) as blob:
                yield BlobFile(blob)
        finally:
            con.close()

    @staticmethod
    def _write_renders(con, job_id: str, renders: Mapping[str, Path | bytes]) -> None:
        """Keep a job's renders: {name: file (copied in chunks) or bytes}."""
        for name, path in renders.items():
            if isinstance(path, bytes):
                con.execute(
                    "INSERT OR REPLACE INTO job_renders (job_id, name, data) VALUES (?, ?, ?)", (job_id, name, path)
                )
                continue
            size = path.stat().st_size
            con.execute(
                "INSERT OR REPLACE INTO job_renders (job_id, name, data) VALUES (?, ?, zeroblob(?))",
                (job_id, name, size),
            )
            rowid = con.execute(
                "SELECT rowid FROM job_renders WHERE job_id = ? AND name = ?", (job_id, name)
            ).fetchone()[0]
            with con.blobopen("job_renders", "data", rowid) as blob, open(path, "rb") as src:
                while chunk := src.read(CHUNK_BYTES):
                    blob.write(chunk)

    # -- the dispatcher ---------------------------------------------------------------------

    _NEXT = """
        WITH q AS (SELECT owner, MIN(seq) AS first FROM jobs WHERE status = 'queued' GROUP BY owner),
             r AS (SELECT owner, COUNT(*) AS n FROM jobs WHERE status = 'running' GROUP BY owner)
        SELECT j.id, j.memory_bytes FROM q JOIN jobs j ON j.seq = q.first
        LEFT JOIN r ON r.owner = q.owner LEFT JOIN owner_turns t ON t.owner = q.owner
        ORDER BY COALESCE(r.n, 0), COALESCE(t.last_turn, -1), q.first LIMIT 1"""

    def claim_next(self, free_memory: int | None = None) -> tuple[str, int] | None:
        """Mark the next queued job running; returns (job id, its new run token).

        The next job is the oldest of the owner with the fewest running jobs (then: whose turn
        came longest ago). None if nothing is queued, or if that job's memory estimate exceeds
        `free_memory` [B] (it waits for room: smaller jobs do not overtake it).
        """
        with self._tx() as con:
            row = con.execute(self._NEXT).fetchone()
            if row is None or (free_memory is not None and row[1] > free_memory):
                return None
            con.execute(
                "UPDATE jobs SET status = 'running', started_at = ?, run_token = run_token + 1, "
                "attempts = attempts + 1, fraction = 0, paths = 0, batches = 0, rel_stderr = NULL, "
                "elapsed_s = 0, worker_pid = NULL WHERE id = ?",
                (time.time(), row[0]),
            )
            token, owner = con.execute("SELECT run_token, owner FROM jobs WHERE id = ?", (row[0],)).fetchone()
            turn = con.execute("SELECT COALESCE(MAX(last_turn), 0) + 1 FROM owner_turns").fetchone()[0]
            con.execute("INSERT OR REPLACE INTO owner_turns (owner, last_turn) VALUES (?, ?)", (owner, turn))
        return row[0], token

    def next_queued(self) -> tuple[str, int] | None:
        """(id, memory estimate [B]) of the job `claim_next` would start, or None."""
        row = self._con().execute(self._NEXT).fetchone()
        return (row[0], row[1]) if row else None

    def fail_queued(self, job_id: str, reason: str) -> None:
        """Fail a queued job that can never start (e.g. larger than the server's memory budget)."""
        self._con().execute(
            "UPDATE jobs SET status = 'failed', finished_at = ?, error = ?, run_token = run_token + 1 "
            "WHERE id = ? AND status = 'queued'",
            (time.time(), reason, job_id),
        )

    def set_worker_pid(self, job_id: str, token: int, pid: int | None) -> None:
        self._con().execute("UPDATE jobs SET worker_pid = ? WHERE id = ? AND run_token = ?", (pid, job_id, token))

    def running_flags(self) -> dict[str, tuple[int, bool, float]]:
        """{job id: (run token, cancel requested, elapsed_s of its last progress write)} of running jobs."""
        rows = self._con().execute(
            "SELECT id, run_token, cancel_requested, elapsed_s FROM jobs WHERE status = 'running'"
        )
        return {r[0]: (r[1], bool(r[2]), r[3]) for r in rows.fetchall()}

    def take_back_running(self, note: str, max_attempts: int | None = None) -> builtins.list[str]:
        """Requeue every running job (server start or stop); a job whose cancel was asked is cancelled,
        one that has started `max_attempts` times already is failed."""
        now = time.time()
        with self._tx() as con:
            ids = [r[0] for r in con.execute("SELECT id FROM jobs WHERE status = 'running'").fetchall()]
            con.execute(
                "UPDATE jobs SET status = 'cancelled', finished_at = ?, run_token = run_token + 1 "
                "WHERE status = 'running' AND cancel_requested = 1",
                (now,),
            )
            if max_attempts is not None:
                con.execute(
                    "UPDATE jobs SET status = 'failed', finished_at = ?, run_token = run_token + 1, error = ? "
                    "WHERE status = 'running' AND attempts >= ?",
                    (
                        now,
                        f"{note}; it was started {max_attempts} times without finishing (setting max_attempts)",
                        max_attempts,
                    ),
                )
            con.execute(
                "UPDATE jobs SET status = 'queued', run_token = run_token + 1, started_at = NULL, "
                "fraction = 0, paths = 0, batches = 0, rel_stderr = NULL, elapsed_s = 0, worker_pid = NULL, "
                "error = ? WHERE status = 'running'",
                (note,),
            )
        return ids

    def settle(self, job_id: str, token: int, reason: str, *, retries: int, retry: bool = True) -> str | None:
        """A worker exited without recording an outcome: cancel, requeue (crash retry) or fail the job.

        Returns the new status, or None when the run had already been settled.
        """
        now = time.time()
        with self._tx() as con:
            row = con.execute(
                "SELECT status, run_token, cancel_requested, crashes FROM jobs WHERE id = ?", (job_id,)
            ).fetchone()
            if row is None or row[0] != "running" or row[1] != token:
                return None
            args: list[object]
            if row[2]:
                status, sql, args = "cancelled", "status = 'cancelled', finished_at = ?", [now]
            elif retry and row[3] < retries:
                status = "queued"
                sql, args = (
                    ("status = 'queued', crashes = crashes + 1, started_at = NULL, worker_pid = NULL, error = ?"),
                    [f"retried after a worker failure: {reason}"],
                )
            else:
                status, sql, args = "failed", "status = 'failed', finished_at = ?, error = ?", [now, reason]
            con.execute(f"UPDATE jobs SET {sql}, run_token = run_token + 1 WHERE id = ?", args + [job_id])
        return status

    def request_cancel(self, job_id: str, owner: str | None) -> JobRow | None:
        """Cancel a queued job now; ask a running one to stop. Returns the job as it is afterwards."""
        with self._tx() as con:
            args = (job_id,) if owner is None else (job_id, owner)
            own = "" if owner is None else " AND owner = ?"
            con.execute(
                f"UPDATE jobs SET status = 'cancelled', finished_at = ?, cancel_requested = 1 "
                f"WHERE id = ? AND status = 'queued'{own}",
                (time.time(), *args),
            )
            con.execute(f"UPDATE jobs SET cancel_requested = 1 WHERE id = ? AND status = 'running'{own}", args)
        return self.get(job_id, owner)

    def delete(self, job_id: str, owner: str | None, statuses: Sequence[str]) -> bool:
        """Delete the job, its documents and renders if it is in one of `statuses` (and the owner's);
        False if it is not (or not any more, e.g. it started meanwhile)."""
        with self._tx() as con:
            own, args = ("", (job_id,)) if owner is None else (" AND owner = ?", (job_id, owner))
            marks = ",".join("?" * len(statuses))
            found = con.execute(f"SELECT 1 FROM jobs WHERE id = ?{own} AND status IN ({marks})", (*args, *statuses))
            if found.fetchone() is None:
                return False
            con.execute("DELETE FROM job_renders WHERE job_id = ?", (job_id,))
            con.execute("DELETE FROM job_documents WHERE job_id = ?", (job_id,))
            con.execute("DELETE FROM jobs WHERE id = ?", (job_id,))
        return True

    # -- a job's worker ---------------------------------------------------------------------

    def run_state(self, job_id: str, token: int) -> tuple[bool, bool]:
        """(still this run's job, cancel requested)."""
        row = (
            self._con()
            .execute("SELECT status, run_token, cancel_requested FROM jobs WHERE id = ?", (job_id,))
            .fetchone()
        )
        mine = row is not None and row[0] == "running" and row[1] == token
        return mine, bool(row and row[2])

    def progress(
        self,
        job_id: str,
        token: int,
        fraction: float,
        paths: int,
        batches: int,
        rel_stderr: float | None,
        elapsed_s: float,
    ) -> bool:
        """Write progress; False if the job is no longer this run's."""
        cur = self._con().execute(
            "UPDATE jobs SET fraction = ?, paths = ?, batches = ?, rel_stderr = ?, elapsed_s = ? "
            "WHERE id = ? AND run_token = ? AND status = 'running'",
            (min(max(fraction, 0.0), 1.0), paths, batches, rel_stderr, elapsed_s, job_id, token),
        )
        return cur.rowcount == 1

    def finish(
        self,
        job_id: str,
        token: int,
        status: str,
        *,
        result_json: str | None = None,
        error: str | None = None,
        warnings: Sequence[str] = (),
        renders: Mapping[str, Path | bytes] | None = None,
    ) -> bool:
        """Record a run's outcome and its renders ({name: file of gzip bytes}) in one transaction;
        False (nothing written) if the job is no longer this run's."""
        packed = pack(result_json) if result_json is not None else None
        with self._tx() as con:
            cur = con.execute(
                "UPDATE jobs SET status = ?, finished_at = ?, error = COALESCE(?, error), warnings = ?, "
                "has_result = ?, "
                "fraction = CASE WHEN ? = 'succeeded' THEN 1.0 ELSE fraction END "
                "WHERE id = ? AND run_token = ? AND status = 'running'",
                (status, time.time(), error, json.dumps(list(warnings)), packed is not None, status, job_id, token),
            )
            if cur.rowcount != 1:
                return False
            if packed is not None:
                con.execute("UPDATE job_documents SET result = ? WHERE job_id = ?", (packed, job_id))
            if renders:
                self._write_renders(con, job_id, renders)
        return True
