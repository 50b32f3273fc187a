"""Smoke from its particles: Mie optics of a log-normal size distribution (physics.md section 3; report 3.5).

Spheres of diameter D, complex refractive index m = n + i k (k >= 0 absorbs) in a gas of
real index n_medium, at vacuum wavelength lambda: size parameter x = pi D n_medium / lambda,
relative index m / n_medium, wavenumber in the gas k0 = 2 pi n_medium / lambda.

Single sphere (Bohren & Huffman 1983, ch. 4): the Mie coefficients a_n, b_n come from
`miepython` (Prahl; a maintained implementation of Wiscombe's 1979/1980 algorithm, with
the continued-fraction logarithmic derivative); `efficiencies` is miepython's Q_ext, Q_sca,
Q_back, g. For size distributions the sums over n are done here on the coefficients,
vectorized over sizes and angles (miepython's own loop over angles is pure Python when
numba is off): Q_ext, Q_sca, g Q_sca by B&H eqs. 4.61, 4.62, 4.74, and with pi_n, tau_n from
the upward recurrences (B&H eq. 4.47)

    S1 = sum_n (2n+1)/(n(n+1)) (a_n pi_n + b_n tau_n),  S2 = sum_n (2n+1)/(n(n+1)) (a_n tau_n + b_n pi_n),

and the unpolarized scattered intensity i(mu) = (|S1|^2 + |S2|^2) / 2, whose integral over
the sphere is k0^2 C_sca (B&H eq. 4.77/3.22).

Size distribution: number density in y = ln D normal with mean ln D_g and standard
deviation ln sigma_g. Averages are trapezoid sums on nodes ln(sigma_g)/10 apart in y for small
particles and 1 apart in x for large ones (the Mie interference structure; 1/4 apart when
the particles absorb too weakly to damp the ripple: k x_max < 2), through a smooth
change of variable that keeps the trapezoid rule's spectral accuracy (`lognormal_nodes`), on a
window outside which the integrand bounds (D^2 min(1, x) and D^2 min(1, x)^4 times the
Gaussian: absorption-like and Rayleigh-scattering-like growth) hold less than 1e-8 (`size_window`):

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

from owcsim.engine.core.errors import SceneError
from owcsim.schemas.medium import MAX_COEFFICIENT, ParticleMediumSpec, ParticlesSpec

__all__ = [
    "ParticleOptics",
    "efficiencies",
    "intensity",
    "phase_single",
    "lognormal_nodes",
    "particle_optics",
    "number_concentration",
    "medium_coefficients",
    "size_window",
    "DEFAULT_ANGLES",
]

#: Points of the phase table: theta_i = pi (i / (n - 1))^2, dense near the forward peak
#: (spacing 2 sqrt(pi theta) / n: ~1e-4 rad at theta = 0.01, 0.18 deg at 180 deg).
DEFAULT_ANGLES = 2001
#: Fraction of each integrand bound left outside the size window.
_TAIL = 1e-8
#: k x above which the absorption index k damps the Mie ripple enough for one size node per unit x.
RIPPLE_DAMPED = 2.0
#: Most size nodes of one distribution.
_MAX_NODES = 4000


def _import_miepython():
    try:
        import miepython
    except ImportError as err:  # pragma: no cover - the engine extra installs it
        raise SceneError("medium: particle smoke needs the `miepython` package (pip install 'owcsim[engine]')") from err
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


def _coefficients(m: complex, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mie a_n, b_n (miepython) of each size parameter, zero-padded to shape (len(x), n_max)."""
    mp = _import_miepython()
    coeffs = [mp.coefficients(_m(m), float(xi)) for xi in x]  # loop over sizes: miepython's per-sphere call
    n_max = max(len(ab[0]) for ab in coeffs)
    a = np.zeros((len(x), n_max), complex)
    b = np.zeros((len(x), n_max), complex)
    for j, (aj, bj) in enumerate(coeffs):
        a[j, : len(aj)], b[j, : len(bj)] = aj, bj
    return a, b


