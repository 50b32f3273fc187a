"""The surface and medium registries: their keys are the wire models' `type` names, and a new surface model or
medium kind is one class plus one registry line (CONTRIBUTING.md, "Add a surface model", "Add a medium kind").

The worked examples are real: a toy surface model (`Matte`, a uniform-hemisphere diffuse lobe) and a toy medium
kind (`Slab`, a homogeneous layer z0 < z < z1 across the scene) are defined here, registered with monkeypatch, and
checked against independent references: energy conservation and a normalised pdf by Gauss-Legendre quadrature,
reciprocity, the sampled cosines against their closed-form mean (and a planted wrong sampler caught), Beer-Lambert
transmittance and free-flight probabilities in closed form.
"""

from __future__ import annotations

import typing
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import pytest

from owcsim.engine.core.arrays import BoolArray, FloatArray
from owcsim.engine.media.medium import Medium
from owcsim.engine.media.model import MediumKind
from owcsim.engine.media.registry import MEDIUM_BUILDERS, medium_from_spec
from owcsim.engine.surfaces import registry
from owcsim.engine.surfaces.bsdf import Materials
from owcsim.engine.surfaces.lobes import Lobe, Pair
from owcsim.schemas.medium import IsotropicPhaseSpec, MediumSpec, PhaseSpec
from owcsim.schemas.surfaces import SurfaceSpec

N = np.array([0.0, 0.0, 1.0])


def _type_literals(union_annotation) -> set[str]:
    """The `type` names of a discriminated union of wire models (Annotated[A | B | ..., Field(...)])."""
    union, *_ = typing.get_args(union_annotation)
    return {typing.get_args(cls.model_fields["type"].annotation)[0] for cls in typing.get_args(union)}


# --- the registries match the wire models -----------------------------------------------------------------------------
def test_surface_registry_matches_schema_types():
    assert set(registry.SURFACE_MODELS) == _type_literals(SurfaceSpec) == {"lambertian", "phong", "mirror"}
    assert next(iter(registry.SURFACE_MODELS)) == registry.DIFFUSE  # the diffuse part is mixed first
    assert all(issubclass(m, Lobe) for m in registry.SURFACE_MODELS.values())


def test_medium_registry_matches_schema_types_and_kinds():
    assert set(MEDIUM_BUILDERS) == _type_literals(MediumSpec) == {k.value for k in MediumKind}


# --- a toy surface model: one class, one registry line ----------------------------------------------------------------
def _about(normals: FloatArray, cos_t: FloatArray, phi: FloatArray) -> FloatArray:
    """Directions (3, n) at polar angle acos(cos_t) and azimuth phi about `normals` (3, n) (Duff et al. 2017)."""
    x, y, z = normals
    sgn = np.copysign(1.0, z)
    a = -1.0 / (sgn + z)
    b = x * y * a
    tangent = np.array([1.0 + sgn * x * x * a, sgn * b, -sgn * x])
    bitangent = np.array([b, sgn + y * y * a, -y])
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t**2))
    return sin_t * np.cos(phi) * tangent + sin_t * np.sin(phi) * bitangent + cos_t * normals


