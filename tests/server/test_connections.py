"""Issue 11, item 12: slow or lying clients cannot hold connections (raw sockets, 127.0.0.1 only).

A real `owcsim serve` with short limits: headers within 1 s, a body within 1 s, 20 connections.
"""

from __future__ import annotations

import socket
import time

import httpx
import pytest

from .helpers import ServerProcess


@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("conn")
    with ServerProcess(
        tmp / "jobs.sqlite", header_timeout_s=1.0, body_timeout_s=1.0, keep_alive_s=1.0, max_connections=20
    ) as s:
        yield s


def _connect(srv) -> socket.socket:
    return socket.create_connection(("127.0.0.1", srv.port), timeout=10)


def _read_all(sock: socket.socket, limit_s: float = 10.0) -> bytes:
    sock.settimeout(limit_s)
    out = b""
    try:
        while chunk := sock.recv(65536):
            out += chunk
    except (TimeoutError, ConnectionResetError):
        pass
    return out


def test_a_content_length_larger_than_the_body_ends_with_408(srv):
    with _connect(srv) as s:
        s.sendall(
            b"POST /v1/jobs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
            b'Content-Length: 1000\r\n\r\n{"room":'
        )
        t0 = time.monotonic()
        answer = _read_all(s)
        assert answer.startswith(b"HTTP/1.1 408"), answer[:200]
        assert b"body-timeout" in answer and time.monotonic() - t0 < 5


def test_content_length_with_transfer_encoding_is_400(srv):
    with _connect(srv) as s:
        s.sendall(
            b"POST /v1/jobs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: 4\r\n"
            b"Transfer-Encoding: chunked\r\n\r\n0\r\n\r\n"
        )
        answer = _read_all(s, 5)
    assert answer.startswith(b"HTTP/1.1 400"), answer[:200]


def test_slow_headers_and_idle_connections_are_closed(srv):
    socks = [_connect(srv) for _ in range(30)]
    try:
        for i, s in enumerate(socks):  # slowloris: a request head that never ends
            s.sendall(b"GET /v1/health HTTP/1.1\r\nHost: x\r\n" if i % 2 else b"GET /v1/hea")
        t0 = time.monotonic()
        closed = [_read_all(s, 5) for s in socks]
        assert time.monotonic() - t0 < 6
        assert all(not c or c.startswith(b"HTTP/1.1 503") for c in closed), [c[:40] for c in closed if c]
    finally:
        for s in socks:
            s.close()
    # and a normal request is served at once afterwards
    assert httpx.get(f"{srv.url}/v1/health", timeout=5).status_code == 200


def test_connections_beyond_the_limit_get_503(srv):
    socks = [_connect(srv) for _ in range(25)]
    try:
        time.sleep(0.3)
        r = httpx.get(f"{srv.url}/v1/health", timeout=5)
        assert r.status_code == 503
    finally:
        for s in socks:
            s.close()
    deadline = time.monotonic() + 5
    while httpx.get(f"{srv.url}/v1/health", timeout=5).status_code != 200:
        assert time.monotonic() < deadline
        time.sleep(0.1)


def test_an_oversized_request_head_is_refused(srv):
    with _connect(srv) as s:
        s.sendall(b"GET /v1/health HTTP/1.1\r\nHost: x\r\nX-Big: " + b"a" * 100_000)  # not ended yet
        time.sleep(0.3)
        try:
            s.sendall(b"\r\n\r\n")
        except OSError:
            pass
        answer = _read_all(s, 5)
    assert answer.startswith(b"HTTP/1.1 4") or answer == b"", answer[:200]
