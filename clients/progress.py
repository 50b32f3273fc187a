"""A one-line progress bar of a job on stderr (terminals and notebooks)."""
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
        now = time.monotonic()
        if not force and now - self._last < self.min_interval_s:
            return
        self._last = now
        p = job.progress
        frac = 1.0 if job.status == "succeeded" else min(max(p.fraction, 0.0), 1.0)
        full = int(round(self.width * frac))
        err = f"  rel.err(H0) {p.dc_gain_rel_stderr:.2e}" if p.dc_gain_rel_stderr is not None else ""
        self.stream.write(f"\r[{'#' * full}{'.' * (self.width - full)}] {100 * frac:5.1f}%  {p.paths:>12,d} paths"
                          f"{err}  {job.status:<9s}")
        self.stream.flush()
        self._shown = True

    def close(self) -> None:
        if self._shown:
            self.stream.write("\n")
            self.stream.flush()
            self._shown = False
