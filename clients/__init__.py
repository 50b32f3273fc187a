"""Clients of owcsim: the Python client of the HTTP service and the result it returns.

`Client`, `AsyncClient` and their exceptions need httpx (`pip install owcsim[client]`);
they are imported on first use, so `clients.result` works without it. Result files and plots
are owcsim.formats'. Depends on formats and schemas only (and owcsim.docs' MAX_SCENE_BYTES), never on
engine or server.
"""

from __future__ import annotations

_LAZY = {
    "Client": "client",
    "Job": "client",
    "AsyncClient": "aio",
    "AsyncJob": "aio",
    "RetryPolicy": "http",
    "Result": "result",
    "OwcsimError": "errors",
    "ApiError": "errors",
    "ConnectionFailed": "errors",
    "InvalidRequest": "errors",
    "Unauthorized": "errors",
    "NotFound": "errors",
    "Conflict": "errors",
    "QueueFull": "errors",
    "ServerError": "errors",
    "JobFailed": "errors",
    "InputFileError": "scene",
    "MeshFileError": "scene",
    "PhotometryFileError": "scene",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module 'clients' has no attribute {name!r}")
