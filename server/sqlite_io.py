"""SQLite helpers of the job store: a write transaction across processes, a blob as a file object."""

from __future__ import annotations

import io
import sqlite3

__all__ = ["BlobFile", "Transaction"]


class BlobFile(io.RawIOBase):
    """An SQLite blob as a binary file object (zipfile wants `seekable()` and friends)."""

    def __init__(self, blob):
        self.blob = blob

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def readinto(self, b) -> int:
        data = self.blob.read(len(b))
        b[: len(data)] = data
        return len(data)

    def seek(self, offset: int, whence: int = 0) -> int:
        self.blob.seek(offset, whence)
        return self.blob.tell()

    def tell(self) -> int:
        return self.blob.tell()


class Transaction:
    """BEGIN IMMEDIATE ... COMMIT (ROLLBACK on error): one writer at a time, across processes."""

    def __init__(self, con: sqlite3.Connection):
        self.con = con

    def __enter__(self) -> sqlite3.Connection:
        self.con.execute("BEGIN IMMEDIATE")
        return self.con

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            try:
                self.con.execute("COMMIT")
            except sqlite3.Error:
                self._rollback()  # e.g. SQLITE_FULL at commit: leave no transaction open
                raise
        else:
            self._rollback()

    def _rollback(self) -> None:
        """Roll back if a transaction is still open (SQLite ends some by itself, e.g. on SQLITE_FULL)."""
        if self.con.in_transaction:
            try:
                self.con.execute("ROLLBACK")
            except sqlite3.Error:
                pass
