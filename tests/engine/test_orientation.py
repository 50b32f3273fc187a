"""Random orientation of a handheld receiver (docs/orientation.md): the engine's stratified rule against an
independent integration over the polar density (scipy.integrate.quad) and the uniform azimuth, in line of sight.

The reference is built here from the geometry: a lamp of Lambertian order m overhead, a receiver tilted by theta
toward azimuth omega, H = (m+1) A cos^m(phi) cos(psi) / (2 pi d^2) for psi <= FOV, with
cos(psi) = sin(theta) rho cos(omega - omega0) + cos(theta) v_z / d (rho = horizontal share of the unit vector to the
lamp). Over omega the FOV cut is an arc |omega - omega0| <= alpha(theta), so the mean over azimuth and the outage
fraction are closed forms in alpha; the integral over theta is scipy's quad.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from scipy import integrate
from scipy.special import erfcinv

from owcsim.engine.scene.scene import build_scene
from owcsim.schemas.orientation import MEASURED, OrientationModel, OrientationSpec, PolarDistribution
from tests.results import simulate_document as simulate
from tests.scenes import room_doc, spec

LAMP = np.array([2.0, 2.0, 3.0])
RX = np.array([2.9, 2.5, 0.8])
AREA, FOV_DEG, M = 1e-4, 60.0, 1.0
#: Komine & Nakagawa 2004 receiver (the defaults of LinkBudgetSpec) at 10 Mbit/s, written out for the reference.
Q, KB = 1.602176634e-19, 1.380649e-23
GAMMA, I_BG, T_K, G_OL, ETA, GAMMA_CH, G_M, I2, I3, B = (
    0.53,
    5.1e-3,
    295.0,
    10.0,
    1.12e-6,
    1.5,
    0.03,
    0.562,
    0.0868,
    1e7,
)


def noise_ab(area: float) -> tuple[float, float]:
    """sigma^2 = a + b P of Komine & Nakagawa 2004 (background shot + thermal; the signal's shot noise b P)."""
    a = (
        2 * Q * I_BG * I2 * B
        + 8 * math.pi * KB * T_K / G_OL * ETA * area * I2 * B**2
        + 16 * math.pi**2 * KB * T_K * GAMMA_CH / G_M * ETA**2 * area**2 * I3 * B**3
    )
    return a, 2 * Q * GAMMA * B


def snr_of(power):
    a, b = noise_ab(AREA)
    return (GAMMA * power) ** 2 / (a + b * power)


def density(model: OrientationModel):
    """The truncated polar density f(theta) [1/rad] on [0, pi/2], written from the measured parameters."""
    dist, mu_deg, s_deg = MEASURED[model]
    mu, s = math.radians(mu_deg), math.radians(s_deg)
    if dist is PolarDistribution.LAPLACE:
        raw = lambda t: math.exp(-abs(t - mu) / s)  # noqa: E731
    else:
        raw = lambda t: math.exp(-0.5 * ((t - mu) / s) ** 2)  # noqa: E731
    mass = integrate.quad(raw, 0, math.pi / 2, points=[mu], limit=200)[0]
    return (lambda t: raw(t) / mass), mu


def geometry():
    v = LAMP - RX
    d = float(np.linalg.norm(v))
    k0 = (M + 1) / (2 * math.pi) * (v[2] / d) ** M * AREA / d**2  # H = k0 cos(psi) inside the FOV
    return k0, math.hypot(v[0], v[1]) / d, v[2] / d


def arc(theta: float, c: float) -> float:
    """alpha: cos(psi) >= c for |omega - omega0| <= alpha (0 when nowhere, pi when everywhere)."""
    _, rho, vz = geometry()
    s = math.sin(theta) * rho
    if s <= 0:
        return math.pi if math.cos(theta) * vz >= c else 0.0
    return math.acos(min(1.0, max(-1.0, (c - math.cos(theta) * vz) / s)))


def reference(model: OrientationModel, threshold_snr: float) -> dict[str, float]:
    """Mean received power [W], mean linear SNR and outage probability over orientations (P_t = 1 W)."""
    f, mu = density(model)
    k0, rho, vz = geometry()
    c_fov = math.cos(math.radians(FOV_DEG))

    def mean_cos(theta):  # (1/2pi) integral of cos(psi) 1[cos psi >= c_fov] d omega
        al = arc(theta, c_fov)
        return (math.sin(theta) * rho * math.sin(al) + math.cos(theta) * vz * al) / math.pi

    def mean_snr(theta):
        al = arc(theta, c_fov)
        g = lambda u: snr_of(k0 * (math.sin(theta) * rho * math.cos(u) + math.cos(theta) * vz))  # noqa: E731
        return integrate.quad(g, -al, al, limit=200)[0] / (2 * math.pi) if al > 0 else 0.0

    a, b = noise_ab(AREA)
    p_thr = (threshold_snr * b + math.sqrt((threshold_snr * b) ** 2 + 4 * GAMMA**2 * threshold_snr * a)) / (
        2 * GAMMA**2
    )
    c_out = max(p_thr / k0, c_fov)  # in outage where cos(psi) < c_out (outside the FOV: no power)

    def quad(g):
        return integrate.quad(lambda t: f(t) * g(t), 0, math.pi / 2, points=[mu], limit=400, epsabs=0, epsrel=1e-10)[0]

    return {
        "received_power_mean_w": k0 * quad(mean_cos),
        "snr_mean": quad(mean_snr),
        "outage_probability": quad(lambda t: 1.0 - arc(t, c_out) / math.pi),
    }


def doc_with(orientation: dict, threshold_db: float | None = None) -> dict:
    doc = room_doc(max_reflections=0, tx=tuple(LAMP), rx=tuple(RX), area=AREA, fov_deg=FOV_DEG, m=M)
    o = dict(orientation)
    if threshold_db is not None:
        o["outage_snr_db"] = threshold_db
    doc["receivers"][0]["orientation"] = o
    doc["link_budget"] = {"bit_rate": B}
    return doc


@pytest.mark.parametrize("model", [OrientationModel.SITTING, OrientationModel.WALKING])
def test_mean_power_snr_and_outage_match_the_integral_over_the_polar_density(model):
    threshold_db = 27.0  # near the median SNR of both models here: an outage well inside (0, 1)
    res = simulate(spec(doc_with({"model": model.value, "samples": 4096}, threshold_db)))
    assert res["run"]["stop_reason"] == "exact"
    (row,) = res["orientation"]
    ref = reference(model, 10 ** (threshold_db / 10))
    assert 0.1 < ref["outage_probability"] < 0.9
    snr_mean = 10 ** (row["snr_mean_db"] / 10)
    snr_se = snr_mean * row["snr_mean_db_stderr"] * math.log(10) / 10
    checks = [
        (row["received_power_mean_w"], row["received_power_mean_w_stderr"], ref["received_power_mean_w"]),
        (snr_mean, snr_se, ref["snr_mean"]),
        (row["outage_probability"], row["outage_probability_stderr"], ref["outage_probability"]),
    ]
    for value, se, r in checks:
        assert se > 0
        assert abs(value - r) <= 4 * se, (value, r, se)
        assert abs(value - 1.1 * r) > 4 * se, "power: a reference 10 % off must fail"


def test_the_stated_quadrature_error_covers_a_small_rule():
    """32 samples (the default): the error grows, and still covers the reference."""
    threshold_db = 27.0
    res = simulate(spec(doc_with({"model": "sitting", "samples": 32}, threshold_db)))
    (row,) = res["orientation"]
    ref = reference(OrientationModel.SITTING, 10 ** (threshold_db / 10))
    se = row["received_power_mean_w_stderr"]
    assert abs(row["received_power_mean_w"] - ref["received_power_mean_w"]) <= 4 * se
    assert se < 0.1 * ref["received_power_mean_w"]  # and is useful: power checked above at 4096
    assert abs(row["outage_probability"] - ref["outage_probability"]) <= 4 * row["outage_probability_stderr"]


def test_samples_are_ordinary_receivers_with_exact_los_gains():
    """Every oriented receiver's link is the closed form H = k0 cos(psi) 1[psi <= FOV] of its own normal (1e-9)."""
    res = simulate(spec(doc_with({"model": "walking", "samples": 64})))
    (row,) = res["orientation"]
    first, k = row["first_sample_index"], row["samples"]
    rx = res["receivers"][first : first + k]
    assert [r["id"] for r in rx] == [f"rx@o{i}" for i in range(k)]
    n = np.array([r["normal"] for r in rx])
    v = (LAMP - RX) / np.linalg.norm(LAMP - RX)
    k0 = geometry()[0]
    cos_psi = n @ v
    ref = np.where(cos_psi >= math.cos(math.radians(FOV_DEG)), k0 * cos_psi, 0.0)
    links = {link["receiver"]: link["dc_gain"] for link in res["links"]}
    got = np.array([links[r["id"]] for r in rx])
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-20)
    assert row["received_power_mean_w"] == pytest.approx(ref.mean(), rel=1e-12)
    # the polar angles are those of the law: one per theta cell, tilted from the receiver's normal (0, 0, 1)
    theta = np.arccos(np.clip(n[:, 2], -1, 1))
    law = OrientationSpec(model="walking", samples=64).law
    n_theta, n_omega = OrientationSpec(model="walking", samples=64).strata
    cdf = np.array([integrate.quad(law.pdf, 0, t)[0] for t in theta])
    cells = np.floor(cdf * n_theta).reshape(n_theta, n_omega)
    assert (cells == np.arange(n_theta)[:, None]).all()


