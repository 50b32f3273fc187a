"""Luminaires from photometric files and non-Lambertian surfaces in full simulations.

References are independent of the kernel: tests/reference.py (LOS closed form, Barry
patch integration), the plain bilinear interpolation and midpoint quadrature of
test_photometry, closed forms (energy, image source), and the other estimator direction.
"""

from __future__ import annotations

import base64
import math
import re

import numpy as np
import pytest

from owcsim.engine.core.errors import SceneError
from tests import reference as ref
from tests.engine.test_photometry import (
    C_FULL,
    G180,
    as_written,
    bilinear,
    cos_power_table,
    ies_text,
    ldt_text,
    midpoint_masses,
    tilted_lobe,
)
from tests.results import simulate_document as simulate
from tests.scenes import barry_first_bounce, room_doc, spec, within


def _b64(text: str) -> str:
    return base64.b64encode(text.encode()).decode("ascii")


def luminaire_doc(text: str, fmt="ies", *, tx=(2.5, 2.5, 3.0), aim=(0, 0, -1), rotation_deg=0.0, **kw) -> dict:
    doc = room_doc(tx=tx, tx_normal=aim, **kw)
    doc["transmitters"] = [
        {
            "id": "lum",
            "position": list(tx),
            "normal": list(aim),
            "photometry": {"data_base64": _b64(text), "format": fmt, "rotation_deg": rotation_deg},
        }
    ]
    return doc


def _link(doc, **kw):
    return simulate(spec(doc), **kw)["links"][0]


def _assert_directions_agree(f, b, orders=range(1, 5)):
    """Forward and backward links agree on H0 (with the power to see a 2 % error) and per reflection order."""
    err = math.hypot(f["dc_gain_stderr"], b["dc_gain_stderr"])
    assert err < 0.02 * f["dc_gain"]
    assert within(f["dc_gain"], b["dc_gain"], err)
    for k in orders:
        ek = math.hypot(f["dc_gain_by_reflection_order_stderr"][k], b["dc_gain_by_reflection_order_stderr"][k])
        assert within(f["dc_gain_by_reflection_order"][k], b["dc_gain_by_reflection_order"][k], ek), k


G1 = np.arange(0.0, 90.01, 1.0)


# ----------------------------------------------------------------------------- cos^m file = generalized Lambertian
@pytest.mark.parametrize(
    "rx,normal,fov", [((0.5, 1.0, 0.0), (0, 0, 1), 85.0), ((4.0, 1.5, 1.0), (-0.3, 0.2, 1.0), 60.0)]
)
def test_cos_power_file_los_equals_lambertian_closed_form(rx, normal, fov):
    m = 2.0
    table = cos_power_table(m, G1, [0.0])
    link = _link(
        luminaire_doc(ies_text(G1, [0.0], table), rx=rx, rx_normal=normal, fov_deg=fov, max_reflections=0, paths=64)
    )
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    h, delay = ref.los_gain((2.5, 2.5, 3.0), (0, 0, -1), m, rx, n, 1e-4, math.radians(fov))
    # interpolation error of cos^2 on 1 deg steps: h^2/8 |f''| / f <= 1e-4 relative here (phi < 60 deg)
    assert link["los_gain"] == pytest.approx(h, rel=2e-4)
    assert link["los_gain"] != pytest.approx(h, rel=1e-7)  # it is the table, not the closed form
    assert link["los_delay_s"] == pytest.approx(delay, rel=1e-12)


@pytest.mark.parametrize("direction", ["forward", "backward"])
def test_cos_power_file_first_bounce_equals_barry_integration(direction):
    rx, fov = (0.5, 1.0, 0.0), 85.0
    text = ies_text(G1, [0.0, 90.0], cos_power_table(1.0, G1, [0.0, 90.0]))  # quadrant-symmetric form
    link = _link(
        luminaire_doc(
            text, rx=rx, fov_deg=fov, max_reflections=1, paths=150_000, batch_size=8192, direction=direction, seed=11
        )
    )
    h1 = barry_first_bounce(rx, fov)
    k1, k1_err = link["dc_gain_by_reflection_order"][1], link["dc_gain_by_reflection_order_stderr"][1]
    assert k1_err < 0.01 * h1
    # bias budget: reference 1e-4, table interpolation (1 deg, cos: < 4e-5 of R)
    assert within(k1, h1, k1_err, bias=5e-4 * h1), (k1, h1, k1_err)


