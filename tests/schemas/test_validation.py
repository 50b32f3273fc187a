"""Bad input gets a clear, located error; good input parses (schemas/)."""

import copy

import pytest
from pydantic import ValidationError

from owcsim.schemas import SceneSpec
from tests.scenes import barry_doc, room_doc


def _errors(doc) -> str:
    with pytest.raises(ValidationError) as exc:
        SceneSpec.model_validate(doc)
    return "\n".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.value.errors())


def test_example_parses_and_round_trips():
    spec = SceneSpec.model_validate(barry_doc())
    again = SceneSpec.model_validate_json(spec.model_dump_json())
    assert again == spec
    assert spec.transmitters[0].m == 1.0
    assert spec.room.reflectance.by_face()["wall_x_min"] == 0.8


def test_unknown_field_is_located():
    doc = barry_doc()
    doc["receivers"][0]["fov"] = 60
    msg = _errors(doc)
    assert "receivers.0.fov" in msg and "Extra inputs" in msg


@pytest.mark.parametrize("normal", [[0, 0, 0], [0.0, 0.0, 1e-20]])
def test_zero_length_normal(normal):
    doc = barry_doc()
    doc["transmitters"][0]["normal"] = normal
    assert "transmitters.0.normal" in _errors(doc) and "non-zero length" in _errors(doc)


def test_nan_position_rejected():
    doc = barry_doc()
    doc["receivers"][0]["position"] = [float("nan"), 1, 0]
    assert "receivers.0.position" in _errors(doc)


@pytest.mark.parametrize("fov", [0, -5, 90.5, 180])
def test_fov_outside_range(fov):
    doc = barry_doc()
    doc["receivers"][0]["fov_deg"] = fov
    assert "receivers.0.fov_deg" in _errors(doc)


def test_fov_90_is_allowed():
    doc = barry_doc()
    doc["receivers"][0]["fov_deg"] = 90
    SceneSpec.model_validate(doc)


@pytest.mark.parametrize("face,value", [("floor", -0.1), ("walls", 1.01), ("ceiling", float("nan"))])
def test_reflectance_outside_unit_interval(face, value):
    doc = barry_doc()
    doc["room"]["reflectance"][face] = value
    assert f"room.reflectance.{face}" in _errors(doc)


def test_missing_wall_reflectance():
    doc = barry_doc()
    del doc["room"]["reflectance"]["walls"]
    doc["room"]["reflectance"]["wall_x_min"] = 0.5
    assert "wall_x_max" in _errors(doc)


def test_device_outside_room():
    doc = barry_doc()
    doc["receivers"][0]["position"] = [6.0, 1.0, 0.5]
    msg = _errors(doc)
    assert "receivers[0] (rx)" in msg and "outside the room" in msg


def test_device_facing_into_its_wall():
    doc = barry_doc()
    doc["receivers"][0]["normal"] = [0, 0, -1]  # on the floor, looking into it
    assert "faces into it" in _errors(doc)


def test_device_inside_furniture():
    doc = barry_doc()
    doc["furniture"] = [{"name": "desk", "min": [0, 0, 0], "max": [1, 2, 0.8], "reflectance": 0.5}]
    doc["receivers"][0]["position"] = [0.5, 1.0, 0.4]
    assert "inside furniture[0] (desk)" in _errors(doc)


@pytest.mark.parametrize("field,value", [("sigma_a", -0.1), ("sigma_s", -1.0)])
def test_negative_coefficients(field, value):
    doc = barry_doc()
    doc["medium"] = {"type": "homogeneous", "sigma_a": 0.1, "sigma_s": 0.1}
    doc["medium"][field] = value
    assert f"medium.homogeneous.{field}" in _errors(doc)


def test_medium_needs_one_form():
    doc = barry_doc()
    doc["medium"] = {"type": "homogeneous", "sigma_a": 0.1, "sigma_s": 0.1, "visibility_m": 10, "albedo": 0.5}
    assert "either" in _errors(doc)
    doc["medium"] = {"type": "homogeneous", "visibility_m": 10.0, "albedo": 0.5}
    spec = SceneSpec.model_validate(doc)
    assert spec.medium.sigma_t == pytest.approx(0.3912)


def test_hg_g_range():
    doc = barry_doc()
    doc["medium"] = {"type": "homogeneous", "sigma_a": 0.1, "sigma_s": 0.1, "phase": {"type": "hg", "g": 1.0}}
    assert "medium.homogeneous.phase.hg.g" in _errors(doc)


