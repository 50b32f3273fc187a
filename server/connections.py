"""Limits per connection that uvicorn does not have: connections per client address, size of a request head.

`protocol_class(settings)` is the h11 protocol `owcsim serve` runs (serve.py), on top of the
header deadline of limits.py:

- connections per client address (`max_connections_per_client`, the TCP peer's address: behind
  a reverse proxy, the proxy's): a connection beyond is answered at once with 503, `Retry-After`
  and a problem document, and closed; it does not count towards `max_connections` (uvicorn's cap
  counts every open connection, so one address with many slow connections took it all);
- the request head (request line + headers) is at most MAX_HEAD_BYTES: a longer one is answered
  431 and the connection closed. uvicorn's `h11_max_incomplete_event_size` only bounds a head
  that is still incomplete, so a head of 70-100 kB arriving at once was served.
"""

from __future__ import annotations

import asyncio
import json
from collections import Counter
from typing import ClassVar

import h11

from .limits import HeaderTimeoutH11Protocol
from .problems import URN
from .settings import Settings

#: Largest request head (request line + headers) a client may send [bytes].
MAX_HEAD_BYTES = 64 * 1024

#: A refused connection is closed this long after its answer at the latest [s] (its data is read and
#: dropped meanwhile, so that closing does not reset the connection before the client has read it).
LINGER_S = 1.0


def _problem_bytes(status: int, reason: str, kind: str, detail: str, extra: list[tuple[str, str]]) -> bytes:
    body = json.dumps({"type": URN + kind, "title": reason, "status": status, "detail": detail}).encode()
    head = [f"HTTP/1.1 {status} {reason}", "Content-Type: application/problem+json"]
    head += [f"{k}: {v}" for k, v in extra] + [f"Content-Length: {len(body)}", "Connection: close", "", ""]
    return "\r\n".join(head).encode() + body


class ClientLimitedProtocol(HeaderTimeoutH11Protocol):
    """uvicorn's h11 protocol with the header deadline, a cap per client address and a head-size cap."""

    max_per_client: ClassVar[int] = 0  # 0: no cap
    max_head_bytes: ClassVar[int] = MAX_HEAD_BYTES
    retry_after_s: ClassVar[int] = 1
    open_by_client: ClassVar[Counter[str]]  # one per server (protocol_class makes a class per server)

    _client_host: str | None = None
    _refused = False
    _head_bytes = 0  # bytes of the request head received so far (before it is complete)
    _tail = b""  # its last 3 bytes (a blank line may straddle two reads)

    def connection_made(self, transport) -> None:
        peer = transport.get_extra_info("peername")
        host = peer[0] if isinstance(peer, tuple) and peer else None
        if self.max_per_client and host is not None and self.open_by_client[host] >= self.max_per_client:
            self._refuse(
                transport,
                _problem_bytes(
                    503,
                    "Service Unavailable",
                    "too-many-connections",
                    f"this client address has {self.max_per_client} connections open already "
                    "(setting max_connections_per_client): reuse one, or try again later",
                    [("Retry-After", str(self.retry_after_s))],
                ),
            )
            return
        if host is not None:
            self._client_host = host
            self.open_by_client[host] += 1
        super().connection_made(transport)

    def _refuse(self, transport, answer: bytes) -> None:
        """Answer, stop sending, read and drop what the client sends; close at its end or after LINGER_S."""
        self._refused = True
        self.transport = transport
        transport.write(answer)
        if transport.can_write_eof():
            transport.write_eof()
        asyncio.get_running_loop().call_later(LINGER_S, transport.close)

    def data_received(self, data: bytes) -> None:
        if self._refused:
            return
        if self.conn.their_state is h11.IDLE:  # in a request head: count its bytes up to its blank line
            probe = self._tail + data
            end = probe.find(b"\r\n\r\n")
            self._head_bytes += len(data) if end < 0 else max(0, end + 4 - len(self._tail))
            self._tail = probe[-3:]
            if self._head_bytes > self.max_head_bytes:
                return self._head_too_large()
        super().data_received(data)
        if self.conn.their_state is not h11.IDLE:  # the head is complete: the next one counts afresh
            self._head_bytes, self._tail = 0, b""

    def _head_too_large(self) -> None:
        self._cancel_header_timer()
        self._refuse(
            self.transport,
            _problem_bytes(
                431,
                "Request Header Fields Too Large",
                "head-too-large",
                f"the request line and headers are larger than this server's limit of {self.max_head_bytes} bytes",
                [],
            ),
        )

    def eof_received(self) -> None:
        if self._refused:
            self.transport.close()
            return
        super().eof_received()

    def connection_lost(self, exc) -> None:
        if self._client_host is not None:
            self.open_by_client[self._client_host] -= 1
            if not self.open_by_client[self._client_host]:
                del self.open_by_client[self._client_host]
            self._client_host = None
        super().connection_lost(exc)


def protocol_class(settings: Settings) -> type[ClientLimitedProtocol]:
    """The protocol of one server: its own count of connections per address, the settings' limits."""
    return type(
        "OwcsimH11Protocol",
        (ClientLimitedProtocol,),
        {
            "header_timeout_s": settings.header_timeout_s,
            "max_per_client": settings.max_connections_per_client,
            "open_by_client": Counter(),
        },
    )