# ----------------------------------------------------------------------------- asymmetric luminaire
TILTED = as_written(tilted_lobe(G180, C_FULL))


@pytest.mark.parametrize("rotation", [0.0, 40.0])
def test_asymmetric_file_los_against_direct_integration(rotation):
    """LOS = I(gamma, C) / Phi * A cos(psi) / d^2, I by plain bilinear interpolation, Phi by midpoint quadrature."""
    receivers = [
        ((3.5, 3.8, 0.0), (0, 0, 1)),
        ((1.0, 1.0, 0.0), (0, 0, 1)),
        ((4.5, 2.0, 1.2), (-1, 0, 0)),
        ((2.0, 4.0, 2.9), (0, 0, -1)),
        ((2.5, 2.5, 0.3), (0, 0, 1)),
    ]
    tx = np.array([2.5, 2.5, 1.5])
    doc = luminaire_doc(
        ies_text(G180, C_FULL, TILTED), tx=tuple(tx), rotation_deg=rotation, max_reflections=0, paths=64
    )
    doc["receivers"] = [
        {"id": f"r{k}", "position": list(p), "normal": list(n), "area": 1e-4, "fov_deg": 90.0}
        for k, (p, n) in enumerate(receivers)
    ]
    links = simulate(spec(doc))["links"]
    flux = midpoint_masses(G180, C_FULL, TILTED, sub=32).sum()
    r = math.radians(rotation)
    e0, e90, aim = (
        np.array([math.cos(r), math.sin(r), 0]),
        np.array([-math.sin(r), math.cos(r), 0]),
        np.array([0, 0, -1.0]),
    )
    for link, (p, n) in zip(links, receivers):
        v = np.asarray(p) - tx
        d = np.linalg.norm(v)
        u = v / d
        gamma = math.degrees(math.acos(u @ aim))
        c = math.degrees(math.atan2(u @ e90, u @ e0)) % 360
        intensity = bilinear(G180, C_FULL, TILTED, np.array([gamma]), np.array([c]))[0]
        nn = np.asarray(n, float) / np.linalg.norm(n)
        expected = intensity / flux * 1e-4 * max(-u @ nn, 0) / d**2
        assert expected > 0
        assert link["los_gain"] == pytest.approx(expected, rel=2e-5), link["receiver"]


def test_forward_backward_agree_with_a_luminaire_that_also_lights_upward():
    """The tilted lobe with a backward glow (gamma > 90 deg), mid-room: both directions, every order."""
    base = dict(tx=(2.0, 2.5, 1.8), rx=(3.5, 3.0, 0.8), fov_deg=80.0, max_reflections=3, paths=60_000, seed=3)
    text = ies_text(G180, C_FULL, TILTED)
    f = _link(luminaire_doc(text, direction="forward", **base))
    b = _link(luminaire_doc(text, direction="backward", **base))
    err = math.hypot(f["dc_gain_stderr"], b["dc_gain_stderr"])
    assert err < 0.02 * f["dc_gain"]
    assert within(f["dc_gain"], b["dc_gain"], err)
    for k in range(1, 4):
        ek = math.hypot(f["dc_gain_by_reflection_order_stderr"][k], b["dc_gain_by_reflection_order_stderr"][k])
        assert within(f["dc_gain_by_reflection_order"][k], b["dc_gain_by_reflection_order"][k], ek)


