"""Optional API keys: bearer tokens from the settings. With keys on, a key owns the jobs it submits.

Tokens are compared by their SHA-256 digest; the owner id stored with a job is a prefix
of that digest, never the token. With keys off every caller is the same owner.
"""

from __future__ import annotations

import hashlib

from fastapi import Depends, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from .problems import ProblemError

bearer = HTTPBearer(auto_error=False, description="an API key of the server (only when the server has keys)")

#: Owner id of every job when the server has no keys.
NO_AUTH_OWNER = ""


def current_owner(request: Request, credentials: HTTPAuthorizationCredentials | None = Depends(bearer)) -> str | None:
    """The caller's owner id; None when the server has no keys (the caller sees every job)."""
    owners: dict[str, str] = request.app.state.owners
    if not owners:
        return None
    challenge = 'Bearer realm="owcsim"'
    if credentials is None or not credentials.credentials.strip():
        raise ProblemError(
            401,
            "unauthorized",
            "this server needs an API key: send `Authorization: Bearer <key>`",
            headers={"WWW-Authenticate": challenge},
        )
    owner = owners.get(hashlib.sha256(credentials.credentials.strip().encode()).hexdigest())
    if owner is None:
        raise ProblemError(
            401,
            "unauthorized",
            "the API key is not valid on this server",
            headers={"WWW-Authenticate": challenge + ', error="invalid_token"'},
        )
    return owner
