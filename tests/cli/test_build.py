"""owcsim.build: the builders give the scene document's models (checked against a bundled example)."""

import json
from pathlib import Path

import pytest
from pydantic import ValidationError

from owcsim import build
from owcsim.schemas import SceneSpec

ROOT = Path(__file__).resolve().parents[2]


def test_builders_reproduce_the_barry_example():
    doc = json.loads((ROOT / "examples" / "barry_config_a.json").read_text())
    expected = SceneSpec.model_validate(doc)
    room = build.box_room((5, 5, 3), walls=0.8, floor=0.3, ceiling=0.8)
    tx = build.lamp((2.5, 2.5, 3.0), lambertian_order=1, id="tx")
    rx = build.photodiode((0.5, 1.0, 0.0), area=1e-4, fov_deg=85, id="rx")
    got = build.scene(room, [tx], [rx], name=expected.name, **doc["simulation"])
    assert got.model_copy(update={"description": expected.description}) == expected
    # a change the comparison must see
    assert (
        build.scene(
            room,
            [tx],
            [build.photodiode((0.5, 1.0, 0.0), fov_deg=80, id="rx")],
            name=expected.name,
            **doc["simulation"],
        )
        != got
    )


def test_work_plane_spans_the_room_inside_its_margin():
    room = build.box_room((6, 4, 3), origin=(1, 2, 0))
    grid = build.work_plane(room, height=0.85, spacing=0.5, margin=0.5)
    assert grid.origin == (1.5, 2.5, 0.85) and grid.size == (5.0, 3.0) and grid.normal == (0.0, 0.0, 1.0)


def test_a_lamp_without_pattern_is_lambertian_and_bad_values_are_located():
    assert build.lamp((1, 1, 3)).lambertian_order == 1.0
    assert build.lamp((1, 1, 3), half_power_semi_angle_deg=60).lambertian_order is None
    with pytest.raises(ValidationError, match="area"):
        build.photodiode((1, 1, 0), area=-1e-4)
    with pytest.raises(ValidationError, match="size"):
        build.box_room((5, -5, 3))


def test_builders_reproduce_the_komine_office_with_lamp_array_group_and_work_plane():
    doc = json.loads((ROOT / "examples" / "komine_map.json").read_text())
    expected = SceneSpec.model_validate(doc)
    room = build.box_room((5, 5, 3), walls=0.8, floor=0.3, ceiling=0.8)
    lamps = build.lamp_array(
        room, (2, 2), half_power_semi_angle_deg=70, power=72.0, luminous_output={"center_luminous_intensity": 2628.0}
    )
    assert [t.position[:2] for t in lamps] == [(1.25, 1.25), (1.25, 3.75), (3.75, 1.25), (3.75, 3.75)]
    grid = build.work_plane(room, height=0.85, spacing=0.1, margin=0.05, fov_deg=85, id_prefix="plane")
    got = build.scene(
        room,
        lamps,
        grids=[grid],
        groups=[build.group("ceiling", lamps)],
        link_budget=doc["link_budget"],
        name=expected.name,
        **doc["simulation"],
    )
    assert got.model_copy(update={"description": expected.description}) == expected
    assert got.model_copy(update={"transmitter_groups": [build.group("ceiling", ["led1", "led2"])]}) != got


def test_work_plane_of_a_non_square_room_gets_50_x_50_points_edge_to_edge():
    room = build.box_room((6, 4, 3), origin=(1, 2, 0))
    grid = build.work_plane(room, shape=(50, 50), margin=0.5)
    assert grid.shape == (50, 50) and grid.steps == pytest.approx((5 / 49, 3 / 49), rel=1e-15)
    assert grid.point(49, 49).position == pytest.approx((6.5, 5.5, 0.85), abs=1e-12)  # the far corner
    rect = build.work_plane(room, spacing=(0.5, 0.25), margin=0.5)
    assert rect.shape == (11, 13)
    masked = build.work_plane(room, spacing=0.5, exclude=[{"min": [0, 0], "max": [1, 1]}])
    assert masked.exclude[0].max == (1.0, 1.0)
    with pytest.raises(ValueError, match="`spacing`"):
        build.work_plane(room, spacing=0.5, shape=(3, 3))


@pytest.mark.parametrize("wall", ["x_min", "x_max", "y_min", "y_max"])
def test_wall_grids_lie_on_their_wall_and_face_into_the_room(wall):
    room = build.box_room((6, 4, 3), origin=(1, 2, 0))
    grid = build.wall_grid(room, wall, shape=(7, 4), margin=0.2, offset=0.01)
    axis, high = {"x_min": (0, 0), "x_max": (0, 1), "y_min": (1, 0), "y_max": (1, 1)}[wall]
    plane = (room.lo, room.hi)[high][axis] + (-0.01 if high else 0.01)
    pts = grid.expand()
    assert all(p.position[axis] == pytest.approx(plane, abs=1e-12) for p in pts)
    centre = [(a + b) / 2 for a, b in zip(room.lo, room.hi)]
    assert all(sum(n * (c - x) for n, c, x in zip(p.normal, centre, p.position)) > 0 for p in pts)  # into the room
    heights = sorted({round(p.position[2], 12) for p in pts})
    assert heights[0] == pytest.approx(0.2) and heights[-1] == pytest.approx(2.8) and len(heights) == 4
    spec = build.scene(room, [build.lamp((3, 3, 3))], grids=[grid], max_reflections=0)
    assert spec.receiver_grids[0].id_prefix == f"wall_{wall}"


def test_furniture_spectra_and_groups_are_checked_on_the_spot():
    desk = build.furniture((1, 1, 0), (2.6, 1.8, 0.75), reflectance=0.4, name="desk")
    assert desk.max == (2.6, 1.8, 0.75)
    with pytest.raises(ValidationError, match="max"):
        build.furniture((1, 1, 0), (0.5, 1.8, 0.75))
    assert build.spectrum("white_led_cool").name == "white_led_cool"
    table = build.spectrum(wavelengths=[400e-9, 700e-9], values=[0.2, 0.9])
    assert table.type == "table" and table.values == [0.2, 0.9]
    with pytest.raises(ValidationError):
        build.spectrum("daylight")
    with pytest.raises(ValidationError, match="strictly increasing"):
        build.spectrum(wavelengths=[700e-9, 400e-9], values=[0.2, 0.9])
    with pytest.raises(ValueError, match="`name`, or its `wavelengths`"):
        build.spectrum()
    with pytest.raises(ValueError, match="has no `id`"):
        build.group("cell", [build.lamp((1, 1, 3))])
    bands = build.bands(380e-9, 780e-9, 4)
    assert bands.band_edges == pytest.approx([380e-9, 480e-9, 580e-9, 680e-9, 780e-9])
    room = build.box_room(
        (5, 5, 3), walls=build.spectral_surface(build.spectrum("white_paint")), floor=0.3, ceiling=0.8
    )
    lamps = build.lamp_array(room, (1, 2), spectrum=build.spectrum("white_led_warm"))
    spec = build.scene(
        room,
        lamps,
        [build.photodiode((2.5, 2.5, 0.85))],
        furniture=[desk],
        groups=[build.group("cells", lamps)],
        spectral=bands,
        paths=1000,
    )
    assert spec.furniture == [desk] and spec.transmitter_groups[0].transmitters == ["led1", "led2"]
    with pytest.raises(ValidationError, match="inside furniture"):
        build.scene(room, lamps, [build.photodiode((1.5, 1.5, 0.5))], furniture=[desk], spectral=bands)