def test_default_threshold_is_the_snr_of_ber_1e_6():
    o = OrientationSpec()
    assert o.threshold_snr == pytest.approx(2 * erfcinv(2e-6) ** 2, rel=1e-9)  # BER = erfc(sqrt(SNR/2)) / 2
    assert OrientationSpec(outage_ber=1e-3).threshold_snr == pytest.approx(2 * erfcinv(2e-3) ** 2, rel=1e-9)
    assert OrientationSpec(outage_snr_db=10.0).threshold_snr == pytest.approx(10.0)


def _grid_doc(orientation: dict | None) -> dict:
    doc = room_doc(max_reflections=0, tx=tuple(LAMP), rx=tuple(RX), area=AREA, fov_deg=FOV_DEG, m=M)
    grid = {"id_prefix": "g", "origin": [1.0, 1.0, 0.8], "size": [2.0, 1.0], "spacing": 0.5, "area": AREA}
    if orientation is not None:
        grid["orientation"] = orientation
    doc["receiver_grids"] = [grid]
    doc["link_budget"] = {"bit_rate": B}
    return doc


def test_oriented_grid_keeps_its_maps_and_adds_the_orientation_quantities():
    plain = simulate(spec(_grid_doc(None)))
    held = simulate(spec(_grid_doc({"model": "sitting", "samples": 16, "outage_snr_db": 27.0})))
    (pm,), (hm,) = plain["maps"], held["maps"]
    assert hm["shape"] == pm["shape"] == [5, 3]
    for q, values in pm["values"].items():
        assert hm["values"][q] == values  # the ordinary map is untouched
    n_points = 1 + 15  # the explicit receiver and the grid
    assert [r["id"] for r in held["receivers"][:n_points]] == [r["id"] for r in plain["receivers"]]
    assert len(held["receivers"]) == n_points + 15 * 16
    rows = [r for r in held["orientation"] if r["receiver"].startswith("g[")]
    assert len(rows) == 15
    outage = np.array(hm["values"]["outage_probability"], float).ravel()
    np.testing.assert_array_equal(outage, [r["outage_probability"] for r in rows])
    assert hm["units"]["snr_mean_db"] == "dB" and "outage_probability" in hm["stderr"]
    # each point's mean is the mean of its own samples' links
    links = {link["receiver"]: link["received_power_w"] for link in held["links"]}
    r = rows[7]
    samples = [links[f"{r['receiver']}@o{k}"] for k in range(16)]
    assert r["received_power_mean_w"] == pytest.approx(np.mean(samples), rel=1e-12)