def test_luminaire_energy_closed_room():
    """Every emitted watt reaches the surfaces: P (1 - rho^K) / (1 - rho), exactly (weights are 1)."""
    rho, K = 0.5, 40
    doc = luminaire_doc(
        ies_text(G180, C_FULL, TILTED),
        rho_walls=rho,
        rho_floor=rho,
        rho_ceiling=rho,
        tx=(2.0, 2.5, 1.8),
        max_reflections=K,
        paths=5000,
        direction="forward",
        russian_roulette=False,
        t_max_s=2e-6,
        time_bin_s=1e-8,
    )
    res = simulate(spec(doc))
    assert res["diagnostics"]["power_on_surfaces"]["lum"] == pytest.approx((1 - rho**K) / (1 - rho), rel=1e-9)


def test_ldt_luminaire_equals_ies_luminaire():
    c_all = np.arange(0.0, 360.0, 15.0)
    ies = ies_text(G180, C_FULL, TILTED)
    ldt = ldt_text(G180, c_all, TILTED[:-1], 0)
    base = dict(tx=(2.0, 2.5, 1.8), max_reflections=2, paths=4096, seed=1)
    a = _link(luminaire_doc(ies, **base))
    b = _link(luminaire_doc(ldt, fmt="ldt", **base))
    assert a["dc_gain"] == pytest.approx(b["dc_gain"], rel=1e-9)


def test_bad_inline_file_is_a_located_scene_error():
    text = ies_text(G1, [0.0], cos_power_table(1.0, G1, [0.0])).replace("TILT=NONE", "TILT=lamp.tlt")
    with pytest.raises(SceneError, match=r"transmitters\[0\]\.photometry: line 5: TILT"):
        _link(luminaire_doc(text, max_reflections=0, paths=64))


def test_photometry_file_path_resolved_against_scene_folder(tmp_path):
    text = ies_text(G1, [0.0], cos_power_table(1.0, G1, [0.0]))
    (tmp_path / "lamp.ies").write_text(text)
    doc = luminaire_doc(text, max_reflections=0, paths=64)
    doc["transmitters"][0]["photometry"] = {"file": "lamp.ies"}
    inline = _link(luminaire_doc(text, max_reflections=0, paths=64))
    assert _link(doc, base_dir=tmp_path)["los_gain"] == inline["los_gain"]
    with pytest.raises(SceneError, match="photometric file .*missing.ies.* not found"):
        doc["transmitters"][0]["photometry"] = {"file": "missing.ies"}
        _link(doc, base_dir=tmp_path)


# ----------------------------------------------------------------------------- glossy (Phong) surfaces
def phong(rho, r_d, n):
    return {"type": "phong", "reflectance": rho, "diffuse_fraction": r_d, "exponent": n}


TX, RX_DOWN = np.array([2.5, 2.5, 3.0]), np.array([1.5, 1.5, 1.0])


def glossy_floor_first_bounce(rho_d, rho_s, n, m=1.0, area=1e-4, grid=1000, window=((0.0, 5.0), (0.0, 5.0))):
    """First bounce off a Phong floor (other faces black): midpoint quadrature over `window` of the floor.

    Tx at TX aimed down (order m), Rx at RX_DOWN facing down (FOV 90 deg). BRDF written out here:
    rho_d / pi + rho_s (n+1)/(2 pi) cos^n(alpha) / max(cos_i, cos_o).
    """
    (x0, x1), (y0, y1) = window
    hx, hy = (x1 - x0) / grid, (y1 - y0) / grid
    X, Y = np.meshgrid(x0 + (np.arange(grid) + 0.5) * hx, y0 + (np.arange(grid) + 0.5) * hy, indexing="ij")
    P = np.stack((X.ravel(), Y.ravel(), np.zeros(X.size)), axis=1)
    v1, v2 = P - TX, RX_DOWN - P
    d1, d2 = np.linalg.norm(v1, axis=1), np.linalg.norm(v2, axis=1)
    cos_tx = -v1[:, 2] / d1  # Tx normal (0, 0, -1)
    cos_i, cos_o = -v1[:, 2] / d1, v2[:, 2] / d2
    cos_rx = v2[:, 2] / d2  # Rx normal (0, 0, -1): cos = -(v2/d2) . n
    mirror = v1 / d1[:, None] * np.array([1, 1, -1])
    cos_a = np.clip(np.einsum("ij,ij->i", mirror, v2 / d2[:, None]), 0, None)
    f = rho_d / np.pi + rho_s * (n + 1) / (2 * np.pi) * cos_a**n / np.maximum(cos_i, cos_o)
    integrand = (m + 1) / (2 * np.pi) * cos_tx**m * cos_i / d1**2 * f * cos_o * area * cos_rx / d2**2
    return float(integrand.sum() * hx * hy)


