"""Shared pieces of the wire models: strict base class and 3-vectors.

Everything is SI (metres, seconds, watts, 1/m); the only unit suffix is `_deg`
for angles, which JSON users think of in degrees.
"""

from __future__ import annotations

import math
from typing import Annotated

from pydantic import AfterValidator, BaseModel, ConfigDict


class SpecModel(BaseModel):
    """Input model: unknown fields are errors, numbers are finite, values are immutable once parsed."""

    # JSON has no inf: "Infinity" is an error
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


def _finite_vec(v: tuple[float, float, float]) -> tuple[float, float, float]:
    if not all(math.isfinite(c) for c in v):
        raise ValueError("components must be finite numbers")
    return v


def _direction(v: tuple[float, float, float]) -> tuple[float, float, float]:
    """Finite and of non-zero length; kept as given (the engine normalises it once, when it builds
    the scene: normalising here would run again at every validation of a stored document, and
    normalising twice is not bit-for-bit idempotent)."""
    _finite_vec(v)
    if not math.sqrt(sum(c * c for c in v)) >= 1e-12:
        raise ValueError("a direction must have a non-zero length")
    return v


#: A point [m], three finite numbers.
Point = Annotated[tuple[float, float, float], AfterValidator(_finite_vec)]
#: A direction: three finite numbers, not all zero; any length (the engine normalises it).
Direction = Annotated[tuple[float, float, float], AfterValidator(_direction)]
