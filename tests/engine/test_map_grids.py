"""Receiver grids on any plane and of any rectangle (issue 24 item 6): counts or steps per axis, tilted and
vertical planes with their default normal, exclude / include areas; old documents give the same bits.

References are built here: positions from the grid's definition in plain Python, the line of sight of a
Lambertian source point by point (closed form), and masks by half-plane tests of convex areas.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from owcsim.engine.scene.scene import build_scene, grid_points
from owcsim.formats.maps import maps_of_result
from owcsim.schemas import SceneSpec
from owcsim.schemas.devices import ReceiverGridSpec
from owcsim.schemas.results import SimulationResultPublic
from tests.results import simulate_document as simulate
from tests.scenes import room_doc

TX = np.array([2.0, 1.5, 2.8])  # a Lambertian (m = 1) lamp facing down in the 5 x 5 x 3 m room


def _grid(**kw) -> ReceiverGridSpec:
    return ReceiverGridSpec.model_validate({"origin": [0.5, 0.5, 0.85], "area": 1e-4, **kw})


def _los(points: np.ndarray, normal: np.ndarray, area: float = 1e-4, m: float = 1.0) -> np.ndarray:
    """H_los = (m+1)/(2 pi) cos^m(phi) A cos(psi) / d^2 point by point (FOV 90 deg), the lamp facing down."""
    out = []
    for p in points:
        w = TX - p
        d = math.sqrt(float(w @ w))
        cos_phi, cos_psi = w[2] / d, float(w @ normal) / d
        out.append((m + 1) / (2 * math.pi) * cos_phi**m * area * cos_psi / d**2 if cos_phi > 0 and cos_psi > 0 else 0.0)
    return np.array(out)


def _los_doc(grid: dict) -> dict:
    doc = room_doc(tx=tuple(TX), max_reflections=0)
    del doc["receivers"]
    doc["receiver_grids"] = [grid]
    return doc


def test_a_single_spacing_gives_the_same_points_and_bits_as_before():
    g = _grid(size=[3.0, 2.0], spacing=0.25, u=[1, 1, 0], v=[-1, 1, 0])
    pos, shape = grid_points(g)
    u, v = np.array([1, 1, 0]) / math.sqrt(2), np.array([-1, 1, 0]) / math.sqrt(2)
    i, j = np.meshgrid(np.arange(13), np.arange(9), indexing="ij")
    old = np.array([0.5, 0.5, 0.85]) + 0.25 * (i.reshape(-1, 1) * u + j.reshape(-1, 1) * v)  # the formula before
    assert shape == (13, 9) and g.shape == (13, 9)
    np.testing.assert_array_equal(pos, old)  # the same bits
    assert g.receiver_normal == (0.0, 0.0, 1.0)  # a horizontal plane faces up, exactly as the old default
    np.testing.assert_array_equal(
        grid_points(_grid(size=[3.0, 2.0], spacing=[0.25, 0.25], u=[1, 1, 0], v=[-1, 1, 0]))[0], old
    )
    assert g.point(12, 8).position == tuple(old[-1])


def test_counts_spread_points_over_the_size_including_both_ends():
    g = _grid(size=[4.0, 3.0], shape=[50, 31])
    pos, shape = grid_points(g)
    assert shape == (50, 31) and g.count == 1550 and g.steps == (4.0 / 49, 0.1)
    ref = np.array(
        [[0.5 + i * 4.0 / 49, 0.5 + j * 3.0 / 30, 0.85] for i in range(50) for j in range(31)]
    )  # plain Python from the definition
    np.testing.assert_allclose(pos, ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(pos[-1], [4.5, 3.5, 0.85], rtol=0, atol=1e-12)  # the far corner is a point
    assert g.model_dump()["shape"] == (50, 31) and ReceiverGridSpec.model_validate(g.model_dump()) == g
    rect = _grid(size=[4.0, 3.0], spacing=[0.5, 0.3])
    assert rect.shape == (9, 11) and rect.steps == (0.5, 0.3)
    line = _grid(size=[4.0, 0.0], shape=[5, 1])
    assert line.shape == (5, 1) and grid_points(line)[0][:, 1].tolist() == [0.5] * 5


@pytest.mark.parametrize(
    "grid, message",
    [
        ({"size": [1, 1]}, "give the grid's `spacing`"),
        ({"size": [1, 1], "spacing": 0.1, "shape": [3, 3]}, "give the grid's `spacing`"),
        ({"size": [1, 1], "shape": [1, 3]}, "one point along u spans no extent"),
        ({"size": [1, 0], "shape": [3, 3]}, "3 points along v need a positive size"),
        ({"size": [1, 1], "shape": [0, 3]}, "at least 1 point along u"),
        ({"size": [1, 1], "shape": [400, 400]}, "more than the 100000 allowed"),
        ({"size": [1, 1], "spacing": [0.1, -0.1]}, "greater than 0"),
        ({"size": [1, 1], "spacing": [0.1, 0.1, 0.1]}, "give one step or two"),
        (
            {"size": [1, 1], "spacing": 0.1, "u": [1, 0, 0], "v": [0, 0, 1], "normal": [0, 0, 1]},
            "lies in the grid's plane",
        ),
        ({"size": [1, 1], "spacing": 0.1, "exclude": [{"min": [0.5, 0.5], "max": [0.2, 0.9]}]}, "must exceed `min`"),
        ({"size": [1, 1], "spacing": 0.1, "exclude": [{"min": [0, 0]}]}, "needs both `min` and `max`"),
        (
            {
                "size": [1, 1],
                "spacing": 0.1,
                "include": [{"min": [0, 0], "max": [1, 1], "polygon": [[0, 0], [1, 0], [0, 1]]}],
            },
            "not both or neither",
        ),
    ],
)
def test_bad_grids_are_refused_with_one_sentence(grid, message):
    with pytest.raises(ValidationError, match=message) as err:
        _grid(**grid)
    assert "Traceback" not in str(err.value)


def test_default_normal_is_u_cross_v_facing_up_unless_vertical():
    wall = _grid(size=[1, 1], spacing=0.5, u=[0, 0, 1], v=[1, 0, 0])  # u x v = +y: the wall at y = const
    assert wall.receiver_normal == pytest.approx((0.0, 1.0, 0.0), abs=1e-15)
    other = _grid(size=[1, 1], spacing=0.5, u=[1, 0, 0], v=[0, 0, 1])  # u x v = -y, kept: a vertical plane
    assert other.receiver_normal == pytest.approx((0.0, -1.0, 0.0), abs=1e-15)
    tilted = _grid(size=[1, 1], spacing=0.5, u=[0, 1, 0], v=[1, 0, 1])  # u x v = (1, 0, -1)/sqrt 2: turned up
    assert tilted.receiver_normal == pytest.approx((-(0.5**0.5), 0.0, 0.5**0.5), abs=1e-15)
    ceiling = _grid(size=[1, 1], spacing=0.5, u=[0, 1, 0], v=[1, 0, 0], normal=[0, 0, -1])  # given: kept
    assert ceiling.receiver_normal == (0.0, 0.0, -1.0)


def test_los_map_on_a_rectangular_grid_equals_the_closed_form():
    doc = _los_doc({"id_prefix": "wp", "origin": [0.2, 0.3, 0.85], "size": [4.6, 4.4], "shape": [24, 9], "area": 1e-4})
    res = simulate(SceneSpec.model_validate(doc))
    m = res["maps"][0]
    su, sv = 4.6 / 23, 4.4 / 8
    assert m["shape"] == [24, 9] or tuple(m["shape"]) == (24, 9)
    assert m["spacing"] is None and m["spacing_uv"] == pytest.approx((su, sv), rel=1e-15)
    pts = np.array([[0.2 + i * su, 0.3 + j * sv, 0.85] for i in range(24) for j in range(9)])
    ref = _los(pts, np.array([0.0, 0.0, 1.0]))
    got = np.array(m["values"]["dc_gain"], float).ravel()
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=0)
    assert not np.allclose(got, 1.1 * ref, rtol=1e-3)  # power: a 10 % error would show
    gm = maps_of_result(SimulationResultPublic.model_validate(res))[0][0]
    np.testing.assert_allclose(gm.positions.reshape(-1, 3), pts, rtol=0, atol=1e-12)


def test_los_map_on_a_wall_and_on_a_tilted_plane_equals_the_closed_form():
    # The wall y = 0.01 (just off the wall y = 0), facing into the room (+y = u x v by default).
    wall = {"id_prefix": "wall", "origin": [0.5, 0.01, 0.2], "u": [0, 0, 1], "v": [1, 0, 0], "size": [2.4, 4.0]}
    tilted = {"id_prefix": "shelf", "origin": [3.0, 1.0, 0.5], "u": [0, 1, 0], "v": [1, 0, 1], "size": [2.0, 1.2]}
    for grid, n in ((wall, (0.0, 1.0, 0.0)), (tilted, (-(0.5**0.5), 0.0, 0.5**0.5))):
        doc = _los_doc({**grid, "spacing": [0.3, 0.4], "area": 1e-4})
        res = simulate(SceneSpec.model_validate(doc))
        m = res["maps"][0]
        nu, nv = m["shape"]
        o, u, v = np.array(grid["origin"], float), np.array(grid["u"], float), np.array(grid["v"], float)
        u, v = u / np.linalg.norm(u), v / np.linalg.norm(v)
        pts = np.array([o + 0.3 * i * u + 0.4 * j * v for i in range(nu) for j in range(nv)])
        assert m["normal"] == pytest.approx(n, abs=1e-15) and res["receivers"][0]["normal"] == pytest.approx(n)
        ref = _los(pts, np.array(n))
        got = np.array(m["values"]["dc_gain"], float).ravel()
        assert (ref > 0).sum() > nu * nv // 2
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-300)


def _inside_convex(p, poly) -> bool:
    """Closed convex polygon (counter-clockwise): on the inner side of every edge (within 1e-12)."""
    k = len(poly)
    for a in range(k):
        (x1, y1), (x2, y2) = poly[a], poly[(a + 1) % k]
        if (x2 - x1) * (p[1] - y1) - (y2 - y1) * (p[0] - x1) < -1e-12:
            return False
    return True


def test_exclude_and_include_areas_mask_exactly_the_points_inside():
    tri = [[0.0, 0.0], [2.0, 0.0], [0.0, 2.0]]
    grid = {
        "origin": [0.5, 0.5, 0.85],
        "size": [4.0, 4.0],
        "spacing": 0.25,
        "area": 1e-4,
        "include": [{"min": [0.0, 0.0], "max": [3.0, 4.0]}],
        "exclude": [{"polygon": tri}, {"min": [2.5, 2.5], "max": [3.5, 3.0]}],
    }
    doc = _los_doc(grid)
    spec = SceneSpec.model_validate(doc)
    scene = build_scene(spec)
    reasons = scene.masked.tolist()
    want = []
    for i in range(17):
        for j in range(17):
            a, b = 0.25 * i, 0.25 * j
            if _inside_convex((a, b), tri):
                want.append("in the grid's exclude[0]")
            elif 2.5 <= a <= 3.5 and 2.5 <= b <= 3.0:
                want.append("in the grid's exclude[1]")
            elif a > 3.0:
                want.append("outside the grid's include areas")
            else:
                want.append("")
    assert reasons == want
    assert want.count("in the grid's exclude[0]") == 45  # the triangle's 9 + 8 + ... + 1 points, edges included
    res = simulate(spec)
    values = np.array(res["maps"][0]["values"]["dc_gain"], float).ravel()
    np.testing.assert_array_equal(np.isnan(values), np.array(want) != "")  # masked: null, not simulated
    assert [r["masked"] or "" for r in res["receivers"]] == want


def test_a_non_convex_include_polygon_keeps_exactly_the_points_inside():
    """An L-shaped room plan: the union of two rectangles, edges included, is the reference."""
    ell = [[0.0, 0.0], [4.0, 0.0], [4.0, 1.5], [1.5, 1.5], [1.5, 4.0], [0.0, 4.0]]
    grid = {"origin": [0.5, 0.5, 0.85], "size": [4.0, 4.0], "shape": [17, 17], "area": 1e-4}
    scene = build_scene(SceneSpec.model_validate(_los_doc({**grid, "include": [{"polygon": ell}]})))
    kept = []
    for i in range(17):
        for j in range(17):
            a, b = 0.25 * i, 0.25 * j
            kept.append((0 <= a <= 4 and 0 <= b <= 1.5) or (0 <= a <= 1.5 and 0 <= b <= 4))
    assert (scene.masked == "").tolist() == kept and 0 < sum(kept) < 17 * 17


def test_orientation_samples_of_an_excluded_point_are_masked_with_it():
    """A grid with random orientation (issue 24 item 5): an excluded point's hidden samples are not simulated
    either, and its orientation figures are null, while the other points keep theirs."""
    grid = {
        "origin": [0.5, 0.5, 0.85],
        "size": [1.0, 1.0],
        "spacing": 0.5,
        "area": 1e-4,
        "exclude": [{"min": [0.0, 0.0], "max": [0.6, 0.6]}],  # points (0, 0), (0, 1), (1, 0), (1, 1)
        "orientation": {"model": "walking", "samples": 4},
    }
    spec = SceneSpec.model_validate(_los_doc(grid))
    scene = build_scene(spec)
    own = scene.masked[:9].tolist()
    assert [r != "" for r in own] == [True, True, False, True, True, False, False, False, False]
    hidden = scene.masked[9:].reshape(9, 4)
    assert (hidden == np.array(own, dtype=object)[:, None]).all()  # each point's 4 samples share its reason
    res = simulate(spec)
    mean = np.array(res["maps"][0]["values"]["received_power_mean_w"], float).ravel()
    assert np.isnan(mean[[0, 1, 3, 4]]).all() and np.isfinite(mean[[2, 5, 6, 7, 8]]).all()
