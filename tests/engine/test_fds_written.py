"""Frames from small FDS cases written in FDS's formats (tests/fds_writer.py), read back through fdsreader.

Values written are the values read (exact: float32 in, float64 out), meshes are joined where they belong,
the origin moves the grid, obstructions are masked, node data becomes the 8-node mean, bad input is refused.
"""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import TypeAdapter, ValidationError

from owcsim.engine.core.errors import SceneError
from owcsim.engine.core.lazy import LazyModule
from owcsim.engine.media import fds as fds_module
from owcsim.engine.media.frame_sources import frames_from_spec
from owcsim.engine.media.mie import particle_optics
from owcsim.schemas.frames import FramesSpec
from tests.fds_writer import FdsCase, FdsMesh, FdsObstruction, FdsSlice, write_case

pytest.importorskip("fdsreader", reason="pip install 'owcsim[fire]'")

TIMES = np.array([0.0, 2.5, 5.0, 7.5], np.float32)
EXT = ("SOOT EXTINCTION COEFFICIENT", "ext_coef_C", "1/m")
SOOT = ("SOOT DENSITY", "rho_C", "kg/m3")


def _spec(path, **kw):
    return TypeAdapter(FramesSpec).validate_python(
        {"type": "fds", "path": str(path), "origin": [0, 0, 0], "albedo": 0.0, **kw}
    )


def _cells(rng, shape, scale=2.0):
    return rng.uniform(0, scale, (len(TIMES), *shape)).astype(np.float32)


@pytest.fixture
def one_mesh(tmp_path):
    rng = np.random.default_rng(1)
    mesh = FdsMesh((0.0, 0.0, 0.0), (1.2, 0.8, 0.6), (6, 4, 3))
    k = _cells(rng, mesh.shape)
    k[:, 1, 1:3, 0] = 0.0  # FDS writes extinction 0 inside obstructions
    case = FdsCase("one", [mesh], TIMES, [FdsSlice("EXT", *EXT, True, [k])], [FdsObstruction(0, (1, 2, 1, 3, 0, 1))])
    write_case(tmp_path, case)
    return tmp_path, k


def test_values_written_are_values_read(one_mesh):
    path, k = one_mesh
    frames = frames_from_spec(_spec(path))
    assert np.array_equal(frames.sigma_t, k.astype(np.float64))
    assert np.array_equal(frames.sigma_s, np.zeros_like(frames.sigma_s))
    assert np.array_equal(frames.times, TIMES.astype(np.float64))
    assert frames.shape == (6, 4, 3) and frames.frames_report().masked_cells == 2
    by_file = frames_from_spec(_spec(path / "one.smv"))  # the .smv file itself, as fdsreader takes it
    assert np.array_equal(by_file.sigma_t, frames.sigma_t)
    assert sorted(p.name for p in path.iterdir()) == ["one.smv", "one_1_1.sf"]  # no cache file written


def test_origin_moves_the_grid_and_albedo_splits(one_mesh):
    path, k = one_mesh
    frames = frames_from_spec(_spec(path, origin=[1.0, -2.0, 0.5], albedo=0.25, phase={"type": "hg", "g": 0.7}))
    assert np.array_equal(frames.lo, [1.0, -2.0, 0.5])
    assert np.allclose(frames.hi, [2.2, -1.2, 1.1], rtol=0, atol=1e-6)  # FDS's node coordinates are float32
    assert np.array_equal(frames.sigma_s, 0.25 * k.astype(np.float64))
    assert np.array_equal(frames.sigma_a + frames.sigma_s, frames.sigma_t)
    report = frames.frames_report()
    assert report.origin == (1.0, -2.0, 0.5) and report.albedo == 0.25 and report.albedo_from == "given"
    # a point at FDS (0.3, 0.5, 0.1) (cell 1, 2, 0) is at room (1.3, -1.5, 0.6)
    sig, _ = frames.frame(2).coefficients_at(np.array([[1.3, -1.5, 0.6]]))
    assert sig[0] == frames.sigma_a[2, 1, 2, 0]


