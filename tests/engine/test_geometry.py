"""Meshes, furniture and shadow rays: the same physics whatever way the surfaces are given."""

import base64
import math
import warnings

import numpy as np
import pytest
import trimesh

from owcsim.engine.core.errors import SceneError
from owcsim.engine.scene.geometry import build_geometry
from owcsim.engine.scene.scene import build_scene
from tests.results import simulate_document as simulate
from tests.scenes import room_doc, spec, within


def _room_as_mesh(size=(5.0, 5.0, 3.0), rho=0.8):
    """The box room as an inline triangle mesh (outward winding: surfaces are two-sided)."""
    box = trimesh.creation.box(extents=size)
    box.apply_translation(np.asarray(size) / 2)
    return {"vertices": box.vertices.tolist(), "faces": box.faces.tolist(), "reflectance": rho}


def _link(doc):
    return simulate(spec(doc))["links"][0]


def test_mesh_room_equals_parametric_room():
    """Same room, once as a box (shadow rays skipped: convex) and once as a mesh (shadow rays cast)."""
    base = dict(
        rho_walls=0.8, rho_floor=0.8, rho_ceiling=0.8, max_reflections=4, paths=40_000, seed=21, direction="forward"
    )
    box = _link(room_doc(**base))
    doc = room_doc(**base)
    del doc["room"]
    doc["meshes"] = [_room_as_mesh()]
    mesh = _link(doc)
    assert mesh["los_gain"] == pytest.approx(box["los_gain"], rel=1e-12)
    assert within(mesh["dc_gain"], box["dc_gain"], math.hypot(mesh["dc_gain_stderr"], box["dc_gain_stderr"]))


def test_furniture_forward_backward_agree():
    """Shadow rays in both directions: a bright cabinet beside the receiver shadows and reflects."""
    base = dict(rx=(1.0, 1.0, 0.0), max_reflections=4, paths=60_000, seed=8)
    docs = {d: room_doc(direction=d, **base) for d in ("forward", "backward")}
    for doc in docs.values():
        doc["furniture"] = [
            {"name": "cabinet", "min": [1.2, 0.0, 0.0], "max": [2.0, 2.5, 2.0], "reflectance": 0.9},
            {"name": "desk", "min": [0.0, 1.5, 0.0], "max": [1.0, 2.5, 0.8], "reflectance": 0.6},
        ]
    f, b = _link(docs["forward"]), _link(docs["backward"])
    assert f["los_gain"] == 0.0  # the cabinet blocks the line of sight
    clear = _link(room_doc(direction="backward", **base))
    assert b["dc_gain"] < 0.8 * clear["dc_gain"]  # the shadow is real
    assert within(f["dc_gain"], b["dc_gain"], math.hypot(f["dc_gain_stderr"], b["dc_gain_stderr"]))
    assert f["dc_gain_stderr"] < 0.03 * f["dc_gain"]


def test_obj_file_groups_get_their_reflectance(tmp_path):
    scene = trimesh.Scene()
    desk = trimesh.creation.box(extents=[1, 1, 0.8])
    desk.apply_translation([3.5, 3.5, 0.4])
    lamp = trimesh.creation.box(extents=[0.2, 0.2, 0.2])
    lamp.apply_translation([1.0, 4.0, 0.1])
    scene.add_geometry(desk, geom_name="desk")
    scene.add_geometry(lamp, geom_name="lamp")
    (tmp_path / "furniture.obj").write_text(scene.export(file_type="obj"))
    doc = room_doc()
    doc["meshes"] = [{"file": "furniture.obj", "reflectance": 0.2, "group_reflectance": {"desk": 0.7}}]
    geo = build_geometry(spec(doc), tmp_path)
    names = np.asarray(geo.group_names)[geo.group]
    rho = geo.reflectance
    assert np.all(rho[np.char.endswith(names.astype(str), ".desk")] == 0.7)
    assert np.all(rho[np.char.endswith(names.astype(str), ".lamp")] == 0.2)
    assert len(geo.faces) == 12 + 24
    # the same file as base64 content gives the same triangles
    doc["meshes"] = [
        {
            "data_base64": base64.b64encode((tmp_path / "furniture.obj").read_bytes()).decode(),
            "format": "obj",
            "reflectance": 0.2,
            "group_reflectance": {"desk": 0.7},
        }
    ]
    geo2 = build_geometry(spec(doc), None)
    assert np.array_equal(geo2.reflectance, geo.reflectance)


