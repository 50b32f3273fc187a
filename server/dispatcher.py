"""The dispatcher: one thread that starts queued jobs, fairly between owners, each in its own worker process.

At most `max_concurrent_jobs` workers run at once. Worker processes come from a
forkserver whose state is clean (it never builds an Embree scene), so nothing with
threads is ever forked. The dispatcher also watches its workers:

- a worker that exits without recording an outcome (killed, crashed) is requeued once
  (`crash_retries`) and then fails the job with the exit code or signal as the reason;
- a worker asked to stop (cancel) that is still alive `cancel_grace_s` later is killed,
  and so is one past the wall-time limit plus that grace, and one that has written no
  progress for `stall_timeout_s` (hung: it would keep its slot until the wall-time limit);
- on start, jobs left running by a previous server process are requeued; on stop,
  running jobs are requeued and their workers stopped (they start afresh next time:
  the same seed gives the same result); a job started `max_attempts` times is failed;
- jobs are admitted against the server's memory budget: the next job starts only if its
  memory estimate fits in what the running jobs leave (it waits otherwise; smaller jobs
  behind it do not overtake it); each worker's address space is capped from its estimate;
- a store error (disk full, a lock held too long) is logged at most once a minute and
  retried with a growing pause (no busy loop: a dead worker whose run cannot be settled yet is
  not waited on again, its run is settled on a later pass); `state()` tells health about it;
- every pass also checks that the store file is still the one the server locked (`JobStore.check`):
  a store replaced or overwritten while the server runs makes health 503 with the reason.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import signal
import threading
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait

from .settings import Settings
from .store import JobStore, StoreError, is_disk_full
from .worker import WorkerLimits, run_job

log = logging.getLogger("owcsim.server")

TICK_S = 0.2

#: Health says 503 "disk full" when the store's file system has less than this left [bytes].
MIN_FREE_BYTES = 1 << 20


@dataclass
class _Run:
    process: mp.process.BaseProcess
    token: int
    started: float
    lifeline: Connection  # write end of a pipe the worker watches: closed (or the server gone) = stop
    memory_bytes: int  # the job's memory estimate [B]
    stop_seen: float | None = None  # when the dispatcher first saw that this run should end
    kill_reason: str | None = None
    progress: float = -1.0  # the last progress (elapsed_s) seen, and when it changed
    progress_seen: float = 0.0
    exited: bool = False  # joined: its sentinel is not waited on any more (settle may wait for the store)

    def end(self) -> None:
        self.lifeline.close()
        self.process.close()


def describe_exit(code: int | None, memory_bytes: int = 0) -> str:
    if code is not None and code < 0:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = f"signal {-code}"
        hint = " (e.g. out of memory)" if -code == signal.SIGKILL else ""
        if memory_bytes and -code in (signal.SIGKILL, signal.SIGABRT, signal.SIGSEGV):
            hint = (
                f" (e.g. out of memory: its memory budget was {memory_bytes / 2**30:.3g} GB, estimated "
                "from its settings)"
            )
        return f"the worker process was killed by {name}{hint}"
    if code == 0:
        return "the worker process ended without recording a result"
    return f"the worker process exited with status {code} (the server log has the details)"


def start_forkserver() -> None:
    """Start the forkserver (once per server process) with the engine imported in it: workers and
    pre-flights start from it."""
    from multiprocessing import forkserver

    # "__main__" too: each child would import the main module again otherwise (0.1-0.3 s per job and
    # per pre-flight); a script that builds the app keeps its top level under `if __name__ == "__main__":`.
    mp.get_context("forkserver").set_forkserver_preload(
        [
            "__main__",
            "owcsim.server.worker",
            "owcsim.server.preflight",
            "owcsim.engine.run.simulate",
            "owcsim.engine.run.budget",
        ]
    )
    forkserver.ensure_running()
    warm = mp.get_context("forkserver").Process(target=_noop, name="owcsim-warm-up")
    warm.start()  # returns once the forkserver has imported the engine: the first job does not wait for it
    warm.join()
    warm.close()


def _noop() -> None:
    pass


class Dispatcher:
    def __init__(self, store: JobStore, settings: Settings):
        self.store, self.settings = store, settings
        self.limits = WorkerLimits(
            workers=settings.workers_per_job,
            max_wall_time_s=settings.max_wall_time_s,
            progress_interval_s=settings.progress_interval_s,
            scheduler=settings.scheduler,
            memory_headroom_bytes=settings.worker_memory_headroom_bytes,
        )
        self._ctx = mp.get_context("forkserver")
        self._runs: dict[str, _Run] = {}
        self._wake_w: int | None  # None once stopped (both ends closed)
        self._wake_r, self._wake_w = os.pipe()  # wake() writes a byte: the loop looks again at once
        os.set_blocking(self._wake_w, False)
        self._wake_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._error: str | None = None  # the store error of the last pass, if any
        self._error_logged = 0.0
        self._counts: dict[str, int] = {}
        self._counts_at = 0.0  # time.monotonic() of the last pass that read the store

    def state(self) -> tuple[dict[str, int], float, str | None]:
        """(job counts by status, seconds since the loop last read them, store error or None): for health,
        without touching the store."""
        age = time.monotonic() - self._counts_at if self._counts_at else float("inf")
        return dict(self._counts), age, self._error

    @property
    def memory_in_use(self) -> int:
        """Memory estimates of the running jobs [B]."""
        return sum(run.memory_bytes for run in list(self._runs.values()))

    @property
    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def running(self) -> dict[str, int]:
        """{job id: worker pid} of the workers this dispatcher runs now."""
        return {job_id: run.process.pid for job_id, run in list(self._runs.items()) if run.process.pid is not None}

    def start(self) -> None:
        taken = self.store.take_back_running(
            "requeued: the server restarted while the job was running", self.settings.max_attempts
        )
        if taken:
            log.warning("requeued %d job(s) left running by the previous server process", len(taken))
        start_forkserver()  # pay the engine's imports now, not with the first job
        # the first read before the loop runs: health answers from it as soon as the app has started (it
        # said 503 "has not read the store" to a probe that came before the thread's first pass)
        self._counts, self._counts_at = self.store.counts(), time.monotonic()
        self._thread = threading.Thread(target=self._loop, name="owcsim-dispatcher", daemon=True)
        self._thread.start()

    def wake(self) -> None:
        with self._wake_lock:
            if self._wake_w is None:  # stopped
                return
            try:
                os.write(self._wake_w, b"!")
            except BlockingIOError:  # full of wake-ups already
                pass

    def stop(self) -> None:
        """Stop starting jobs; requeue the running ones and end their workers."""
        self._stop.set()
        self.wake()
        if self._thread is not None:
            self._thread.join()
        with self._wake_lock:
            if self._wake_w is not None:
                os.close(self._wake_r)
                os.close(self._wake_w)
                self._wake_w = None
        if not self._runs:
            return
        try:
            self.store.take_back_running(
                "requeued: the server stopped while the job was running", self.settings.max_attempts
            )
        except Exception as exc:  # disk full, store replaced: the workers are stopped all the same; the next
            log.error("dispatcher: could not requeue the running jobs on stop: %s", exc)  # start requeues them
        for run in self._runs.values():
            run.lifeline.close()
        deadline = time.monotonic() + self.settings.cancel_grace_s
        for run in self._runs.values():
            run.process.join(max(0.0, deadline - time.monotonic()))
            if run.process.is_alive():
                run.process.kill()
                run.process.join()
            run.end()
        log.info("stopped %d running job(s); they are queued again", len(self._runs))
        self._runs.clear()

    def _loop(self) -> None:
        """Look after the workers and the queue on every wake-up, worker exit, or tick."""
        pause = TICK_S
        while not self._stop.is_set():
            try:
                self.store.check()
                self._reap()
                self._fill()
                self._counts, self._counts_at = self.store.counts(), time.monotonic()
                low = self._disk_low()  # workers waiting to store an outcome write nothing the loop would see
                if self._error is not None and low is None:
                    log.warning("dispatcher: the job store works again")
                if low is not None and self._error is None:
                    log.error("dispatcher: %s", low)
                self._error, pause = low, TICK_S
            except Exception as exc:  # e.g. disk full, the store busy for too long: log, back off
                self._error = ("disk full" if is_disk_full(exc) else "store error") + f": {exc}"
                now = time.monotonic()
                if now - self._error_logged > 60.0:
                    self._error_logged = now
                    log.error(
                        "dispatcher: %s (retrying every few seconds; logged once a minute)",
                        self._error,
                        exc_info=not (is_disk_full(exc) or isinstance(exc, StoreError)),
                    )
                pause = min(5.0, pause * 2)
            sentinels = [run.process.sentinel for run in self._runs.values() if not run.exited]
            ready = wait(sentinels + [self._wake_r], pause)
            if self._wake_r in ready:
                os.read(self._wake_r, 4096)

    def _disk_low(self) -> str | None:
        """A reason ("disk full: ...") when the store's file system has less than MIN_FREE_BYTES left, else None."""
        try:
            st = os.statvfs(self.store.path.parent)
        except OSError:
            return None
        free = st.f_bavail * st.f_frsize
        if free >= MIN_FREE_BYTES:
            return None
        return f"disk full: {free / 2**20:.2f} MiB free on the job store's file system (jobs wait for space)"

    def _fill(self) -> None:
        cap = self.settings.job_memory_cap
        while len(self._runs) < self.settings.max_concurrent_jobs and not self._stop.is_set():
            head = self.store.next_queued()
            if head is not None and head[1] > cap:  # e.g. the budget was lowered since it was accepted
                self.store.fail_queued(
                    head[0],
                    f"its memory estimate of {head[1] / 2**30:.3g} GB is more than this "
                    f"server's limit of {cap / 2**30:.3g} GB per job (setting max_job_memory_bytes)",
                )
                continue
            claimed = self.store.claim_next(free_memory=self.settings.memory_budget_bytes - self.memory_in_use)
            if claimed is None:
                return
            job_id, token = claimed
            row = self.store.get(job_id)
            memory = row.memory_bytes if row is not None else 0
            lifeline_r, lifeline_w = self._ctx.Pipe(duplex=False)
            process = self._ctx.Process(
                target=run_job,
                name=f"owcsim-job-{job_id[:8]}",
                args=(str(self.store.path), job_id, token, self.limits, lifeline_r, memory),
            )
            try:
                process.start()
            except Exception as exc:
                log.exception("could not start a worker for job %s", job_id)
                lifeline_w.close()
                self.store.settle(job_id, token, f"could not start a worker process ({exc})", retries=0)
                continue
            finally:
                lifeline_r.close()
            # watched before the next write: if that write fails (disk full), the worker is not lost
            self._runs[job_id] = _Run(process, token, time.monotonic(), lifeline_w, memory)
            self.store.set_worker_pid(job_id, token, process.pid)

    def _reap(self) -> None:
        if not self._runs:
            return
        flags = self.store.running_flags()
        now, grace = time.monotonic(), self.settings.cancel_grace_s
        for job_id, run in list(self._runs.items()):
            if run.exited or not run.process.is_alive():
                if not run.exited:
                    run.process.join()
                    run.exited = True  # a settle that fails (disk full) is retried after the pause, not at once
                reason = run.kill_reason or describe_exit(run.process.exitcode, run.memory_bytes)
                status = self.store.settle(
                    job_id, run.token, reason, retries=self.settings.crash_retries, retry=run.kill_reason is None
                )
                if status is not None:
                    log.warning("job %s: %s; the job is now %s", job_id, reason, status)
                run.end()
                del self._runs[job_id]
                continue
            token, cancel, progress = flags.get(job_id, (None, False, 0.0))
            if progress != run.progress or not run.progress_seen:
                run.progress, run.progress_seen = progress, now
            if run.stop_seen is None and (token != run.token or cancel):
                run.stop_seen = now  # cancelled, or finished and still exiting
            if run.stop_seen is not None and now - run.stop_seen > grace:
                run.kill_reason = run.kill_reason or "the worker did not stop in time and was killed"
                run.process.kill()
            elif self.settings.stall_timeout_s and now - run.progress_seen > self.settings.stall_timeout_s:
                run.kill_reason = (
                    f"the worker wrote no progress for {self.settings.stall_timeout_s:g} s and was "
                    "killed (setting stall_timeout_s)"
                )
                run.process.kill()
            elif now - run.started > self.settings.max_wall_time_s + grace:
                run.kill_reason = (
                    f"killed at the server's wall-time limit of {self.settings.max_wall_time_s:g} s "
                    "(the worker did not stop by itself)"
                )
                run.process.kill()
