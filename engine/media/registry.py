"""The medium kinds by the `type` of their wire model (schemas/medium.py), and `medium_from_spec`: a document's medium.

`MEDIUM_BUILDERS` maps each kind to its builder: the document's spec -> its `Medium` (medium.py's interface:
free-flight sampling, transmittance, phase, `scatters`, `max_albedo`), or None when sigma_t = 0 everywhere (nothing
to attenuate). Adding a kind is its file (a `Medium` subclass and its builder), one line here and its member of
model.py's `MediumKind` (CONTRIBUTING.md, "Add a medium kind"; tests/engine/test_registries.py checks the three
agree with the schema).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from owcsim.engine.media.grid import grid_from_spec
from owcsim.engine.media.media import homogeneous_from_spec
from owcsim.engine.media.medium import Medium
from owcsim.engine.media.particles import particles_from_spec
from owcsim.schemas.medium import MediumSpec

__all__ = ["MEDIUM_BUILDERS", "medium_from_spec"]

#: a kind's builder: its spec -> the medium, or None when it attenuates nothing
MediumBuilder = Callable[[Any], Medium | None]

MEDIUM_BUILDERS: dict[str, MediumBuilder] = {
    "homogeneous": homogeneous_from_spec,
    "particles": particles_from_spec,
    "grid": grid_from_spec,
}


def medium_from_spec(spec: MediumSpec | None) -> Medium | None:
    """The engine medium of the document's `spec` (its kind's builder), or None when there is nothing to attenuate
    (no medium, or sigma_t = 0 everywhere). A particle medium is a homogeneous one with its Mie sigma_a, sigma_s and
    the Mie phase spec (particles.py)."""
    if spec is None:
        return None
    return MEDIUM_BUILDERS[spec.type](spec)
