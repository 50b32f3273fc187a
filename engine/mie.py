"""Smoke from its particles: Mie optics of a log-normal size distribution (physics.md section 3; report 3.5).

Spheres of diameter D, complex refractive index m = n + i k (k >= 0 absorbs) in a gas of
real index n_medium, at vacuum wavelength lambda: size parameter x = pi D n_medium / lambda,
relative index m / n_medium, wavenumber in the gas k0 = 2 pi n_medium / lambda.

Single sphere (Bohren & Huffman 1983, ch. 4): the Mie coefficients a_n, b_n come from
`miepython` (Prahl; a maintained implementation of Wiscombe's 1979/1980 algorithm, with
the continued-fraction logarithmic derivative), as do Q_ext, Q_sca and g. The angular
part is summed here, vectorized over angles (miepython's own loop over angles is in
pure Python when numba is off): with pi_n, tau_n from the upward recurrences (B&H eq. 4.47)

    S1 = sum_n (2n+1)/(n(n+1)) (a_n pi_n + b_n tau_n),  S2 = sum_n (2n+1)/(n(n+1)) (a_n tau_n + b_n pi_n),

and the unpolarized scattered intensity i(mu) = (|S1|^2 + |S2|^2) / 2, whose integral over
the sphere is k0^2 C_sca (B&H eq. 4.77/3.22).

Size distribution: number density in y = ln D normal with mean ln D_g and standard
deviation ln sigma_g. Averages are trapezoid sums over nodes in y (the trapezoid rule is
spectrally accurate for the Gaussian; the node spacing also follows the Mie interference
structure, nodes at most 1 apart in x at the upper end), on a window outside which the integrand bounds (Rayleigh-like
D^2 min(1, x) and D^2 min(1, x)^4 growth times the Gaussian) hold less than 1e-10:

    <C> = int C(D) n(D) dD,   sigma = N <C>,
    p(mu) = int i_D(mu) n(D) dD / (k0^2 <C_sca>),  g = int g_D C_sca n dD / <C_sca>.

Mass concentration M with material density rho: N = M / (rho pi/6 <D^3>) with the exact
log-normal moment <D^3> = D_g^3 exp(4.5 ln^2 sigma_g) (Hatch & Choate 1929).
Visibility: Koschmieder, V = 3.912 / sigma_t.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from owcsim.schemas.medium import KOSCHMIEDER, MAX_COEFFICIENT, ParticleMediumSpec, ParticlesSpec

from .errors import SceneError

__all__ = ["ParticleOptics", "efficiencies", "intensity", "phase_single", "lognormal_nodes", "particle_optics",
           "number_concentration", "medium_coefficients", "describe", "DEFAULT_ANGLES"]

#: Points of the phase table: theta_i = pi (i / (n - 1))^2, dense near the forward peak
#: (spacing 2 sqrt(pi theta) / n: ~1e-4 rad at theta = 0.01, 0.18 deg at 180 deg).
DEFAULT_ANGLES = 2001
#: Fraction of each integrand bound left outside the size window.
_TAIL = 1e-10
#: Most size nodes of one distribution.
_MAX_NODES = 4000


def _import_miepython():
    try:
        import miepython
    except ImportError as err:  # pragma: no cover - the engine extra installs it
        raise SceneError("medium: particle smoke needs the `miepython` package (pip install 'owcsim[engine]')") \
            from err
    return miepython


def _m(m: complex) -> complex:
    """Our m = n + i k (k >= 0 absorbs) in miepython's convention n - i k."""
    return complex(m.real, -abs(m.imag))