def image_source_gain(rho_m, m=1.0, area=1e-4):
    """Mirror floor: the receiver sees the image of the Tx at (x, y, -z): rho_m R(phi) A cos(psi) / d^2."""
    img = TX * np.array([1, 1, -1])
    v = RX_DOWN - img
    d = np.linalg.norm(v)
    cos_phi = v[2] / d  # angle at the real Tx between its normal (0,0,-1) and the ray toward the floor
    cos_psi = v[2] / d
    return rho_m * (m + 1) / (2 * np.pi) * cos_phi**m * area * cos_psi / d**2


def glossy_doc(floor, walls=0.0, ceiling=0.0, **kw):
    doc = room_doc(walls, 0.0, ceiling, rx=tuple(RX_DOWN), rx_normal=(0, 0, -1), **kw)
    doc["room"]["reflectance"]["floor"] = floor
    return doc


@pytest.mark.parametrize("direction", ["forward", "backward"])
def test_phong_floor_first_bounce_against_quadrature(direction):
    ref_h1 = glossy_floor_first_bounce(0.2, 0.6, 20.0)
    link = _link(
        glossy_doc(
            phong(0.8, 0.25, 20.0), max_reflections=1, paths=200_000, batch_size=8192, direction=direction, seed=21
        )
    )
    k1, se = link["dc_gain_by_reflection_order"][1], link["dc_gain_by_reflection_order_stderr"][1]
    assert se < 0.02 * ref_h1
    assert within(k1, ref_h1, se, bias=1e-3 * ref_h1), (k1, ref_h1, se)
    # power: the Lambertian floor of the same reflectance differs by far more than the error band
    assert abs(glossy_floor_first_bounce(0.8, 0.0, 20.0) - ref_h1) > 10 * se


def test_phong_with_large_exponent_tends_to_the_image_source():
    """The Phong floor's first bounce (quadrature) -> the mirror's image-source gain as n grows."""
    img = image_source_gain(1.0)
    # the specular point is (1.75, 1.75, 0); for n >= 50 the lobe is < 1e-7 of its peak 1 m away
    window = ((0.75, 2.75), (0.75, 2.75))
    errs = [
        abs(glossy_floor_first_bounce(0.0, 1.0, n, grid=1500, window=window) - img) / img for n in (50.0, 500.0, 5000.0)
    ]
    assert errs[2] < errs[1] < errs[0] and errs[2] < 0.02, errs


def test_forward_backward_agree_per_order_with_glossy_surfaces():
    doc = dict(max_reflections=4, paths=80_000, seed=8, tx=(2.0, 3.0, 3.0), rx=(3.5, 1.0, 0.8), fov_deg=80.0)
    docs = {}
    for direction in ("forward", "backward"):
        d = room_doc(**doc, direction=direction)
        d["room"]["reflectance"] = {"floor": phong(0.6, 0.3, 30.0), "ceiling": 0.8, "walls": phong(0.7, 0.5, 5.0)}
        docs[direction] = _link(d)
    _assert_directions_agree(docs["forward"], docs["backward"])


def test_reciprocity_swapping_devices_with_glossy_surfaces():
    a, na, b, nb = (1.2, 3.4, 2.2), (0.3, -0.2, -1.0), (3.9, 0.8, 0.9), (-0.5, 0.4, 1.0)
    common = dict(m=1.0, fov_deg=90.0, max_reflections=3, paths=60_000, seed=5, direction="forward")
    res = []
    for p, n, q, nq in ((a, na, b, nb), (b, nb, a, na)):
        d = room_doc(tx=p, tx_normal=n, rx=q, rx_normal=nq, **common)
        d["room"]["reflectance"] = {"floor": phong(0.7, 0.2, 15.0), "ceiling": 0.8, "walls": phong(0.6, 0.4, 8.0)}
        res.append(_link(d))
    ab, ba = res
    assert ab["dc_gain_stderr"] < 0.02 * ab["dc_gain"]
    assert within(ab["dc_gain"], ba["dc_gain"], math.hypot(ab["dc_gain_stderr"], ba["dc_gain_stderr"]))


