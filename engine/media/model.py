"""The document's medium as the engine decides it once, when the scene is built (`Scene.medium_model`).

Whether the medium scatters and its largest single-scattering albedo are asked by the
automatic settings (engine/run/auto.py: the algorithm; albedo_max bounds the scattering
orders' geometric tail) and by the result (its warnings, what is left out, the truncation
estimate). They are read from the medium built from the document (`Medium.scatters`,
`Medium.max_albedo`: sigma_s > 0 somewhere; max sigma_s / sigma_t), not re-decided from the
document in each place; a particle medium's Mie report (derived coefficients, g, visibility)
is computed here once. A spectral scene runs a carrier band's medium (engine/spectral) but
keeps this model of the document's grey medium: the automatic settings follow the grey rules.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from owcsim.engine.media.media import Medium
from owcsim.engine.media.phase import PhaseFunction, describe_phase
from owcsim.engine.media.report import describe
from owcsim.schemas.medium import MediumSpec


class MediumKind(StrEnum):
    """The kind of medium a document describes (its `type`)."""

    HOMOGENEOUS = "homogeneous"
    GRID = "grid"
    PARTICLES = "particles"


@dataclass(frozen=True)
class MediumModel:
    """What the scene's medium is: its `kind`, whether it `scatters` (sigma_s > 0 somewhere), its largest
    single-scattering albedo `max_albedo` = max sigma_s / sigma_t [-] (0 where sigma_t = 0), and for particle
    smoke the Mie report `particles` (engine/media/mie.py `describe`)."""

    kind: MediumKind
    scatters: bool
    max_albedo: float
    particles: dict[str, Any] | None = None

    def report(self, phase: PhaseFunction | None) -> dict[str, Any]:
        """The result's `modeled.medium` entry: the Mie report of particle smoke; otherwise the kind and the
        phase function the scene runs (`phase`: None without a built medium)."""
        if self.particles is not None:
            return dict(self.particles)
        return {"model": self.kind.value, "phase": describe_phase(phase) if phase is not None else None}


def medium_model(spec: MediumSpec | None, medium: Medium | None) -> MediumModel | None:
    """The model of the document's medium `spec` given the medium built from it (`medium`: None when sigma_t = 0
    everywhere: it neither scatters nor has an albedo); None without a medium."""
    if spec is None:
        return None
    kind = MediumKind(spec.type)
    particles = describe(spec) if spec.type == "particles" else None
    if medium is None:
        return MediumModel(kind, False, 0.0, particles)
    return MediumModel(kind, bool(medium.scatters), medium.max_albedo, particles)
