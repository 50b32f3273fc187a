"""Problem details (RFC 9457): the body of every error answer of the HTTP API.

Served as `application/problem+json`. `errors` locates each wrong field of a document
by its dotted path (e.g. `receivers.0.fov_deg`), the same paths `owcsim validate` prints.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

#: Media type of a problem document.
PROBLEM_MEDIA_TYPE = "application/problem+json"


class ProblemField(BaseModel):
    """One wrong field: where it is and what is wrong with it."""

    model_config = ConfigDict(extra="allow")

    loc: str = Field(
        description="dotted path of the field in the request, e.g. `receivers.0.fov_deg`; "
        "`body` for the whole document, `query.limit` for a query parameter"
    )
    msg: str = Field(description="what is wrong, in words")
    type: str = Field("value_error", description="machine-readable kind of error")


class Problem(BaseModel):
    """An error answer. `type` names the kind of problem (`urn:owcsim:problem:...`)."""

    model_config = ConfigDict(extra="allow")

    type: str = Field("about:blank", description="kind of problem, e.g. `urn:owcsim:problem:invalid-scene`")
    title: str = Field(description="short summary of the kind of problem")
    status: int = Field(description="HTTP status code")
    detail: str | None = Field(None, description="what went wrong in this case, in words")
    instance: str | None = Field(None, description="the request path")
    errors: list[ProblemField] = Field(default_factory=list, description="each wrong field, located")
    error_count: int | None = Field(
        None, description="how many errors the document has; `errors` lists the first 20 (422 answers)"
    )


def located(errors: Sequence[Mapping[str, Any]], prefix: tuple = ()) -> list[tuple[str, str]]:
    """pydantic error dicts -> (dotted location, message without pydantic's "Value error, " prefix)."""
    return [
        (
            ".".join(str(part) for part in prefix + tuple(e["loc"])),
            e["msg"].removeprefix("Value error, ").removeprefix("Assertion failed, "),
        )
        for e in errors
    ]