@dataclass(frozen=True)
class Matte(Lobe):
    """Diffuse reflectance `rho` sampled uniformly over the hemisphere: f = rho / pi, pdf = 1 / (2 pi),
    weight f cos th_o / pdf = 2 rho cos th_o."""

    def brdf(self, pair: Pair) -> FloatArray:
        return self.rho / np.pi

    def density(self, share: FloatArray, pair: Pair) -> FloatArray:
        return share * np.where(pair.cos_o > 0, 1.0 / (2.0 * np.pi), 0.0)

    def sample(
        self, d_in: FloatArray, normals: FloatArray, u1: FloatArray, u2: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        cos_t = u1  # uniform in solid angle: cos th_o uniform on [0, 1)
        return _about(normals, cos_t, 2.0 * np.pi * u2), 2.0 * self.rho * cos_t


@dataclass(frozen=True)
class Planted(Matte):
    """A planted bug: cosine-weighted directions (mean cos th_o = 2/3) while `density` still says 1 / (2 pi)."""

    def sample(
        self, d_in: FloatArray, normals: FloatArray, u1: FloatArray, u2: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        cos_t = np.sqrt(1.0 - u1)
        return _about(normals, cos_t, 2.0 * np.pi * u2), 2.0 * self.rho * cos_t


@pytest.fixture
def matte(monkeypatch):
    """Register `Matte` as the surface type "matte" (the one registry line of CONTRIBUTING's example)."""
    monkeypatch.setitem(registry.SURFACE_MODELS, "matte", Matte)
    return Matte


def _incoming(theta_i: float, phi_i: float = 0.3) -> FloatArray:
    """The arriving direction d_in (into the surface) of light from polar angle theta_i [rad]."""
    return -np.array([np.sin(theta_i) * np.cos(phi_i), np.sin(theta_i) * np.sin(phi_i), np.cos(theta_i)])


def _hemisphere(n_mu: int = 24, n_phi: int = 64) -> tuple[FloatArray, FloatArray]:
    """Quadrature of the upper hemisphere: (directions (3, m), weights (m,) [sr]); Gauss-Legendre in cos th on
    [0, 1] times the periodic trapezoid in phi (exact for polynomials in cos th of degree < 2 n_mu)."""
    x, w = np.polynomial.legendre.leggauss(n_mu)
    mu, w_mu = 0.5 * (x + 1.0), 0.5 * w
    phi = 2.0 * np.pi * np.arange(n_phi) / n_phi
    m, p = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1.0 - m**2)
    dirs = np.array([s * np.cos(p), s * np.sin(p), m]).reshape(3, -1)
    return dirs, np.repeat(w_mu * 2.0 * np.pi / n_phi, n_phi)


def _batch(mat_of_count, d_in: FloatArray, w_o: FloatArray):
    count = w_o.shape[1]
    return mat_of_count(count), np.repeat(d_in[:, None], count, axis=1), np.repeat(N[:, None], count, axis=1)


@pytest.mark.parametrize("theta_i", [0.0, 0.7, 1.4])
@pytest.mark.parametrize("weights", [{"matte": 0.6}, {"lambertian": 0.3, "matte": 0.4}])
def test_toy_surface_conserves_energy_and_its_pdf_integrates_to_one(matte, theta_i, weights):
    """Directional albedo a(w_i) = int f cos th_o dw = sum of the weights; int pdf dw = 1 (quadrature)."""
    w_o, dw = _hemisphere()
    mat, d_in, normals = _batch(
        lambda n: Materials.mix(**{k: np.full(n, v) for k, v in weights.items()}), _incoming(theta_i), w_o
    )
    albedo = np.sum(mat.eval(d_in, normals, w_o) * w_o[2] * dw)
    assert albedo == pytest.approx(sum(weights.values()), rel=1e-12)
    assert np.sum(mat.pdf(d_in, normals, w_o) * dw) == pytest.approx(1.0, rel=1e-12)
    assert (mat.eval(d_in, normals, -w_o) == 0).all()  # nothing below the surface


def test_toy_surface_is_reciprocal(matte):
    rng = np.random.default_rng(5)
    a, b = (_about(np.repeat(N[:, None], 1000, axis=1), rng.random(1000), 2 * np.pi * rng.random(1000)) for _ in "ab")
    mat = Materials.mix(lambertian=np.full(1000, 0.2), matte=np.full(1000, 0.5))
    normals = np.repeat(N[:, None], 1000, axis=1)
    np.testing.assert_allclose(mat.eval(-a, normals, b), mat.eval(-b, normals, a), rtol=1e-15)


def _sampled_cosines(lobe: type[Matte], count: int = 200_000) -> tuple[float, float, FloatArray]:
    """(mean cos th_o, its standard error, weights) of `count` directions sampled by a Materials of `lobe`."""
    rng = np.random.default_rng(11)
    mat = Materials.mix(matte=lobe(np.full(count, 0.7)))
    d_in = np.repeat(_incoming(0.5)[:, None], count, axis=1)
    w_o, weight = mat.sample(d_in, np.repeat(N[:, None], count, axis=1), rng.random(count), rng.random(count))
    np.testing.assert_allclose(np.linalg.norm(w_o, axis=0), 1.0, rtol=1e-12)
    assert (w_o[2] >= 0).all()
    return float(w_o[2].mean()), float(w_o[2].std(ddof=1) / np.sqrt(count)), weight


def test_toy_surface_sampling_follows_its_pdf(matte):
    """Under pdf 1 / (2 pi) on the hemisphere, E[cos th_o] = int cos th / (2 pi) dw = 1/2; E[weight] = rho."""
    mean, se, weight = _sampled_cosines(Matte)
    assert abs(mean - 0.5) < 4 * se
    assert abs(weight.mean() - 0.7) < 4 * weight.std(ddof=1) / np.sqrt(len(weight))


def test_the_sampling_check_catches_a_planted_wrong_sampler(monkeypatch):
    monkeypatch.setitem(registry.SURFACE_MODELS, "matte", Planted)
    mean, se, _ = _sampled_cosines(Planted)
    assert abs(mean - 0.5) > 4 * se  # (2/3 in fact)


def test_toy_surface_from_a_document_and_mixed_by_albedo(matte):
    """A face of type "matte" (a stand-in for its wire model) is r_d rho diffuse plus (1 - r_d) rho matte; sampling
    picks the matte lobe with probability (1 - r_d)."""
    face = SimpleNamespace(type="matte", reflectance=0.5, diffuse_fraction=0.2)
    mat = Materials.of_surfaces([face, 0.3])
    assert mat.kinds == ("lambertian", "phong", "mirror", "matte")
    np.testing.assert_array_equal(mat.weight_of("lambertian"), [0.2 * 0.5, 0.3])
    np.testing.assert_array_equal(mat.weight_of("matte"), [0.5 - 0.2 * 0.5, 0.0])
    np.testing.assert_array_equal(mat.total, [0.5, 0.3])
    assert not mat.is_lambertian
    count = 100_000
    rng = np.random.default_rng(3)
    many = mat.take(np.zeros(count, np.int64))
    d_in = np.repeat(_incoming(0.2)[:, None], count, axis=1)
    _, weight = many.sample(d_in, np.repeat(N[:, None], count, axis=1), rng.random(count), rng.random(count))
    matte_share = np.mean(weight != 0.5)  # the diffuse lobe's weight is rho = 0.5 exactly, the matte's 2 rho cos
    assert abs(matte_share - 0.8) < 4 * np.sqrt(0.8 * 0.2 / count)
    assert abs(weight.mean() - 0.5) < 4 * weight.std(ddof=1) / np.sqrt(count)


# --- a toy medium kind: one file's worth, one registry line -----------------------------------------------------------
class Slab(Medium):
    """A homogeneous layer z0 < z < z1 [m] across the scene: extinction `sigma_t` [1/m], albedo `albedo` [-]."""

    def __init__(self, z0: float, z1: float, sigma_t: float, albedo: float, phase_spec: PhaseSpec | None = None):
        self.z0, self.z1, self.sigma_t, self.albedo = z0, z1, sigma_t, albedo
        self.phase_spec = phase_spec if phase_spec is not None else IsotropicPhaseSpec()
        self.bounds = None
        self.evaluations = 0

    @property
    def sigma_t_max(self) -> float:
        return self.sigma_t

    @property
    def scatters(self) -> bool:
        return self.sigma_t * self.albedo > 0

    @property
    def max_albedo(self) -> float:
        return self.albedo

    def _interval(self, o: FloatArray, d: FloatArray, L: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(t_in, t_out) of each segment inside the layer (t_out <= t_in: it misses)."""
        dz = np.where(d[:, 2] == 0, 1e-300, d[:, 2])
        ta, tb = (self.z0 - o[:, 2]) / dz, (self.z1 - o[:, 2]) / dz
        return np.maximum(np.minimum(ta, tb), 0.0), np.minimum(np.maximum(ta, tb), L)

    def _optical_depth(self, o: FloatArray, d: FloatArray, L: FloatArray) -> tuple[FloatArray, int]:
        t0, t1 = self._interval(o, d, L)
        inside = np.maximum(t1 - t0, 0.0)
        return self.sigma_t * inside, int(np.count_nonzero(inside))

    def _regular(
        self, o: FloatArray, d: FloatArray, L: FloatArray, need: FloatArray
    ) -> tuple[FloatArray, BoolArray, int]:
        tau, crossed = self._optical_depth(o, d, L)
        scattered = tau > need
        t0, _ = self._interval(o, d, L)
        return np.where(scattered, t0 + need / max(self.sigma_t, 1e-300), L), scattered, crossed

    def _coefficients_at(self, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        sigma_t = np.where((p[:, 2] > self.z0) & (p[:, 2] < self.z1), self.sigma_t, 0.0)
        return sigma_t, sigma_t * self.albedo


def slab_from_spec(spec) -> Slab | None:
    """The "slab" kind's builder: None when it attenuates nothing."""
    return Slab(spec.z0, spec.z1, spec.sigma_t, spec.albedo) if spec.sigma_t > 0 else None


@pytest.fixture
def slab(monkeypatch):
    monkeypatch.setitem(MEDIUM_BUILDERS, "slab", slab_from_spec)
    return SimpleNamespace(type="slab", z0=1.0, z1=2.0, sigma_t=0.8, albedo=0.6)


def test_toy_medium_transmittance_is_beer_lambert(slab):
    medium = medium_from_spec(slab)
    assert isinstance(medium, Slab) and medium.scatters and medium.max_albedo == 0.6
    empty: typing.Any = SimpleNamespace(**{**vars(slab), "sigma_t": 0.0})  # (a stand-in for its wire model)
    assert medium_from_spec(empty) is None
    theta = 0.4  # crossing the layer at polar angle theta: path length (z1 - z0) / cos theta inside
    o = np.array([[0.0, 0.0, 0.5], [0.0, 0.0, 1.2], [0.0, 0.0, 3.0]])
    d = np.array([[np.sin(theta), 0.0, np.cos(theta)], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    L = np.array([10.0, 2.5, 4.0])
    expected = np.exp(-0.8 * np.array([1.0 / np.cos(theta), 2.5, 0.0]))
    np.testing.assert_allclose(medium.transmittance(o, d, L), expected, rtol=1e-13)
    assert medium.evaluations == 2  # the third segment never enters the layer


@pytest.mark.parametrize("method", ["regular", "delta"])
def test_toy_medium_free_flight_follows_the_exponential(slab, method):
    """A segment of length L inside the layer collides with probability 1 - exp(-sigma_t L), at mean distance
    1 / sigma_t - L exp(-sigma_t L) / (1 - exp(-sigma_t L)) given a collision."""
    medium = medium_from_spec(slab)
    assert isinstance(medium, Slab)
    count, length = 200_000, 1.5
    rng = np.random.default_rng(7)
    o = np.tile([0.0, 0.0, 1.5], (count, 1))
    d = np.tile([1.0, 0.0, 0.0], (count, 1))
    t, scattered = medium.sample_distance(o, d, np.full(count, length), method=method, rng=rng)
    p = 1.0 - np.exp(-0.8 * length)
    assert abs(scattered.mean() - p) < 4 * np.sqrt(p * (1 - p) / count)
    hit = t[scattered]
    mean = 1.0 / 0.8 - length * (1.0 - p) / p
    assert abs(hit.mean() - mean) < 4 * hit.std(ddof=1) / np.sqrt(len(hit))
    assert (t[~scattered] == length).all()