def test_times_are_chosen(one_mesh):
    path, k = one_mesh
    assert frames_from_spec(_spec(path, times_s=[2.4, 2.6, 7.0])).times.tolist() == [2.5, 7.5]
    assert frames_from_spec(_spec(path, t_min=2.0, t_max=7.0)).times.tolist() == [2.5, 5.0]
    picked = frames_from_spec(_spec(path, every=2))
    assert picked.times.tolist() == [0.0, 5.0] and np.array_equal(picked.sigma_t[1], k[2].astype(np.float64))
    assert picked.frames_report().times_s == [0.0, 5.0]
    with pytest.raises(SceneError, match="no frame in the chosen times"):
        frames_from_spec(_spec(path, t_min=20.0))


def test_wavelength_scales_the_extinction(one_mesh):
    path, k = one_mesh
    frames = frames_from_spec(_spec(path, wavelength_nm=850.0, wavelength_exponent=1.2))
    factor = (632.8 / 850.0) ** 1.2
    np.testing.assert_allclose(frames.sigma_t, k.astype(np.float64) * factor, rtol=1e-15)
    assert frames.frames_report().wavelength_factor == pytest.approx(factor, rel=1e-15)


def test_mie_albedo_and_phase(one_mesh):
    path, k = one_mesh
    particles = {
        "geometric_mean_diameter": 1e-7,
        "geometric_std": 1.5,
        "refractive_index": {"real": 1.57, "imag": 0.56},
        "wavelength": 632.8e-9,
    }
    frames = frames_from_spec(_spec(path, albedo=None, particles=particles))
    optics = particle_optics(
        TypeAdapter(FramesSpec)
        .validate_python({"type": "fds", "path": ".", "origin": [0, 0, 0], "particles": particles})
        .particles
    )
    albedo = optics.c_sca / optics.c_ext
    assert 0.05 < albedo < 0.5
    np.testing.assert_allclose(frames.sigma_s, albedo * k.astype(np.float64), rtol=1e-15)
    assert frames.phase.type == "mie" and frames.frames_report().albedo_from == "mie"


def test_two_meshes_are_joined(tmp_path):
    rng = np.random.default_rng(2)
    m1, m2 = FdsMesh((0.0, 0.0, 0.0), (1.2, 0.8, 0.6), (6, 4, 3)), FdsMesh((1.2, 0.0, 0.0), (2.4, 0.8, 0.6), (6, 4, 3))
    k1, k2 = _cells(rng, m1.shape), _cells(rng, m2.shape)
    k2[:, 2, 0, 1:3] = 0.0
    case = FdsCase(
        "two", [m1, m2], TIMES, [FdsSlice("EXT", *EXT, True, [k1, k2])], [FdsObstruction(1, (2, 3, 0, 1, 1, 3))]
    )
    write_case(tmp_path, case)
    frames = frames_from_spec(_spec(tmp_path, origin=[0.5, 0.0, 0.0]))
    assert frames.shape == (12, 4, 3) and frames.frames_report().meshes == 2
    assert np.array_equal(frames.sigma_t, np.concatenate([k1, k2], axis=1).astype(np.float64))
    assert np.allclose(frames.lo, [0.5, 0, 0]) and np.allclose(frames.hi, [2.9, 0.8, 0.6], atol=1e-6)
    assert frames.frames_report().masked_cells == 2


def test_node_soot_density_two_meshes_masked(tmp_path):
    """Node-based soot density over two meshes (shared nodes at x = 1.2 m), a Burner whose nodes hold the gas
    density 1.195 kg/m3: cells = 8700 x the mean of their corner nodes outside the Burner; inside it 0."""
    rng = np.random.default_rng(3)
    nodes = rng.uniform(0, 1e-4, (len(TIMES), 13, 5, 4))
    burner = (2, 4, 1, 3, 0, 1)  # cells 2..3, 1..2, 0 of mesh 1; nodes 2..4, 1..3, 0..1 inside or on it
    nodes[:, 2:5, 1:4, 0:2] = 1.195
    nodes = nodes.astype(np.float32)
    m1, m2 = FdsMesh((0.0, 0.0, 0.0), (1.2, 0.8, 0.6), (6, 4, 3)), FdsMesh((1.2, 0.0, 0.0), (2.4, 0.8, 0.6), (6, 4, 3))
    case = FdsCase(
        "nodes",
        [m1, m2],
        TIMES,
        [FdsSlice("SOOT", *SOOT, False, [nodes[:, :7], nodes[:, 6:]])],
        [FdsObstruction(0, burner, "Burner")],
    )
    write_case(tmp_path, case)
    frames = frames_from_spec(_spec(tmp_path, quantity="soot_density"))
    ok = np.ones(nodes.shape[1:], bool)
    ok[2:5, 1:4, 0:2] = False
    ref = np.zeros((len(TIMES), 12, 4, 3))
    for i in range(12):  # plain reference: loops over the few cells
        for j in range(4):
            for k in range(3):
                corner = (slice(i, i + 2), slice(j, j + 2), slice(k, k + 2))
                if ok[corner].any():
                    ref[:, i, j, k] = nodes[(slice(None), *corner)][:, ok[corner]].astype(np.float64).mean(axis=1)
    np.testing.assert_allclose(frames.sigma_t, 8700.0 * ref, rtol=1e-14)
    assert np.all(frames.sigma_t[:, 2:4, 1:3, 0] == 0) and frames.frames_report().masked_cells == 4
    assert "8 corner nodes" in frames.source


