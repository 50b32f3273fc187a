"""Run the service with uvicorn (what `owcsim serve` does)."""

from __future__ import annotations

import logging

from .settings import Settings


def uvicorn_config(settings: Settings, host: str, port: int, log_level: str = "info"):
    """uvicorn's Config: the app, and limits on connections (all, and per client address), idle time, header
    time and head size (connections.py)."""
    import uvicorn

    from .app import create_app
    from .connections import MAX_HEAD_BYTES, protocol_class

    return uvicorn.Config(
        create_app(settings),
        host=host,
        port=port,
        log_level=log_level,
        timeout_graceful_shutdown=10,
        server_header=False,
        http=protocol_class(settings),
        timeout_keep_alive=settings.keep_alive_s,  # type: ignore[arg-type]  # uvicorn passes it to call_later: a float works
        limit_concurrency=settings.max_connections,
        h11_max_incomplete_event_size=MAX_HEAD_BYTES,
    )


def serve(settings: Settings, host: str = "127.0.0.1", port: int = 8000, log_level: str = "info") -> None:
    """Serve until SIGINT/SIGTERM; running jobs are requeued on the way out (see Dispatcher.stop)."""
    import uvicorn

    logging.basicConfig(level=log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    uvicorn.Server(uvicorn_config(settings, host, port, log_level)).run()
