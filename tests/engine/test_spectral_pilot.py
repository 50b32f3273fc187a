"""A spectral scene with more receivers than the truncation pilot traces (issue 22, item 2).

The pilot runs on up to pilot.PILOT_RECEIVERS receivers of the job's built scene; the scene's spectral
tables (the receivers' responsivity rows, the link count) stayed the job's, so its line of sight indexed
a transmitter row that does not exist (IndexError in spectra.channel_power) with 9 or more receivers.
receivers.with_receivers now gives the pilot (and a worker reusing a built geometry) the tables of its own
receivers (spectra.with_receivers). Checks: the tables against those of a scene built from the pilot's
document, and the automatic run of 12 receivers against the same scene with its K and window given.
"""

import copy

import numpy as np

from owcsim.api import simulate
from owcsim.engine.run import auto
from owcsim.engine.run import pilot as pilot_module
from owcsim.engine.scene.scene import build_scene
from owcsim.schemas import SceneSpec
from tests.scenes import within

BANDS = [380e-9, 430e-9, 480e-9, 530e-9, 580e-9, 630e-9, 680e-9, 730e-9, 780e-9]


def _doc(n_rx=12, **simulation) -> dict:
    """A white LED over a 5 x 5 x 3 m room with spectral ceiling and walls, `n_rx` receivers at desk height
    (two in three with a silicon responsivity, every other one behind a 0.9 filter)."""
    receivers = []
    for j in range(n_rx):
        r = {
            "id": f"rx{j}",
            "position": [0.6 + 3.8 * (j % 4) / 3, 0.8 + 1.7 * (j // 4), 0.8],
            "normal": [0, 0, 1],
            "area": 1e-4,
            "fov_deg": 80,
        }
        if j % 3 != 2:
            r["responsivity"] = {"type": "named", "name": "silicon_pin"}
        if j % 2:
            r["filter_transmission"] = 0.9
        receivers.append(r)
    walls = [0.20, 0.25, 0.45, 0.50, 0.30, 0.22, 0.30, 0.40]
    return {
        "spectral": {"band_edges": BANDS},
        "transmitters": [
            {
                "id": "tx",
                "position": [2.5, 2.5, 3],
                "normal": [0, 0, -1],
                "lambertian_order": 1,
                "power": 3.0,
                "spectrum": {"type": "named", "name": "white_led_cool"},
            }
        ],
        "room": {
            "size": [5, 5, 3],
            "reflectance": {
                "ceiling": {"type": "spectral", "reflectance": {"type": "named", "name": "white_paint"}},
                "floor": 0.3,
                "walls": {"type": "spectral", "reflectance": walls},
            },
        },
        "receivers": receivers,
        "simulation": simulation,
    }


def test_the_pilot_scene_has_the_spectral_tables_of_its_receivers():
    spec = SceneSpec.model_validate(_doc(12, paths=1000))
    scene = build_scene(spec)
    step = auto.plan(spec, scene)
    pilot = step.pilot
    assert pilot is not None and len(pilot.receivers) == pilot_module.PILOT_RECEIVERS < 12
    own = build_scene(pilot.spec).spectra  # the tables a scene of the pilot's document has
    tables = pilot.scene.spectra
    assert tables.n_links == own.n_links == pilot_module.PILOT_RECEIVERS
    np.testing.assert_array_equal(tables.rx_electrical, own.rx_electrical)
    np.testing.assert_array_equal(tables.rx_responsive, own.rx_responsive)
    np.testing.assert_array_equal(tables.rx_electrical, scene.spectra.rx_electrical[pilot.receivers])
    assert not np.array_equal(tables.rx_electrical, scene.spectra.rx_electrical[: pilot_module.PILOT_RECEIVERS])
    np.testing.assert_array_equal(tables.face_rho, scene.spectra.face_rho)  # the rest is shared
    assert scene.spectra.n_links == 12  # the job's own tables are untouched


def test_automatic_settings_with_twelve_spectral_receivers_agree_with_explicit_ones():
    result = simulate(_doc(12, paths=20_000, seed=1, pilot_paths=1024))  # IndexError before
    modeled = result.modeled
    assert len(modeled.pilot.receivers) == pilot_module.PILOT_RECEIVERS and modeled.max_reflections >= 5
    explicit = copy.deepcopy(_doc(12, paths=20_000, seed=2))
    explicit["simulation"].update(
        algorithm=modeled.algorithm, max_reflections=modeled.max_reflections, t_max_s=modeled.time_window_s[1]
    )
    reference = simulate(explicit)
    assert reference.modeled is None or reference.modeled.pilot is None  # nothing chosen automatically
    checked = 0
    for a, b in zip(result.spectral.links, reference.spectral.links, strict=True):
        pairs = [("optical_gain", "optical_gain_stderr"), ("illuminance_lx", "illuminance_lx_stderr")]
        if a.electrical_gain_a_per_w is not None:
            pairs.append(("electrical_gain_a_per_w", "electrical_gain_a_per_w_stderr"))
        else:
            assert b.electrical_gain_a_per_w is None  # no responsivity: no electrical figure in either run
        for value, error in pairs:
            x, ref = getattr(a, value), getattr(b, value)
            se = float(np.hypot(getattr(a, error), getattr(b, error)))
            assert np.isfinite(x) and x > 0
            assert within(x, ref, se), (a.receiver, value, x, ref, se)
            assert not within(1.05 * x, ref, se)  # a 5 % error would be seen
            checked += 1
    assert checked == 12 * 2 + 8  # eight receivers have a responsivity