def test_meshes_of_different_cells_are_refused(tmp_path):
    rng = np.random.default_rng(4)
    m1, m2 = FdsMesh((0.0, 0.0, 0.0), (1.2, 0.8, 0.6), (6, 4, 3)), FdsMesh((1.2, 0.0, 0.0), (2.4, 0.8, 0.6), (12, 8, 6))
    case = FdsCase(
        "mixed", [m1, m2], TIMES, [FdsSlice("EXT", *EXT, True, [_cells(rng, m1.shape), _cells(rng, m2.shape)])]
    )
    write_case(tmp_path, case)
    with pytest.raises(SceneError, match="different cell sizes"):
        frames_from_spec(_spec(tmp_path))


def test_bad_fds_input_is_refused(one_mesh, tmp_path, monkeypatch):
    path, _ = one_mesh
    with pytest.raises(SceneError, match="no FDS slice with ID 'NOPE'.*EXT"):
        frames_from_spec(_spec(path, slice_id="NOPE"))
    with pytest.raises(SceneError, match="not SOOT DENSITY"):
        frames_from_spec(_spec(path, quantity="soot_density", slice_id="EXT"))
    with pytest.raises(SceneError, match="not found"):
        frames_from_spec(_spec(tmp_path / "missing"))
    (tmp_path / "empty").mkdir()
    with pytest.raises(SceneError, match="no .smv file"):
        frames_from_spec(_spec(tmp_path / "empty"))
    with pytest.raises(ValidationError, match="either `albedo`"):
        _spec(path, albedo=None)
    with pytest.raises(ValidationError, match="SMOKE3D holds soot density"):
        _spec(path, source="smoke3d")
    monkeypatch.setattr(fds_module, "fdsreader", LazyModule("owcsim_no_such_module_fdsreader"))
    with pytest.raises(SceneError, match=r"pip install 'owcsim\[fire\]'"):
        frames_from_spec(_spec(path))


def test_a_zipped_case_in_the_document_reads_the_same(one_mesh, tmp_path_factory):
    """`data_base64`: the case as a zip archive (in a sub-folder, as users zip folders), e.g. over HTTP."""
    import base64
    import io
    import zipfile

    path, _ = one_mesh
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as z:
        for f in sorted(path.iterdir()):
            z.write(f, f"case/{f.name}")
    doc = {
        "type": "fds",
        "data_base64": base64.b64encode(buffer.getvalue()).decode(),
        "origin": [0, 0, 0],
        "albedo": 0.0,
    }
    frames = frames_from_spec(TypeAdapter(FramesSpec).validate_python(doc))
    assert np.array_equal(frames.sigma_t, frames_from_spec(_spec(path)).sigma_t)
    assert frames.frames_report().file == "data_base64:case/one.smv"
    with zipfile.ZipFile(buffer, "a") as z:
        z.writestr("other/two.smv", "CHID\n two\n")
    doc["data_base64"] = base64.b64encode(buffer.getvalue()).decode()
    with pytest.raises(SceneError, match="exactly one .smv file, it holds 2"):
        frames_from_spec(TypeAdapter(FramesSpec).validate_python(doc))
    with pytest.raises(SceneError, match="not a base64 zip archive"):
        frames_from_spec(TypeAdapter(FramesSpec).validate_python({**doc, "data_base64": "bm90IGEgemlw"}))
    with pytest.raises(ValidationError, match="exactly one of `path` and `data_base64`"):
        TypeAdapter(FramesSpec).validate_python({**doc, "path": str(path)})