def test_lambertian_through_the_material_path_is_bit_identical():
    """A Lambertian scene run through the materials code gives the same numbers as the plain path
    (it consumes the same random numbers); Lambertian scenes themselves never enter that code."""
    from owcsim.engine.scene.scene import build_scene
    from owcsim.engine.surfaces.bsdf import Materials

    doc = room_doc(max_reflections=3, paths=8192, seed=2, direction="forward")
    plain = simulate(spec(doc))["links"][0]
    scene = build_scene(spec(doc))
    scene.geometry.material = Materials.lambertian(scene.geometry.reflectance)
    via = simulate(spec(doc), scene=scene)["links"][0]
    # same random numbers; the NEE factors are multiplied in another order (equal to rounding)
    assert via["dc_gain_by_reflection_order"] == pytest.approx(plain["dc_gain_by_reflection_order"], rel=1e-12)
    # and a material written as {"type": "lambertian"} is the number
    doc2 = room_doc(max_reflections=3, paths=8192, seed=2, direction="forward")
    doc2["room"]["reflectance"]["floor"] = {"type": "lambertian", "reflectance": 0.3}
    assert simulate(spec(doc2))["links"][0]["dc_gain"] == plain["dc_gain"]


# ----------------------------------------------------------------------------- perfect mirrors
def mirror(rho, r_d=0.0):
    return {"type": "mirror", "reflectance": rho, "diffuse_fraction": r_d}


@pytest.mark.parametrize("direction", ["forward", "backward"])
def test_mirror_floor_first_reflection_is_the_image_source(direction):
    """Black room, mirror floor: k = 1 is the image of the Tx in the floor, exactly (no variance)."""
    link = _link(glossy_doc(mirror(0.9), max_reflections=2, paths=2048, direction=direction))
    h1 = image_source_gain(0.9)
    assert link["dc_gain_by_reflection_order"][1] == pytest.approx(h1, rel=1e-9)
    assert link["dc_gain_by_reflection_order_stderr"][1] < 1e-7 * h1  # zero up to rounding
    assert link["dc_gain_by_reflection_order"][2] == 0.0  # a black room: nothing else
    d_img = np.linalg.norm(RX_DOWN - TX * np.array([1, 1, -1]))
    assert link["mean_delay_s"] == pytest.approx(d_img / 299_792_458.0, rel=1e-9)


@pytest.mark.parametrize("direction", ["forward", "backward"])
def test_half_mirror_floor_is_image_plus_diffuse_quadrature(direction):
    """Mirror 0.5 + diffuse 0.3: k = 1 = image source (0.5) + Lambertian floor (0.3) by quadrature."""
    link = _link(glossy_doc(mirror(0.8, 0.375), max_reflections=1, paths=100_000, direction=direction, seed=4))
    ref_h1 = image_source_gain(0.5) + glossy_floor_first_bounce(0.3, 0.0, 0.0)
    k1, se = link["dc_gain_by_reflection_order"][1], link["dc_gain_by_reflection_order_stderr"][1]
    assert 0 < se < 0.01 * ref_h1
    assert within(k1, ref_h1, se, bias=1e-3 * ref_h1), (k1, ref_h1, se)


def test_forward_backward_agree_per_order_with_a_mirror_floor_and_a_luminaire():
    """Mirror floor, diffuse walls, Phong ceiling, the tilted luminaire: both directions, every order."""
    base = dict(tx=(2.0, 2.5, 2.2), rx=(3.5, 3.0, 0.8), fov_deg=80.0, max_reflections=4, paths=80_000, seed=12)
    out = {}
    for direction in ("forward", "backward"):
        d = luminaire_doc(ies_text(G180, C_FULL, TILTED), direction=direction, **base)
        d["room"]["reflectance"] = {"floor": mirror(0.7, 0.3), "ceiling": phong(0.8, 0.5, 10.0), "walls": 0.6}
        out[direction] = _link(d)
    _assert_directions_agree(out["forward"], out["backward"])


