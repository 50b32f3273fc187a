"""Helpers of the service tests: small scene documents, an in-process app, a real server process."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import warnings
from pathlib import Path

import httpx

from owcsim.server.app import create_app
from owcsim.server.settings import Settings
from tests.scenes import room_doc

with warnings.catch_warnings():  # starlette asks for httpx2; the client and the tests use httpx
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

ROOT = Path(__file__).resolve().parents[2]


def quick_doc(paths: int = 2000, **simulation) -> dict:
    """A job of a few tens of milliseconds: 5 x 5 x 3 m room, K = 1, 50 bins."""
    sim = {
        "max_reflections": 1,
        "time_bin_s": 1e-9,
        "t_max_s": 5e-8,
        "paths": paths,
        "seed": 1,
        "batch_size": 1024,
        "direction": "backward",
    }
    sim.update(simulation)
    return room_doc(**sim)


def long_doc(paths: int = 200_000_000) -> dict:
    """A job that runs for minutes unless stopped (progress after every batch of 4096 paths)."""
    return quick_doc(paths=paths, batch_size=4096)


def app_client(tmp_path, run_jobs: bool = False, **settings) -> TestClient:
    """An in-process TestClient (use as a context manager: that runs startup and shutdown)."""
    s = Settings(db=tmp_path / "jobs.sqlite", **settings)
    return TestClient(create_app(s, run_jobs=run_jobs), raise_server_exceptions=False)


def wait_for(client, job_id: str, statuses, timeout: float = 30.0, headers=None) -> dict:
    statuses = {statuses} if isinstance(statuses, str) else set(statuses)
    deadline = time.monotonic() + timeout
    while True:
        job = client.get(f"/v1/jobs/{job_id}", headers=headers).json()
        if job["status"] in statuses:
            return job
        assert time.monotonic() < deadline, f"job {job_id} still {job['status']} after {timeout} s: {job}"
        time.sleep(0.05)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ServerProcess:
    """`owcsim serve` on 127.0.0.1 in a child process; settings from OWCSIM_* variables."""

    def __init__(
        self,
        db: Path,
        port: int | None = None,
        log: Path | None = None,
        *,
        root: Path = ROOT,
        python: str = sys.executable,
        address_space_bytes: int | None = None,
        **settings,
    ):
        """`root`, `python`: another checkout and its interpreter (a baseline for benchmarks);
        `address_space_bytes`: soft RLIMIT_AS of the server (inherited by its children)."""
        self.root, self.python, self.address_space_bytes = Path(root), python, address_space_bytes
        self.db, self.port = db, port or free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.log = log or db.with_suffix(".log")
        self.env = {k: v for k, v in os.environ.items() if not k.startswith("OWCSIM_")}  # only what we set
        self.env.update({f"OWCSIM_{k.upper()}": str(v) for k, v in settings.items()})
        self.env["PYTHONPATH"] = str(self.root)
        self.proc: subprocess.Popen | None = None
        self._groups: list[int] = []

    def start(self, timeout: float = 60.0) -> "ServerProcess":
        out = open(self.log, "a")
        self.proc = subprocess.Popen(
            [
                self.python,
                "-m",
                "owcsim",
                "serve",
                "--host",
                "127.0.0.1",
                "--port",
                str(self.port),
                "--db",
                str(self.db),
            ],
            env=self.env,
            stdout=out,
            stderr=subprocess.STDOUT,
            cwd=self.root,
            start_new_session=True,
            preexec_fn=self._cap if self.address_space_bytes else None,
        )
        self._groups.append(self.proc.pid)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            assert self.proc.poll() is None, f"server exited: {self.log.read_text()[-3000:]}"
            try:
                if httpx.get(f"{self.url}/v1/health", timeout=1.0).status_code == 200:
                    return self
            except httpx.TransportError:
                pass
            time.sleep(0.1)
        self.kill()
        raise AssertionError(f"server did not start: {self.log.read_text()[-3000:]}")

    def _cap(self) -> None:
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (self.address_space_bytes, resource.RLIM_INFINITY))

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 30.0) -> int:
        """Send `sig` to the server process only (its workers notice on their own)."""
        if self.proc is None or self.proc.poll() is not None:
            return self.proc.returncode if self.proc else 0
        self.proc.send_signal(sig)
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            return self.kill()

    def kill(self) -> int:
        """Kill the process groups this object started (server, forkserver, workers)."""
        if self.proc is None:
            return 0
        for group in self._groups:
            try:
                os.killpg(group, signal.SIGKILL)
            except ProcessLookupError:
                pass
        return self.proc.wait()

    def __enter__(self) -> "ServerProcess":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
        self.kill()
