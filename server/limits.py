"""Limits on what a client's connection may hold: header and body deadlines, ambiguous framing.

- `RequestLimits` (ASGI middleware): a request with both Content-Length and
  Transfer-Encoding (request smuggling's ambiguity, RFC 9112 section 6.1) or a malformed
  Content-Length is answered 400; a body not received within `body_timeout_s` of the
  request's start (a slow client, or a Content-Length larger than what it sends) ends
  the request with 408.
- `HeaderTimeoutH11Protocol` (uvicorn's h11 protocol): a connection that has not sent a
  request's complete headers `header_timeout_s` after it opened (or after its previous
  answer) is closed. uvicorn's own options cover the rest (serve.py): idle keep-alive
  (`timeout_keep_alive`), open connections (`limit_concurrency`: 503 beyond) and the size
  of an incomplete request head (`h11_max_incomplete_event_size`).
"""

from __future__ import annotations

import asyncio
import json

from uvicorn.protocols.http.h11_impl import H11Protocol

from .problems import URN

PROBLEM = b"application/problem+json"


class BodyTimeout(Exception):
    """The request body did not arrive in time."""


async def _problem(send, status: int, kind: str, title: str, detail: str, path: str) -> None:
    body = json.dumps(
        {"type": URN + kind, "title": title, "status": status, "detail": detail, "instance": path}
    ).encode()
    await send(
        {
            "type": "http.response.start",
            "status": status,
            "headers": [
                (b"content-type", PROBLEM),
                (b"content-length", str(len(body)).encode()),
                (b"connection", b"close"),
            ],
        }
    )
    await send({"type": "http.response.body", "body": body})


class RequestLimits:
    """ASGI middleware: reject ambiguous framing, give the body a deadline (see the module)."""

    def __init__(self, app, body_timeout_s: float):
        self.app, self.body_timeout_s = app, body_timeout_s

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        names = [k for k, _ in scope["headers"]]
        lengths = [v for k, v in scope["headers"] if k == b"content-length"]
        if b"transfer-encoding" in names and lengths:
            return await _problem(
                send,
                400,
                "bad-request",
                "Bad Request",
                "a request may not carry both Content-Length and Transfer-Encoding",
                scope["path"],
            )
        if len(lengths) > 1 or (lengths and not lengths[0].strip().isdigit()):
            return await _problem(send, 400, "bad-request", "Bad Request", "malformed Content-Length", scope["path"])
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.body_timeout_s
        body_done = False
        started = False

        async def limited_receive():
            nonlocal body_done
            if body_done:  # after the body: only the disconnect is left to wait for, without deadline
                return await receive()
            left = deadline - loop.time()
            try:
                message = await asyncio.wait_for(receive(), max(left, 0.0))
            except TimeoutError:
                raise BodyTimeout() from None
            if message["type"] != "http.request" or not message.get("more_body", False):
                body_done = True
            return message

        async def tracked_send(message):
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        try:
            await self.app(scope, limited_receive, tracked_send)
        except BodyTimeout:
            if not started:
                await _problem(
                    send,
                    408,
                    "body-timeout",
                    "Request Timeout",
                    f"the request body did not arrive within {self.body_timeout_s:g} s (setting body_timeout_s)",
                    scope["path"],
                )


class HeaderTimeoutH11Protocol(H11Protocol):
    """h11 protocol that closes a connection whose request head is not complete in time."""

    header_timeout_s: float = 10.0
    _header_timer: asyncio.TimerHandle | None
    _seen_cycle: object | None

    def connection_made(self, transport) -> None:
        super().connection_made(transport)
        self._seen_cycle = None
        self._header_timer = self.loop.call_later(self.header_timeout_s, self._headers_too_slow)

    def _headers_too_slow(self) -> None:
        self._header_timer = None
        if self.cycle is None or self.cycle is self._seen_cycle or self.cycle.response_complete:
            self.transport.close()  # no request head completed since the timer started

    def _cancel_header_timer(self) -> None:
        timer = getattr(self, "_header_timer", None)
        if timer is not None:
            timer.cancel()
            self._header_timer = None

    def handle_events(self) -> None:
        super().handle_events()
        if self.cycle is not None and self.cycle is not self._seen_cycle and not self.cycle.response_complete:
            self._cancel_header_timer()  # a request head arrived

    def on_response_complete(self) -> None:
        done = self.cycle
        super().on_response_complete()
        if not self.transport.is_closing() and self.cycle is done:  # (not: a pipelined request started)
            self._seen_cycle = done
            self._cancel_header_timer()
            self._header_timer = self.loop.call_later(self.header_timeout_s, self._headers_too_slow)

    def connection_lost(self, exc) -> None:
        self._cancel_header_timer()
        super().connection_lost(exc)


def protocol_with_header_timeout(seconds: float) -> type[HeaderTimeoutH11Protocol]:
    return type("OwcsimH11Protocol", (HeaderTimeoutH11Protocol,), {"header_timeout_s": seconds})