# ----------------------------------------------------------------------------- files at the edges
def test_photometry_files_are_inlined_for_clusters_and_clients_and_refused_by_the_server(tmp_path):
    from owcsim.clients.scene import scene_document
    from owcsim.engine.run.execution_dask import portable_spec
    from owcsim.server.problems import ProblemError
    from owcsim.server.settings import Settings
    from owcsim.server.submission import check_limits

    text = ies_text(G1, [0.0], cos_power_table(1.0, G1, [0.0]))
    (tmp_path / "lamp.ies").write_text(text)
    doc = luminaire_doc(text, max_reflections=0, paths=64)
    doc["transmitters"][0]["photometry"] = {"file": "lamp.ies", "rotation_deg": 10.0}
    portable = portable_spec(spec(doc), tmp_path).transmitters[0].photometry
    assert portable.file is None and portable.format == "ies" and portable.rotation_deg == 10.0
    assert base64.b64decode(portable.data_base64).decode() == text
    sent = scene_document(doc, base_dir=tmp_path)["transmitters"][0]["photometry"]
    assert "file" not in sent and sent["format"] == "ies" and base64.b64decode(sent["data_base64"]).decode() == text
    with pytest.raises(ProblemError):
        check_limits(spec(doc), Settings())


def test_all_algorithms_agree_without_scattering_with_a_luminaire_and_glossy_surfaces():
    """sigma_s = 0 (absorbing air): algorithms 1 to 5 estimate the same paths (physics.md section 6)."""
    medium = {"type": "homogeneous", "sigma_a": 0.05, "sigma_s": 0.0}
    res = {}
    for algorithm in (1, 2, 3, 4, 5):
        d = luminaire_doc(
            ies_text(G180, C_FULL, TILTED),
            tx=(2.0, 2.5, 2.2),
            rx=(3.5, 3.0, 0.8),
            fov_deg=80.0,
            max_reflections=3,
            paths=20_000,
            seed=17,
            algorithm=algorithm,
            medium=medium,
            direction="forward",
        )
        if algorithm != 1:
            d["simulation"]["max_scattering"] = 1
        d["room"]["reflectance"] = {"floor": phong(0.6, 0.4, 25.0), "ceiling": 0.8, "walls": phong(0.7, 0.6, 4.0)}
        res[algorithm] = _link(d)
    ref_link = res[1]
    for a in (2, 3, 4, 5):
        err = math.hypot(res[a]["dc_gain_stderr"], ref_link["dc_gain_stderr"])
        assert within(res[a]["dc_gain"], ref_link["dc_gain"], err), a


# ----------------------------------------------------------------------------- schemas and automatic settings
@pytest.mark.parametrize(
    "change,message",
    [
        (lambda t: t.update(lambertian_order=1.0), "give `photometry` or a Lambertian pattern"),
        (lambda t: t["photometry"].update(data_base64="not base64!"), "`data_base64` is not valid base64"),
        (lambda t: t["photometry"].pop("format"), "`data_base64` needs `format`"),
        (lambda t: t.update(photometry={"file": "lamp.xyz"}), "cannot tell the format of 'lamp.xyz'"),
        (lambda t: t.update(photometry={"file": "a.ies", "data_base64": "AAAA", "format": "ies"}), "exactly one of"),
    ],
)
def test_photometry_spec_validation(change, message):
    from pydantic import ValidationError

    doc = luminaire_doc(ies_text(G1, [0.0], cos_power_table(1.0, G1, [0.0])))
    change(doc["transmitters"][0])
    with pytest.raises(ValidationError, match=re.escape(message)):
        spec(doc)


