"""A one-line progress bar on stderr (terminals and notebooks): of a job on a server (`update`), or of a
run in this process (`show`, the command line's bar over the engine's Progress)."""

from __future__ import annotations

import sys
import time

from owcsim.schemas.jobs import JobPublic


class ProgressBar:
    def __init__(self, stream=None, width: int = 30, min_interval_s: float = 0.1):
        self.stream = stream if stream is not None else sys.stderr
        self.width, self.min_interval_s = width, min_interval_s
        self._last = 0.0
        self._shown = False

    def update(self, job: JobPublic, force: bool = False) -> None:
        """The bar of a job as the server reports it."""
        p = job.progress
        fraction = 1.0 if job.status == "succeeded" else p.fraction
        self.show(fraction, p.paths, p.dc_gain_rel_stderr, f"{job.status:<9s}", force=force)

    def show(self, fraction: float, paths: int, rel_stderr: float | None, tail: str, force: bool = False) -> None:
        """Draw `[####....]  25.0%  1,234 paths  rel.err(H0) 1.00e-02  tail`, at most every min_interval_s
        (always when `force` or at the end)."""
        now = time.monotonic()
        if not force and fraction < 1.0 and now - self._last < self.min_interval_s:
            return
        self._last = now
        frac = min(max(fraction, 0.0), 1.0)
        full = int(round(self.width * frac))
        err = f"  rel.err(H0) {rel_stderr:.2e}" if rel_stderr is not None else ""
        self.stream.write(
            f"\r[{'#' * full}{'.' * (self.width - full)}] {100 * frac:5.1f}%  {paths:>12,d} paths{err}  {tail}"
        )
        self.stream.flush()
        self._shown = True

    def close(self) -> None:
        if self._shown:
            self.stream.write("\n")
            self.stream.flush()
            self._shown = False
