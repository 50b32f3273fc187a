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