def test_a_masked_oriented_point_is_one_masked_grid_point_in_the_warning():
    doc = _grid_doc({"model": "sitting", "samples": 16})
    doc["receiver_grids"][0]["exclude"] = [{"min": [-0.1, -0.1], "max": [0.1, 0.1]}]
    res = simulate(spec(doc))
    (warning,) = [w for w in res["warnings"] if "not simulated" in w]
    assert warning.startswith("1 grid point(s) not simulated") and "g[0,0]" in warning
    assert sum(1 for r in res["receivers"] if r["masked"]) == 1 + 16  # the point and its samples


def test_an_oriented_point_on_a_wall_is_refused_in_one_sentence():
    """Its samples tilted into the wall would be masked: null statistics, silently, before this check."""
    doc = _grid_doc({"model": "sitting", "samples": 8})
    doc["receiver_grids"][0]["origin"] = [0.0, 1.0, 0.8]  # the grid's first row on the wall x = 0
    with pytest.raises(
        ValueError, match=r"receiver_grids\[0\] \(g\): the point at \(0.0, 1.0, 0.8\) sits on a room face"
    ):
        spec(doc)
    doc["receiver_grids"][0]["origin"] = [0.01, 1.0, 0.8]
    spec(doc)  # 1 cm into the room: fine
    floor = _grid_doc(None)
    floor["receivers"][0].update(position=[2.0, 2.0, 0.0], orientation={"samples": 8})  # on the floor, facing up
    spec(floor)  # tilts of at most 90 deg never face into the floor