def efficiencies(m: complex, x) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(Q_ext, Q_sca, Q_back, g) of spheres of size parameter x (array) and relative index m = n + i k."""
    mp = _import_miepython()
    x = np.atleast_1d(np.asarray(x, np.float64))
    qext, qsca, qback, g = (np.atleast_1d(np.asarray(v, np.float64)) for v in mp.efficiencies_mx(_m(m), x))
    return qext, qsca, qback, g


def _angular(mu: np.ndarray, n_terms: int) -> tuple[np.ndarray, np.ndarray]:
    """pi_n(mu), tau_n(mu) for n = 1..n_terms, shape (n_terms, len(mu)) (B&H eq. 4.47)."""
    pi = np.zeros((n_terms, len(mu)))
    tau = np.zeros((n_terms, len(mu)))
    p_prev, p = np.zeros_like(mu), np.ones_like(mu)
    for n in range(1, n_terms + 1):  # loop over multipole orders, vectorized over angles
        pi[n - 1] = p
        tau[n - 1] = n * mu * p - (n + 1) * p_prev
        p_prev, p = p, ((2 * n + 1) * mu * p - (n + 1) * p_prev) / n
    return pi, tau


def intensity(m: complex, x, mu) -> np.ndarray:
    """Unpolarized scattered intensity i = (|S1|^2 + |S2|^2) / 2 [-], shape (len(x), len(mu)).

    Normalisation of B&H: int i dOmega = x^2 pi Q_sca (= k0^2 C_sca).
    """
    mp = _import_miepython()
    x = np.atleast_1d(np.asarray(x, np.float64))
    mu = np.atleast_1d(np.asarray(mu, np.float64))
    coeffs = [mp.coefficients(_m(m), float(xi)) for xi in x]
    n_max = max(len(ab[0]) for ab in coeffs)
    a = np.zeros((len(x), n_max), complex)
    b = np.zeros((len(x), n_max), complex)
    for j, (aj, bj) in enumerate(coeffs):  # loop over sizes (padding only)
        a[j, :len(aj)], b[j, :len(bj)] = aj, bj
    n = np.arange(1, n_max + 1)
    scale = (2 * n + 1) / (n * (n + 1.0))
    pi, tau = _angular(mu, n_max)
    sa, sb = a * scale, b * scale
    s1 = sa @ pi + sb @ tau
    s2 = sa @ tau + sb @ pi
    return 0.5 * (np.abs(s1) ** 2 + np.abs(s2) ** 2)


def phase_single(m: complex, x: float, mu) -> np.ndarray:
    """Phase function of one sphere [1/sr], normalised over the sphere: i / (pi x^2 Q_sca)."""
    _, qsca, _, _ = efficiencies(m, x)
    return intensity(m, x, mu)[0] / (np.pi * x * x * qsca[0])


def lognormal_nodes(dg: float, sigma_g: float, wavelength: float, medium_index: float = 1.0,
                    n_nodes: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(D [m], w [-]) with sum_j w_j f(D_j) ~ int f(D) n(D) dD for the log-normal number pdf n.

    Trapezoid in y = ln D on the window described in the module docstring; the weights are
    the Gaussian density times the node spacing (not renormalised: the part of the number
    distribution outside the window is left out, and it is the part that does not scatter).
    sigma_g = 1: one node D_g with weight 1.
    """
    s = math.log(sigma_g)
    if s == 0.0:
        return np.array([dg]), np.array([1.0])
    mu = math.log(dg)
    y = np.linspace(mu - 9 * s, mu + 9 * s + 6 * s * s, 20001)
    x = np.pi * np.exp(y) * medium_index / wavelength
    gauss = np.exp(-0.5 * ((y - mu) / s) ** 2)
    lo, hi = y[-1], y[0]
    for bound in (np.minimum(1.0, x), np.minimum(1.0, x) ** 4):
        f = gauss * np.exp(2 * y - 2 * mu) * bound
        cdf = np.cumsum(f) / f.sum()
        lo = min(lo, y[np.searchsorted(cdf, _TAIL)])
        hi = max(hi, y[min(np.searchsorted(cdf, 1.0 - _TAIL), len(y) - 1)])
    x_hi = np.pi * math.exp(hi) * medium_index / wavelength
    if n_nodes is None:
        h = min(s / 10.0, 1.0 / max(x_hi, 1e-12))
        n_nodes = int(min(_MAX_NODES, max(33, math.ceil((hi - lo) / h) + 1)))
    yn = np.linspace(lo, hi, n_nodes)
    w = np.full(n_nodes, (hi - lo) / (n_nodes - 1))
    w[[0, -1]] *= 0.5
    w *= np.exp(-0.5 * ((yn - mu) / s) ** 2) / (s * math.sqrt(2 * math.pi))
    return np.exp(yn), w


@dataclass(frozen=True)
class ParticleOptics:
    """Per-particle optics of a size distribution (multiply the cross sections by N for coefficients).

    c_ext, c_sca, c_abs: mean cross sections <C> [m^2]; g: asymmetry parameter [-];
    cos_theta, phase: the size-averaged phase table (increasing cos, p [1/sr]);
    mean_d3: <D^3> [m^3]; x_median: size parameter of D_g [-]; nodes: size nodes used.
    """

    c_ext: float
    c_sca: float
    g: float
    cos_theta: np.ndarray
    phase: np.ndarray
    mean_d3: float
    x_median: float
    nodes: int

    @property
    def c_abs(self) -> float:
        return self.c_ext - self.c_sca


