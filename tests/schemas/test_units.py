"""Values plausible only in another unit warn (schemas/units.py; issue 22, item 8).

A room in centimetres, a field of view or half-power semi-angle in radians, a time bin in
nanoseconds: valid documents that ran silently. Each warns with one sentence naming the field, in
the result's `warnings` (API), on `owcsim run` and `owcsim validate`; the bundled examples and a
normal scene do not.
"""

import json
from pathlib import Path

import pytest

from owcsim.api import simulate
from owcsim.cli import main
from owcsim.schemas import SceneSpec
from owcsim.schemas.units import ANGLE_MIN_DEG, LENGTH_MAX_M, unit_warnings
from tests.scenes import barry_doc, room_doc

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _centimetre_room() -> dict:
    """Barry configuration A with every length in centimetres."""
    doc = room_doc(size=(500, 400, 300), tx=(250, 200, 300), rx=(100, 100, 0), max_reflections=1, paths=2000)
    doc["furniture"] = [{"name": "desk", "min": [100, 60, 72], "max": [260, 140, 76], "reflectance": 0.5}]
    return doc


def _warned(doc) -> list[str]:
    return unit_warnings(SceneSpec.model_validate(doc))


def test_a_room_in_centimetres_warns():
    notes = _warned(_centimetre_room())
    assert len(notes) == 2
    assert notes[0].startswith("room.size = 500 x 400 x 300 m: a room side over 100 m is unusual")
    assert "furniture[0] (desk)" in notes[1] and "centimetres" in notes[1]


def test_a_field_of_view_in_radians_warns():
    doc = room_doc()
    doc["receivers"][0]["fov_deg"] = 1.48
    doc["receiver_grids"] = [
        {"origin": [1, 1, 0.8], "size": [1, 1], "spacing": 0.5, "area": 1e-4, "fov_deg": 1.48, "id_prefix": "g"}
    ]
    (note,) = _warned(doc)  # one sentence for the value, naming both
    assert note == (
        "fov_deg = 1.48 of receivers[0] (rx), receiver_grids[0] (g): a field of view under 2 deg is unusual; "
        "the field is in degrees (1.48 rad would be 84.8 deg)"
    )


def test_a_half_power_semi_angle_in_radians_warns():
    doc = room_doc()
    del doc["transmitters"][0]["lambertian_order"]
    doc["transmitters"][0]["half_power_semi_angle_deg"] = 1.047
    (note,) = _warned(doc)
    assert note.startswith("half_power_semi_angle_deg = 1.047 of transmitters[0] (tx): a half-power semi-angle")
    assert "(Lambertian order 4.15e+03)" in note and "(1.047 rad would be 59.99 deg, order 1)" in note


def test_time_settings_in_nanoseconds_warn():
    notes = _warned(room_doc(time_bin_s=0.25, t_max_s=100.0))
    assert [n.split(" = ")[0] for n in notes] == ["simulation.time_bin_s", "simulation.t_max_s"]


@pytest.mark.parametrize(
    "field, value",
    [("fov_deg", ANGLE_MIN_DEG), ("size", (LENGTH_MAX_M, 5.0, 3.0)), ("fov_deg", 5.0)],
    ids=["fov at the threshold", "room side at the threshold", "a narrow fov"],
)
def test_values_at_the_thresholds_do_not_warn(field, value):
    doc = room_doc(**({"size": value} if field == "size" else {}))
    if field == "fov_deg":
        doc["receivers"][0]["fov_deg"] = value
    assert _warned(doc) == []


@pytest.mark.parametrize("path", sorted(EXAMPLES.glob("*.json")), ids=lambda p: p.stem)
def test_the_examples_do_not_warn(path):
    assert _warned(json.loads(path.read_text())) == []


def test_a_mesh_file_in_millimetres_warns_from_the_built_extent():
    doc = room_doc()
    notes = unit_warnings(SceneSpec.model_validate(doc), extent_m=5000.0)
    assert notes == [
        "the surfaces span 5000 m, over 100 m: unusual for an indoor scene; mesh coordinates are read as "
        "metres (were millimetres or centimetres meant?)"
    ]
    assert unit_warnings(SceneSpec.model_validate(doc), extent_m=5.0) == []


def test_the_warnings_reach_the_result_and_the_command_line(tmp_path, capsys):
    doc = _centimetre_room()
    doc["receivers"][0]["fov_deg"] = 1.48
    expected = _warned(doc)
    assert len(expected) == 3
    result = simulate(doc)  # the API's result
    assert all(note in result.warnings for note in expected)
    scene = tmp_path / "cm.json"
    scene.write_text(json.dumps(doc))
    assert main(["validate", str(scene)]) == 0  # warnings, not errors
    err = capsys.readouterr().err
    assert all(f"owcsim: warning: {note}" in err for note in expected)
    assert main(["run", str(scene), "--out", str(tmp_path / "out"), "--paths", "500"]) == 0
    err = capsys.readouterr().err
    assert all(f"owcsim: warning: {note}" in err for note in expected)


def test_a_normal_scene_gets_no_unit_warning(tmp_path, capsys):
    result = simulate(barry_doc(paths=2000, max_reflections=1))
    # K = 1 leaves out a large share of H0, which the result says (engine/results/result.py); no unit warning
    assert [w for w in result.warnings if "in the orders above K = 1" not in w] == []
    assert main(["validate", str(EXAMPLES / "barry_config_a.json")]) == 0
    assert "warning" not in capsys.readouterr().err
