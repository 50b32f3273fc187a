"""Particle smoke (the `particles` kind): a homogeneous medium with the Mie coefficients of its particles.

sigma_a, sigma_s [1/m] = N (<C_abs>, <C_sca>) averaged over the size distribution (mie.py, Bohren & Huffman
1983); the phase spec is the size-averaged Mie phase (`ParticleMediumSpec.phase`, tabulated by phase.py).
"""

from __future__ import annotations

from owcsim.engine.media.media import HomogeneousMedium, homogeneous_medium
from owcsim.engine.media.mie import medium_coefficients
from owcsim.schemas.medium import ParticleMediumSpec

__all__ = ["particles_from_spec"]


def particles_from_spec(spec: ParticleMediumSpec) -> HomogeneousMedium | None:
    """The `particles` kind (registry.py): smoke from its particles; None when it attenuates nothing."""
    sigma_a, sigma_s = medium_coefficients(spec)
    return homogeneous_medium(sigma_a, sigma_s, spec)