def test_mesh_with_nan_or_no_faces():
    doc = barry_doc()
    doc["meshes"] = [
        {"vertices": [[0, 0, 0], [1, 0, 0], [float("nan"), 1, 0]], "faces": [[0, 1, 2]], "reflectance": 0.5}
    ]
    assert "meshes.0.vertices" in _errors(doc)
    doc["meshes"] = [{"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "faces": [], "reflectance": 0.5}]
    assert "non-empty" in _errors(doc)
    doc["meshes"] = [{"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "faces": [[0, 1, 3]], "reflectance": 0.5}]
    assert "outside 0..2" in _errors(doc)


def test_bin_budget():
    doc = barry_doc(time_bin_s=1e-15, t_max_s=1e-6)
    msg = _errors(doc)
    assert "simulation" in msg and "bins" in msg and "budget" in msg


@pytest.mark.parametrize(
    "field,value,where",
    [
        ("time_bin_s", 1e-300, "simulation.time_bin_s"),
        ("time_bin_s", 5e-324, "simulation.time_bin_s"),
        ("segment_time_step_s", 1e-300, "simulation.segment_time_step_s"),
        ("t_min_s", 1e300, "simulation.t_min_s"),
    ],
)
def test_time_scales_below_a_femtosecond_or_beyond_a_second_are_refused(field, value, where):
    # Unphysical bin widths and window starts: a located error, not an overflowing bin index.
    msg = _errors(barry_doc(**{field: value, "t_max_s": None}))
    assert msg.startswith(where), msg


def test_bin_budget_message_stays_short():
    msg = _errors(barry_doc(time_bin_s=1e-15, t_max_s=1.0))
    assert "1e+15 bins" in msg and "1,000,000" in msg and len(msg) < 300


def test_tally_budget():
    doc = barry_doc(time_bin_s=1e-12, t_max_s=5e-7, max_reflections=200)
    assert "tally cells" in _errors(doc)


def test_paths_and_target_exclusive():
    assert "not both" in _errors(barry_doc(paths=10, target_rel_error=0.01))


def test_transmitter_pattern_exactly_one():
    doc = barry_doc()
    doc["transmitters"][0]["half_power_semi_angle_deg"] = 60
    assert "exactly one" in _errors(doc)
    del doc["transmitters"][0]["lambertian_order"]
    spec = SceneSpec.model_validate(doc)
    assert spec.transmitters[0].m == pytest.approx(1.0)  # Phi_1/2 = 60 deg <=> m = 1


def test_no_receiver():
    doc = barry_doc()
    doc["receivers"] = []
    assert "no receiver" in _errors(doc)


def test_duplicate_ids():
    doc = barry_doc()
    doc["receivers"].append(copy.deepcopy(doc["receivers"][0]))
    assert "duplicate ids" in _errors(doc)


def test_receiver_grid_expands():
    doc = room_doc()
    doc["receiver_grids"] = [{"origin": [0.5, 0.5, 0.85], "size": [4.0, 4.0], "spacing": 1.0, "area": 1e-4}]
    spec = SceneSpec.model_validate(doc)
    rx = spec.all_receivers()
    assert len(rx) == 1 + 25
    assert spec.receiver_ids()[1] == "grid[0,0]" and rx[-1].position == (4.5, 4.5, 0.85)


@pytest.mark.parametrize(
    "field,value,message",
    [
        ("half_power_semi_angle_deg", 1e-300, "above 10000"),
        ("half_power_semi_angle_deg", 0.5, "above 10000"),
    ],
)
def test_extreme_half_power_angle_is_an_error_not_a_crash(field, value, message):
    doc = barry_doc()
    del doc["transmitters"][0]["lambertian_order"]
    doc["transmitters"][0][field] = value
    assert message in _errors(doc)


def test_tiny_grid_spacing_is_an_error_not_a_crash():
    doc = room_doc()
    doc["receiver_grids"] = [{"origin": [0.5, 0.5, 0.85], "size": [4.0, 4.0], "spacing": 5e-324, "area": 1e-4}]
    assert "100000 receivers" in _errors(doc)


def test_tiny_fov_is_bounded():
    doc = barry_doc()
    doc["receivers"][0].update(fov_deg=1e-300, concentrator_index=1.5)
    assert "receivers.0.fov_deg" in _errors(doc)


@pytest.mark.parametrize(
    "path,where",
    [
        (("transmitters", 0, "power"), "transmitters.0.power"),
        (("simulation", "time_bin_s"), "simulation.time_bin_s"),
        (("receivers", 0, "area"), "receivers.0.area"),
    ],
)
def test_infinite_numbers_are_located_errors(path, where):
    # JSON readers accept `Infinity`; the schema does not (it used to reach the engine, or the store as null).
    doc = barry_doc()
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = float("inf")
    assert where + ": Input should be a finite number" in _errors(doc)


def test_infinite_grid_spacing_and_mixture_weight_are_located():
    doc = barry_doc()
    doc["receiver_grids"] = [{"origin": [1, 1, 0.5], "size": [1, 1], "spacing": float("inf"), "area": 1e-4}]
    assert "receiver_grids.0.spacing: Input should be a finite number" in _errors(doc)
    doc = barry_doc()
    doc["medium"] = {
        "type": "homogeneous",
        "sigma_a": 0.01,
        "sigma_s": 0.1,
        "phase": {"type": "mixture", "components": [{"weight": float("inf"), "phase": {"type": "isotropic"}}]},
    }
    assert "components.0.weight: Input should be a finite number" in _errors(doc)