def _index(p: ParticlesSpec) -> complex:
    return complex(p.refractive_index.real, p.refractive_index.imag) / p.medium_index


def _table_mu(n_angles: int) -> np.ndarray:
    theta = np.pi * (np.arange(n_angles) / (n_angles - 1)) ** 2
    mu = np.cos(theta)[::-1].copy()
    mu[0], mu[-1] = -1.0, 1.0
    return mu


@lru_cache(maxsize=64)
def _optics(p: ParticlesSpec, n_angles: int, n_nodes: int | None) -> ParticleOptics:
    m = _index(p)
    k0 = 2 * np.pi * p.medium_index / p.wavelength
    d, w = lognormal_nodes(p.geometric_mean_diameter, p.geometric_std, p.wavelength, p.medium_index, n_nodes)
    x = d * k0 / 2
    qext, qsca, _, g = efficiencies(m, x)
    area = np.pi * d * d / 4
    c_ext = float(np.sum(w * qext * area))
    c_sca = float(np.sum(w * qsca * area))
    mu = _table_mu(n_angles)
    phase = np.zeros(n_angles)
    for chunk in np.array_split(np.arange(len(x)), max(1, len(x) // 64)):  # bounded memory
        phase += w[chunk] @ intensity(m, x[chunk], mu)
    phase /= k0 * k0 * c_sca
    g_mean = float(np.sum(w * qsca * area * g) / c_sca)
    s = math.log(p.geometric_std)
    mean_d3 = p.geometric_mean_diameter ** 3 * math.exp(4.5 * s * s)
    x_med = float(np.pi * p.geometric_mean_diameter * p.medium_index / p.wavelength)
    phase.setflags(write=False)
    mu.setflags(write=False)
    return ParticleOptics(c_ext, c_sca, g_mean, mu, phase, mean_d3, x_med, len(x))


def particle_optics(particles: ParticlesSpec, n_angles: int = DEFAULT_ANGLES, n_nodes: int | None = None) \
        -> ParticleOptics:
    """Size-averaged Mie optics of `particles` (cached per spec)."""
    if not (p := particles).refractive_index.real > 0:
        raise SceneError("medium.particles.refractive_index: the real part must be > 0")
    return _optics(p, int(n_angles), n_nodes)


def number_concentration(spec: ParticleMediumSpec, optics: ParticleOptics | None = None) -> float:
    """N [1/m^3]: given, or M / (rho pi/6 <D^3>) from a mass concentration."""
    if spec.number_concentration is not None:
        return float(spec.number_concentration)
    optics = optics or particle_optics(spec.particles)
    return float(spec.mass_concentration / (spec.particle_density * np.pi / 6 * optics.mean_d3))


def medium_coefficients(spec: ParticleMediumSpec) -> tuple[float, float]:
    """(sigma_a, sigma_s) [1/m] = N (<C_abs>, <C_sca>); a SceneError if beyond MAX_COEFFICIENT."""
    optics = particle_optics(spec.particles)
    n = number_concentration(spec, optics)
    sigma_a, sigma_s = n * max(optics.c_abs, 0.0), n * optics.c_sca
    if sigma_a + sigma_s > MAX_COEFFICIENT:
        raise SceneError(f"medium: the particles give sigma_t = {sigma_a + sigma_s:.4g} 1/m, above the limit of "
                         f"{MAX_COEFFICIENT:g} 1/m (opaque); lower the concentration")
    return sigma_a, sigma_s


def describe(spec: ParticleMediumSpec) -> dict:
    """What a result reports about particle smoke: derived coefficients, albedo, g, visibility, the table."""
    from .phase import MiePhase

    optics = particle_optics(spec.particles)
    sigma_a, sigma_s = medium_coefficients(spec)
    sigma_t = sigma_a + sigma_s
    table = MiePhase(optics.cos_theta, optics.phase)
    return {
        "model": "Mie, log-normal size distribution (engine/mie.py, miepython)",
        "number_concentration_per_m3": number_concentration(spec, optics),
        "sigma_a": sigma_a, "sigma_s": sigma_s, "sigma_t": sigma_t,
        "albedo": sigma_s / sigma_t if sigma_t > 0 else 0.0,
        "g": optics.g,
        "visibility_m": KOSCHMIEDER / sigma_t if sigma_t > 0 else None,
        "size_parameter_median": optics.x_median,
        "size_nodes": optics.nodes,
        "phase": table.describe(),
    }