def _efficiencies_ab(a: np.ndarray, b: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Q_ext, Q_sca, g Q_sca) from the coefficients (B&H eqs. 4.61, 4.62 and 4.74)."""
    n = np.arange(1, a.shape[1] + 1)
    qext = 2 / x**2 * ((2 * n + 1) * (a + b).real).sum(axis=1)
    qsca = 2 / x**2 * ((2 * n + 1) * (np.abs(a) ** 2 + np.abs(b) ** 2)).sum(axis=1)
    nn = n[:-1]
    cross = (nn * (nn + 2) / (nn + 1) * (a[:, :-1] * a[:, 1:].conj() + b[:, :-1] * b[:, 1:].conj()).real).sum(axis=1)
    own = ((2 * n + 1) / (n * (n + 1)) * (a * b.conj()).real).sum(axis=1)
    return qext, qsca, 4 / x**2 * (cross + own)


def _intensity_ab(a: np.ndarray, b: np.ndarray, pi: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """(|S1|^2 + |S2|^2) / 2 for each row of coefficients at the angles of pi, tau: shape (rows, angles).

    Real matrix products: [Re; Im] of (2n+1)/(n(n+1)) a_n (and b_n) times pi_n, tau_n.
    """
    n = np.arange(1, a.shape[1] + 1)
    scale = (2 * n + 1) / (n * (n + 1.0))
    k = len(a)
    sa = np.concatenate([(a * scale).real, (a * scale).imag])
    sb = np.concatenate([(b * scale).real, (b * scale).imag])
    pi, tau = pi[: a.shape[1]], tau[: a.shape[1]]
    s1 = sa @ pi + sb @ tau  # rows 0..k-1: Re S1, k..2k-1: Im S1
    s2 = sa @ tau + sb @ pi
    return 0.5 * (s1[:k] ** 2 + s1[k:] ** 2 + s2[:k] ** 2 + s2[k:] ** 2)


def intensity(m: complex, x, mu) -> np.ndarray:
    """Unpolarized scattered intensity i = (|S1|^2 + |S2|^2) / 2 [-], shape (len(x), len(mu)).

    Normalisation of B&H: int i dOmega = x^2 pi Q_sca (= k0^2 C_sca).
    """
    x = np.atleast_1d(np.asarray(x, np.float64))
    mu = np.atleast_1d(np.asarray(mu, np.float64))
    a, b = _coefficients(m, x)
    return _intensity_ab(a, b, *_angular(mu, a.shape[1]))


def phase_single(m: complex, x: float, mu) -> np.ndarray:
    """Phase function of one sphere [1/sr], normalised over the sphere: i / (pi x^2 Q_sca)."""
    _, qsca, _, _ = efficiencies(m, x)
    return intensity(m, x, mu)[0] / (np.pi * x * x * qsca[0])


def lognormal_nodes(
    dg: float,
    sigma_g: float,
    wavelength: float,
    medium_index: float = 1.0,
    n_nodes: int | None = None,
    per_x: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """(D [m], w [-]) with sum_j w_j f(D_j) ~ int f(D) n(D) dD for the log-normal number pdf n.

    Trapezoid rule in a variable t with dt/dy = sqrt(A^2 + (c x)^2), y = ln D, A = 10 / ln sigma_g,
    c = `per_x`: nodes ln(sigma_g)/10 apart in y for small particles and 1/c apart in x for large
    ones (the Mie interference structure), and, the map being analytic, the rule keeps the
    spectral accuracy of the trapezoid rule for an integrand that vanishes at both ends of the
    window. t(y) = sqrt(A^2 + (c x)^2) - A asinh(A / (c x)). Weights: the Gaussian density times dy/dt times the
    step (not renormalised: the part of the number distribution outside the window is left out,
    and it is the part that does not scatter). sigma_g = 1: one node D_g with weight 1.
    """
    s = math.log(sigma_g)
    if s == 0.0:
        return np.array([dg]), np.array([1.0])
    mu = math.log(dg)
    lo, hi = size_window(dg, sigma_g, wavelength, medium_index)
    x0 = per_x * np.pi * medium_index / wavelength  # c x = x0 D
    big_a = 10.0 / s

    def t_of(y):
        x = x0 * np.exp(y)
        return np.sqrt(big_a**2 + x * x) - big_a * np.arcsinh(big_a / x)

    t_lo, t_hi = float(t_of(lo)), float(t_of(hi))
    if n_nodes is None:
        n_nodes = int(min(_MAX_NODES, max(33, math.ceil(t_hi - t_lo) + 1)))
    t = np.linspace(t_lo, t_hi, n_nodes)
    fine = np.linspace(lo, hi, 4001)
    y = np.interp(t, t_of(fine), fine)
    for _ in range(4):  # Newton on t(y) = t from the interpolated start (t is smooth and increasing)
        y = np.clip(y - (t_of(y) - t) / np.sqrt(big_a**2 + (x0 * np.exp(y)) ** 2), lo, hi)
    step = (t_hi - t_lo) / (n_nodes - 1)
    w = np.full(n_nodes, step) / np.sqrt(big_a**2 + (x0 * np.exp(y)) ** 2)
    w[[0, -1]] *= 0.5
    w *= np.exp(-0.5 * ((y - mu) / s) ** 2) / (s * math.sqrt(2 * math.pi))
    return np.exp(y), w


def size_window(dg: float, sigma_g: float, wavelength: float, medium_index: float = 1.0) -> tuple[float, float]:
    """(ln D_lo, ln D_hi): the window holding all but _TAIL of each integrand bound (module docstring); one
    point for a single size (sigma_g = 1, which `lognormal_nodes` takes as one node)."""
    s = math.log(sigma_g)
    mu = math.log(dg)
    if s == 0.0:  # monodisperse: no spread to integrate (0/0 in the Gaussian below)
        return mu, mu
    y = np.linspace(mu - 8 * s, mu + 8 * s + 6 * s * s, 20001)
    x = np.pi * np.exp(y) * medium_index / wavelength
    gauss = np.exp(-0.5 * ((y - mu) / s) ** 2)
    lo, hi = float(y[-1]), float(y[0])
    for bound in (np.minimum(1.0, x), np.minimum(1.0, x) ** 4):
        f = gauss * np.exp(2 * y - 2 * mu) * bound
        cdf = np.cumsum(f) / f.sum()
        lo = min(lo, float(y[int(np.searchsorted(cdf, _TAIL))]))
        hi = max(hi, float(y[min(int(np.searchsorted(cdf, 1.0 - _TAIL)), len(y) - 1)]))
    return lo, hi


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
    # weakly absorbing spheres keep the ripple of the Mie efficiencies (period ~1 in x): 4 nodes per unit x
    x_hi = math.exp(size_window(p.geometric_mean_diameter, p.geometric_std, p.wavelength, p.medium_index)[1]) * k0 / 2
    per_x = 4.0 if m.imag * x_hi < RIPPLE_DAMPED else 1.0
    d, w = lognormal_nodes(p.geometric_mean_diameter, p.geometric_std, p.wavelength, p.medium_index, n_nodes, per_x)
    x = d * k0 / 2
    a, b = _coefficients(m, x)
    qext, qsca, gqsc = _efficiencies_ab(a, b, x)
    area = np.pi * d * d / 4
    c_ext = float(np.sum(w * qext * area))
    c_sca = float(np.sum(w * qsca * area))
    mu = _table_mu(n_angles)
    pi, tau = _angular(mu, a.shape[1])
    phase = np.zeros(n_angles)
    order = np.argsort(x)  # chunks of similar sizes share their number of terms
    for chunk in np.array_split(order, max(1, len(x) // 32)):  # bounded memory
        n_terms = int(np.max(np.flatnonzero((a[chunk] != 0).any(axis=0)), initial=0)) + 1
        phase += w[chunk] @ _intensity_ab(a[chunk, :n_terms], b[chunk, :n_terms], pi, tau)
    phase /= k0 * k0 * c_sca
    g_mean = float(np.sum(w * gqsc * area) / c_sca)
    s = math.log(p.geometric_std)
    mean_d3 = p.geometric_mean_diameter**3 * math.exp(4.5 * s * s)
    x_med = float(np.pi * p.geometric_mean_diameter * p.medium_index / p.wavelength)
    phase.setflags(write=False)
    mu.setflags(write=False)
    return ParticleOptics(c_ext, c_sca, g_mean, mu, phase, mean_d3, x_med, len(x))


def particle_optics(
    particles: ParticlesSpec, n_angles: int = DEFAULT_ANGLES, n_nodes: int | None = None
) -> ParticleOptics:
    """Size-averaged Mie optics of `particles` (cached per spec)."""
    if not (p := particles).refractive_index.real > 0:
        raise SceneError("medium.particles.refractive_index: the real part must be > 0")
    return _optics(p, int(n_angles), n_nodes)


def number_concentration(spec: ParticleMediumSpec, optics: ParticleOptics | None = None) -> float:
    """N [1/m^3]: given, or M / (rho pi/6 <D^3>) from a mass concentration."""
    if spec.number_concentration is not None:
        return float(spec.number_concentration)
    optics = optics or particle_optics(spec.particles)
    assert spec.mass_concentration is not None and spec.particle_density is not None  # (the schema's rule)
    return float(spec.mass_concentration / (spec.particle_density * np.pi / 6 * optics.mean_d3))


def medium_coefficients(spec: ParticleMediumSpec) -> tuple[float, float]:
    """(sigma_a, sigma_s) [1/m] = N (<C_abs>, <C_sca>); a SceneError if beyond MAX_COEFFICIENT."""
    optics = particle_optics(spec.particles)
    n = number_concentration(spec, optics)
    sigma_a, sigma_s = n * max(optics.c_abs, 0.0), n * optics.c_sca
    if sigma_a + sigma_s > MAX_COEFFICIENT:
        raise SceneError(
            f"medium: the particles give sigma_t = {sigma_a + sigma_s:.4g} 1/m, above the limit of "
            f"{MAX_COEFFICIENT:g} 1/m (opaque); lower the concentration"
        )
    return sigma_a, sigma_s
