"""The frames document (schemas/frames.py): a union on `type`, and the refusals of the file kinds."""

from __future__ import annotations

import subprocess
import sys

import pytest
from pydantic import TypeAdapter, ValidationError

from owcsim.schemas.frames import FdsFramesSpec, FramesReportPublic, FramesSpec, InlineFramesSpec, NetcdfFramesSpec

ADAPTER = TypeAdapter(FramesSpec)
FDS = {"type": "fds", "path": "case", "origin": [0, 0, 0], "albedo": 0.1}
NC = {"type": "netcdf", "path": "smoke.nc", "origin": [0, 0, 0], "variable": "extinction", "albedo": 0.1}
PARTICLES = {"geometric_mean_diameter": 1e-7, "refractive_index": {"real": 1.57, "imag": 0.56}, "wavelength": 850e-9}


def test_the_union_tells_the_kinds_apart():
    inline = {
        "type": "inline",
        "times": [0],
        "min": [0, 0, 0],
        "max": [1, 1, 1],
        "shape": [1, 1, 1],
        "sigma_a": [0.1],
        "sigma_s": [0.0],
    }
    assert isinstance(ADAPTER.validate_python(inline), InlineFramesSpec)
    fds = ADAPTER.validate_python(FDS)
    assert isinstance(fds, FdsFramesSpec) and fds.mass_extinction_m2_per_kg == 8700.0 and fds.wavelength_nm == 632.8
    assert isinstance(ADAPTER.validate_python(NC), NetcdfFramesSpec)
    assert ADAPTER.validate_python({**FDS, "albedo": None, "particles": PARTICLES, "wavelength_nm": 850}).particles
    assert isinstance(ADAPTER.validate_python({k: v for k, v in inline.items() if k != "type"}), InlineFramesSpec)
    assert len(ADAPTER.json_schema()["oneOf"]) == 3
    with pytest.raises(ValidationError, match="frames `type` must be 'inline', 'fds' or 'netcdf'"):
        ADAPTER.validate_python({**FDS, "type": "hdf5"})


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ({**FDS, "origin": None}, "origin"),
        ({k: v for k, v in FDS.items() if k != "origin"}, "origin"),
        ({**FDS, "albedo": None}, "either `albedo`"),
        ({**FDS, "particles": PARTICLES, "wavelength_nm": 850}, "either `albedo`"),
        ({**FDS, "albedo": None, "particles": PARTICLES}, "differs from `wavelength_nm`"),
        (
            {**FDS, "albedo": None, "particles": PARTICLES, "wavelength_nm": 850, "phase": {"type": "isotropic"}},
            "`phase` goes with `albedo`",
        ),
        ({**FDS, "times_s": [1.0], "every": 2}, "not both"),
        ({**FDS, "t_min": 5, "t_max": 1}, "must not be below"),
        ({**FDS, "source": "smoke3d"}, "SMOKE3D holds soot density"),
        ({**FDS, "quantity": "soot_density", "source": "smoke3d", "slice_id": "S"}, "`slice_id` is for"),
        ({**FDS, "quantity": "visibility"}, "quantity"),
        ({**FDS, "wavelength_nm": 50}, "wavelength_nm"),
        ({**NC, "sigma_a_variable": "a", "sigma_s_variable": "s"}, "either `variable`"),
        ({**NC, "variable": None, "sigma_a_variable": "a"}, "both `sigma_a_variable`"),
        ({**NC, "variable": None}, "either `variable`"),
    ],
)
def test_bad_documents_are_refused(doc, message):
    with pytest.raises(ValidationError, match=message):
        ADAPTER.validate_python(doc)


def test_report_text_names_the_mapping():
    report = FramesReportPublic(
        kind="fds",
        file="a/case.smv",
        quantity="SOOT DENSITY [kg/m3]",
        data_id="SOOT_3D",
        cell_values="8-node mean",
        mass_extinction_m2_per_kg=8700,
        wavelength_nm=850,
        wavelength_factor=0.7445,
        albedo=0.2,
        albedo_from="mie",
        phase="mie",
        origin=(1, 2, 0),
        grid_min=(1, 2, 0),
        grid_max=(7, 6, 3),
        grid_shape=(30, 20, 15),
        times_s=[0, 90],
        max_sigma_t=3.1,
    )
    text = report.text()
    for part in (
        "SOOT_3D",
        "K_m 8700",
        "850 nm (factor 0.7445)",
        "albedo 0.2 (mie)",
        "origin [1.0, 2.0, 0.0]",
        "2 frames 0..90 s",
    ):
        assert part in text


def test_the_engine_imports_neither_fdsreader_nor_xarray():
    code = (
        "import sys, owcsim.engine.media.frame_sources, owcsim.engine.run.simulate; "
        "print('fdsreader' in sys.modules, 'xarray' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False"]


def test_inline_frames_report_themselves():
    from owcsim.engine.media.frame_sources import frames_from_spec

    doc = {
        "times": [0, 5],
        "min": [0, 0, 0],
        "max": [2, 1, 1],
        "shape": [2, 1, 1],
        "sigma_a": [0.1, [0.2, 0.3]],
        "sigma_s": [0.0, 0.4],
    }
    frames = frames_from_spec(ADAPTER.validate_python(doc))
    report = frames.frames_report()
    assert report.kind == "inline" and report.times_s == [0.0, 5.0] and report.grid_shape == (2, 1, 1)
    assert report.max_sigma_t == pytest.approx(0.7)
    assert frames.select([1]).frames_report().times_s == [5.0]