@pytest.mark.parametrize(
    "floor,message",
    [
        ({"type": "phong", "reflectance": 0.5, "diffuse_fraction": 1.2, "exponent": 10}, "less than or equal to 1"),
        ({"type": "phong", "reflectance": 0.5, "diffuse_fraction": 0.2}, "exponent"),
        ({"type": "glass", "reflectance": 0.5}, "a material with `type` lambertian, phong or mirror"),
        ({"type": "mirror", "reflectance": 1.5}, "less than or equal to 1"),
        (1.5, "a Lambertian reflectance must lie in [0, 1], found 1.5"),
    ],
)
def test_surface_spec_validation(floor, message):
    from pydantic import ValidationError

    doc = room_doc()
    doc["room"]["reflectance"]["floor"] = floor
    with pytest.raises(ValidationError, match=re.escape(message)):
        spec(doc)


def test_materials_per_face_and_rho_max_is_the_total_reflectance():
    from owcsim.engine.scene.scene import build_scene

    doc = room_doc(0.5, 0.3, 0.6)
    doc["room"]["reflectance"]["floor"] = phong(0.9, 0.2, 40.0)
    doc["furniture"] = [{"min": [1, 1, 0], "max": [2, 2, 1], "reflectance": mirror(0.7, 0.1)}]
    s = spec(doc)
    scene = build_scene(s)
    g = scene.geometry
    floor = np.array([n == "room.floor" for n in np.asarray(g.group_names)[g.group]])
    box = np.array([n == "furniture[0]" for n in np.asarray(g.group_names)[g.group]])
    np.testing.assert_allclose(g.material.rho_d[floor], 0.18)
    np.testing.assert_allclose(g.material.rho_s[floor], 0.72)
    np.testing.assert_allclose(g.material.exponent[floor], 40.0)
    np.testing.assert_allclose(g.material.rho_m[box], 0.63)
    np.testing.assert_allclose(g.material.rho_d[box], 0.07)
    np.testing.assert_allclose(g.reflectance, g.material.total)
    assert scene.max_reflectance == pytest.approx(0.9)
    assert len(scene.mirror_planes) == 6  # the box's six faces


def test_vertices_on_a_mirror_do_not_reflect_on_it_again():
    """Half-mirror floor, other faces black, K = 2: nothing reflects twice (floor -> floor is impossible).

    A floor vertex sees the floor's image of the receiver behind itself (cos < 0), and the
    kernel also skips vertices within a few ray offsets of a mirror plane."""
    link = _link(glossy_doc(mirror(0.8, 0.375), max_reflections=2, paths=50_000, seed=4))
    assert link["dc_gain_by_reflection_order"][1] > 0
    assert link["dc_gain_by_reflection_order"][2] == 0.0


@pytest.mark.parametrize("name", ["office_luminaires.json", "barry_glossy_floor.json"])
def test_example_scenes_run(name):
    """The shipped examples (their .ies / .ldt files by path, relative to the scene) build and run."""
    import json

    from tests.scenes import EXAMPLES

    doc = json.loads((EXAMPLES / name).read_text())
    doc["simulation"].update(paths=2048, max_reflections=2)
    res = simulate(spec(doc), base_dir=EXAMPLES)
    assert all(link["dc_gain"] > 0 and link["dc_gain_stderr"] < 0.1 * link["dc_gain"] for link in res["links"])


def test_automatic_settings_with_a_luminaire_and_glossy_surfaces():
    """K and the window chosen automatically; the tail estimate uses rho_max = the largest total reflectance."""
    doc = luminaire_doc(ies_text(G180, C_FULL, TILTED), tx=(2.0, 2.5, 2.2), paths=4096, seed=3)
    doc["room"]["reflectance"] = {"floor": phong(0.9, 0.3, 20.0), "ceiling": 0.5, "walls": mirror(0.6, 0.5)}
    doc["simulation"].pop("max_reflections")
    doc["simulation"].pop("t_max_s")
    res = simulate(spec(doc))
    assert res["modeled"]["pilot"]["rho_max"] == pytest.approx(0.9)
    assert res["links"][0]["dc_gain"] > 0
