"""What a Phong material's `reflectance` is, and the albedo it implies (issue 22, item 9).

`reflectance` rho = rho_d + rho_s is the sum of the parts' weights, not the albedo
a(th_i) = int f(w_i, w_o) cos th_o dw_o (the fraction of the incident power reflected). With the
BRDF of engine/surfaces/bsdf.py (docs/luminaires-surfaces.md),

    f = rho_d / pi + rho_s (n + 1) / (2 pi) cos^n(alpha) / max(cos th_i, cos th_o),

a(0) = rho_d + rho_s (n + 1) / (n + 2) at normal incidence (the lobe's axis is the normal, alpha = th_o),
and less at grazing incidence, where part of the lobe falls below the surface. References: that
closed form, and a plain midpoint quadrature of the BRDF written here over the hemisphere; the
engine's albedo is the mean weight of Materials.sample (its one-sample estimator of a), compared
within 4 standard errors.
"""

import math
import re
from pathlib import Path

import numpy as np
import pytest

from owcsim.engine.surfaces.bsdf import Materials
from owcsim.engine.surfaces.lobes import Phong

DOCS = Path(__file__).resolve().parents[2] / "docs" / "luminaires-surfaces.md"
#: The docs' example floor: {"type": "phong", "reflectance": 0.3, "diffuse_fraction": 0.6, "exponent": 30}
RHO, R_D, N = 0.3, 0.6, 30.0


def albedo_quadrature(rho_d, rho_s, n, theta_i, steps=600):
    """int f cos th_o dw_o over the upper hemisphere: midpoint rule in (cos th_o, phi_o)."""
    mu = (np.arange(steps) + 0.5) / steps  # cos th_o
    phi = (np.arange(2 * steps) + 0.5) * (2 * math.pi / (2 * steps))
    mu, phi = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - mu * mu)
    w_o = np.stack([s * np.cos(phi), s * np.sin(phi), mu])
    w_i = np.array([math.sin(theta_i), 0.0, math.cos(theta_i)])  # toward where the light came from
    r = np.array([-w_i[0], -w_i[1], w_i[2]])  # its mirror direction about the normal +z
    cos_a = np.tensordot(r, w_o, axes=1)
    lobe = np.where(cos_a > 0, (n + 1) / (2 * math.pi) * np.maximum(cos_a, 0) ** n, 0.0)
    f = rho_d / math.pi + rho_s * lobe / np.maximum(math.cos(theta_i), mu)
    return float(np.sum(f * mu) * (1.0 / steps) * (2 * math.pi / (2 * steps)))


def albedo_engine(rho_d, rho_s, n, theta_i, count=400_000, seed=3):
    """Mean and standard error of Materials.sample's weight factor (the engine's estimate of the albedo)."""
    mat = Materials.mix(lambertian=np.full(count, rho_d), phong=Phong(np.full(count, rho_s), np.full(count, n)))
    d_in = np.tile(np.array([[-math.sin(theta_i)], [0.0], [-math.cos(theta_i)]]), count)  # arriving, into the surface
    normals = np.tile(np.array([[0.0], [0.0], [1.0]]), count)
    u = np.random.default_rng(seed).random((2, count))
    _, weight = mat.sample(d_in, normals, u[0], u[1])
    return float(weight.mean()), float(weight.std() / math.sqrt(count))


def test_normal_incidence_closed_form_against_quadrature():
    for n in (0.0, 1.0, 10.0, 30.0):
        closed = R_D * RHO + (1 - R_D) * RHO * (n + 1) / (n + 2)
        assert albedo_quadrature(R_D * RHO, (1 - R_D) * RHO, n, 0.0) == pytest.approx(closed, rel=2e-4)
    assert albedo_quadrature(0.0, 1.0, 0.0, 0.0) == pytest.approx(0.5, rel=2e-4)  # n = 0: half the lobe


@pytest.mark.parametrize("theta_deg", [0.0, 45.0, 75.0])
def test_the_engine_reflects_the_albedo_of_the_stated_brdf(theta_deg):
    rho_d, rho_s = R_D * RHO, (1 - R_D) * RHO
    ref = albedo_quadrature(rho_d, rho_s, N, math.radians(theta_deg))
    mean, se = albedo_engine(rho_d, rho_s, N, math.radians(theta_deg))
    assert abs(mean - ref) < 4 * se + 1e-4 * ref, (theta_deg, mean, ref, se)
    assert abs(1.05 * mean - ref) > 4 * se + 1e-4 * ref  # a 5 % error would be seen
    assert ref < RHO  # the albedo is below `reflectance`


def test_the_albedo_falls_at_grazing_incidence():
    rho_d, rho_s = R_D * RHO, (1 - R_D) * RHO
    a = [albedo_quadrature(rho_d, rho_s, N, math.radians(t)) for t in (0.0, 45.0, 75.0, 85.0)]
    assert a[0] > a[2] > a[3] and a[1] <= a[0] + 1e-9


def test_the_docs_state_the_normal_incidence_albedo_of_their_example():
    text = DOCS.read_text()
    assert "a(0) = rho_d + rho_s (n + 1) / (n + 2)" in text
    found = re.search(r"albedo\s+at\s+normal\s+incidence\s+is\s+([0-9.]+)", text)
    assert found is not None
    stated = float(found.group(1))
    assert stated == pytest.approx(albedo_quadrature(R_D * RHO, (1 - R_D) * RHO, N, 0.0), abs=5e-5)