def test_hidden_receivers_agree_with_receiver_at():
    """The scene's arrays and SceneSpec.receiver_at (the truncation pilot's view) give the same receivers."""
    doc = _grid_doc({"model": "walking", "samples": 4})
    doc["receivers"][0]["orientation"] = {"samples": 6}
    doc["angle_diversity_receivers"] = [
        {"id": "adr", "position": [2.0, 1.0, 0.8], "pyramid": {"tilt_deg": 40, "area": 1e-4, "fov_deg": 50}}
    ]
    s = spec(doc)
    rx = build_scene(s).receivers
    assert len(rx) == 1 + 15 + 6 + 15 * 4 + 5 == len(s.receiver_ids())
    for i in range(16, len(rx)):
        r = s.receiver_at(i)
        assert r.id == rx.ids[i]
        np.testing.assert_allclose(r.position, rx.positions[i], rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.array(r.normal) / np.linalg.norm(r.normal), rx.normals[i], atol=1e-12)
        assert math.cos(math.radians(r.fov_deg)) == pytest.approx(rx.cos_fov[i], abs=1e-12)


@pytest.mark.parametrize(
    "change, message",
    [
        ({"model": "custom", "mean_deg": 30}, "needs `distribution`, `mean_deg` and `scale_deg`"),
        ({"model": "sitting", "mean_deg": 30}, "are for `model: custom`"),
        ({"samples": 31}, "samples must be even"),
        ({"outage_snr_db": 10, "outage_ber": 1e-3}, "not both"),
    ],
)
def test_bad_requests_are_refused_in_one_sentence(change, message):
    with pytest.raises(ValueError, match=message):
        OrientationSpec.model_validate(change)


def test_spectral_scenes_and_too_many_receivers_are_refused():
    doc = _grid_doc({"samples": 4096})
    doc["receiver_grids"][0]["spacing"] = 0.05  # 41 x 21 points x 4096
    with pytest.raises(ValueError, match="more than the 200000 allowed"):
        spec(doc)
    doc = copy.deepcopy(_grid_doc({"samples": 4}))
    doc["spectral"] = {"wavelengths": [450e-9, 550e-9]}
    with pytest.raises(ValueError, match="not supported in spectral scenes"):
        spec(doc)


def test_all_orders_mean_matches_los_plus_first_bounce_at_the_samples_normals():
    """K = 1 by the Monte Carlo: the point's mean power against the mean over its samples' normals of the closed-form
    LOS plus the converged first-bounce patch integral (tests/reference.py), within 4 of the Monte Carlo bound
    (1/K) sum sigma_k the engine adds (the quadrature error does not apply: the same nodes)."""
    from tests.reference import first_bounce_box_dc_gain
    from tests.scenes import BARRY_RHO

    doc = doc_with({"model": "sitting", "samples": 8})
    doc["simulation"].update(max_reflections=1, paths=40_000, seed=5)
    res = simulate(spec(doc))
    (row,) = res["orientation"]
    first, k = row["first_sample_index"], row["samples"]
    normals = [r["normal"] for r in res["receivers"][first : first + k]]
    v = (LAMP - RX) / np.linalg.norm(LAMP - RX)
    k0 = geometry()[0]
    los = [k0 * (n @ v) if n @ v >= math.cos(math.radians(FOV_DEG)) else 0.0 for n in np.asarray(normals)]
    h1 = [
        first_bounce_box_dc_gain(
            (5.0, 5.0, 3.0), BARRY_RHO, tuple(LAMP), (0, 0, -1), M, tuple(RX), tuple(n), AREA,
            math.radians(FOV_DEG), rel_tol=1e-3,
        )
        for n in normals
    ]  # fmt: skip
    ref = float(np.mean(np.add(los, h1)))
    links = {link["receiver"]: link for link in res["links"]}
    sigma_mc = np.mean([links[f"rx@o{i}"]["dc_gain_stderr"] for i in range(k)])
    assert 0 < sigma_mc < 0.005 * ref
    assert row["received_power_mean_w_stderr"] >= sigma_mc
    assert abs(row["received_power_mean_w"] - ref) <= 4 * sigma_mc + 1e-3 * ref  # + the patch integral's tolerance
    assert abs(row["received_power_mean_w"] - 1.1 * ref) > 4 * sigma_mc + 1e-3 * ref