def test_unknown_group_and_missing_file_are_errors(tmp_path):
    doc = room_doc()
    doc["meshes"] = [{"file": "nowhere.obj", "reflectance": 0.2}]
    with pytest.raises(SceneError, match="not found"):
        build_geometry(spec(doc), tmp_path)
    (tmp_path / "bad.stl").write_text("this is not an STL file")
    doc["meshes"] = [{"file": "bad.stl", "reflectance": 0.2}]
    with pytest.raises(SceneError, match="meshes\\[0\\]"):
        build_geometry(spec(doc), tmp_path)
    box = trimesh.creation.box()
    (tmp_path / "box.obj").write_text(box.export(file_type="obj"))
    doc["meshes"] = [{"file": "box.obj", "reflectance": 0.2, "group_reflectance": {"sofa": 0.5}}]
    with pytest.raises(SceneError, match="sofa"):
        build_geometry(spec(doc), tmp_path)


def test_degenerate_triangles_dropped_with_warning():
    doc = room_doc()
    doc["meshes"] = [
        {
            "vertices": [[1, 1, 1], [2, 1, 1], [3, 1, 1], [1, 2, 1]],
            "faces": [[0, 1, 2], [0, 1, 3]],
            "reflectance": 0.5,
            "name": "shelf",
        }
    ]
    with pytest.warns(UserWarning, match="dropped 1 degenerate"):
        geo = build_geometry(spec(doc))
    assert len(geo.faces) == 13


def test_intersector_far_from_origin_hits_precisely():
    shift = np.array([5000.0, 5000.0, 0.0])
    doc = room_doc(origin=shift, tx=shift + (2.5, 2.5, 3.0), rx=shift + (1.0, 1.0, 0.0))
    scene = build_scene(spec(doc))
    origins = np.tile(shift + (2.5, 2.5, 1.5), (4, 1))
    dirs = np.array([[1, 0, 0], [0, -1, 0], [0, 0, 1], [0.6, 0.0, -0.8]], float)
    prim, t = scene.intersector.intersect(origins, dirs)
    assert np.all(prim >= 0)
    assert t == pytest.approx([2.5, 2.5, 1.5, 1.875], abs=1e-5)


def test_open_scene_no_surfaces_is_los_only():
    doc = room_doc(max_reflections=3, paths=256, direction="forward")
    del doc["room"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = simulate(spec(doc))
    link = res["links"][0]
    assert link["dc_gain"] == link["los_gain"] > 0
    assert res["diagnostics"]["escaped_power"]["tx"] == pytest.approx(1.0)  # every emitted watt leaves


@pytest.mark.parametrize(
    "change",
    [
        {"room": {"size": [1e6, 1e6, 3.0]}},
        {"room": {"size": [5.0, 5.0, 3e5]}},
        {
            "meshes": [
                {"vertices": [[1e300, 0, 0], [0, 1e300, 0], [0, 0, 1e300]], "faces": [[0, 1, 2]], "reflectance": 0.5}
            ]
        },
        {
            "meshes": [
                {"vertices": [[1e30, 0, 0], [0, 1e30, 0], [1e30, 1e30, 1e30]], "faces": [[0, 1, 2]], "reflectance": 0.5}
            ]
        },
    ],
)
def test_scene_too_large_for_float32_tracing_is_refused(change):
    # A distant mesh used to shrink the room into float32 noise (H0 = 0, silently); now a located error.
    doc = room_doc()
    for key, value in change.items():
        doc[key] = {**doc[key], **value} if key == "room" else value
    with pytest.raises(SceneError, match=r"span [0-9.e+]+ m, more than the 2000 m"):
        build_scene(spec(doc))


def test_a_mesh_a_kilometre_away_leaves_the_room_result_unchanged():
    far = {"vertices": [[1000, 0, 0], [1001, 0, 0], [1000, 1, 0]], "faces": [[0, 1, 2]], "reflectance": 0.5}
    base = _link(room_doc(paths=8192, seed=2))
    doc = room_doc(paths=8192, seed=2)
    doc["meshes"] = [far]
    with_far = _link(doc)
    # The same estimator on a coarser float32 grid: equal within the error bars.
    assert within(with_far["dc_gain"], base["dc_gain"], math.hypot(base["dc_gain_stderr"], with_far["dc_gain_stderr"]))
