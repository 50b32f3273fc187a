"""What a result reports about the medium (`modeled["medium"]`): particle smoke's derived optics, or the phase function.

Built on mie.py (the Mie optics) and phase.py (the phase functions, MiePhase among them).
"""

from __future__ import annotations

from owcsim.engine.media.mie import medium_coefficients, number_concentration, particle_optics
from owcsim.engine.media.phase import MiePhase
from owcsim.schemas.medium import KOSCHMIEDER, ParticleMediumSpec


def describe(spec: ParticleMediumSpec) -> dict:
    """What a result reports about particle smoke: derived coefficients, albedo, g, visibility, the table."""
    optics = particle_optics(spec.particles)
    sigma_a, sigma_s = medium_coefficients(spec)
    sigma_t = sigma_a + sigma_s
    table = MiePhase(optics.cos_theta, optics.phase)
    return {
        "model": "Mie, log-normal size distribution (engine/media/mie.py, miepython)",
        "number_concentration_per_m3": number_concentration(spec, optics),
        "sigma_a": sigma_a,
        "sigma_s": sigma_s,
        "sigma_t": sigma_t,
        "albedo": sigma_s / sigma_t if sigma_t > 0 else 0.0,
        "g": optics.g,
        "visibility_m": KOSCHMIEDER / sigma_t if sigma_t > 0 else None,
        "size_parameter_median": optics.x_median,
        "size_nodes": optics.nodes,
        "phase": table.describe(),
    }
