"""The medium's kind decided once, when the scene is built (engine/media/model.py, issue 23).

`scene.medium_model` answers what the automatic settings and the result used to re-decide from the
document in several places: whether the medium scatters, its largest albedo (the document's own
arithmetic: sigma_s / (sigma_a + sigma_s), per cell for a grid, Mie coefficients for particles), and
the result's `modeled.medium` entry. A spectral scene keeps the model of its grey medium.
"""

import math

import pytest

from owcsim.engine.media import mie, report
from owcsim.engine.media.model import MediumKind
from owcsim.engine.media.phase import HenyeyGreenstein, Tabulated
from owcsim.engine.scene.scene import build_scene
from tests.scenes import room_doc, spec

NM = 1e-9
SOOT = {"geometric_mean_diameter": 1.2e-7, "geometric_std": 1.6, "refractive_index": {"real": 1.57, "imag": 0.56}}
GRID = {"type": "grid", "min": [0, 0, 2], "max": [5, 5, 3], "shape": [2, 3, 1], "sigma_a": [0.1] * 6, "sigma_s": 0.2}


@pytest.mark.parametrize(
    "medium, kind, scatters, albedo",
    [
        ({"type": "homogeneous", "sigma_a": 0.1, "sigma_s": 0.3}, MediumKind.HOMOGENEOUS, True, 0.3 / (0.1 + 0.3)),
        ({"type": "homogeneous", "sigma_a": 0.1, "sigma_s": 0.0}, MediumKind.HOMOGENEOUS, False, 0.0),
        ({"type": "homogeneous", "sigma_a": 0.0, "sigma_s": 0.0}, MediumKind.HOMOGENEOUS, False, 0.0),  # not built
        ({**GRID, "sigma_a": [0.1, 0.0, 0.1, 0.1, 0.1, 0.1], "sigma_s": 0.2}, MediumKind.GRID, True, 1.0),
        ({**GRID, "sigma_s": 0.0}, MediumKind.GRID, False, 0.0),
    ],
)
def test_the_built_scene_says_what_its_medium_is(medium, kind, scatters, albedo):
    scene = build_scene(spec(room_doc(medium=medium)))
    model = scene.medium_model
    assert model is not None and model.kind is kind
    assert model.scatters is scatters and model.max_albedo == albedo  # bit for bit: the document's arithmetic
    assert model.report(scene.phase)["model"] == kind.value


def test_particle_smoke_reports_its_mie_optics_once():
    medium = {"type": "particles", "particles": {**SOOT, "wavelength": 850 * NM}, "number_concentration": 1e12}
    s = spec(room_doc(medium=medium))
    scene = build_scene(s)
    model = scene.medium_model
    sigma_a, sigma_s = mie.medium_coefficients(s.medium)
    assert model.kind is MediumKind.PARTICLES and model.scatters
    assert model.max_albedo == sigma_s / (sigma_a + sigma_s)
    assert model.report(scene.phase) == report.describe(s.medium)


def test_no_medium_no_model():
    assert build_scene(spec(room_doc())).medium_model is None


def test_a_spectral_scene_keeps_the_model_of_its_grey_medium():
    """The scene runs the least attenuated band's medium; the automatic settings and the result keep reading the
    document's grey medium (the grey rules, as before the model was decided once)."""
    doc = room_doc(medium={"type": "homogeneous", "sigma_a": 0.05, "sigma_s": 0.2})
    doc["spectral"] = {"wavelengths": [450 * NM, 650 * NM], "medium": {"sigma_a": [0.05, 0.02], "sigma_s": [0.2, 0.1]}}
    scene = build_scene(spec(doc))
    assert scene.medium.sigma_s == 0.1  # the carrier band
    assert scene.medium_model.max_albedo == 0.2 / (0.05 + 0.2)


def test_the_report_of_a_homogeneous_medium_names_its_phase_function():
    """The result's `modeled.medium` entry (was mie.medium_report): the kind and the phase function run."""
    scene = build_scene(spec(room_doc(medium={"type": "homogeneous", "sigma_a": 0.1, "sigma_s": 0.1})))
    model = scene.medium_model
    assert model.report(HenyeyGreenstein(0.3)) == {"model": "homogeneous", "phase": {"type": "hg", "mean_cosine": 0.3}}
    assert model.report(None) == {"model": "homogeneous", "phase": None}
    rep = model.report(Tabulated([-1, 1], [2, 2]))["phase"]
    assert rep["type"] == "tabulated" and rep["normalisation"] == pytest.approx(8 * math.pi) and rep["points"] == 2
