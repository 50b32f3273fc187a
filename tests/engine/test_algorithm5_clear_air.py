"""`simulation.algorithm: 5` in a scene without a medium (issue 22, item 3).

The automatic scattering order S read the medium's albedo and raised AttributeError ('NoneType'
object has no attribute 'type') in auto._max_albedo: a traceback and exit 1, while algorithms 2-4
ran. In clear air algorithm 5 is a surface path tracer (roulette past rr_start_depth, no
scattering): S is set to the field's least (1) with the reason, and its H0 must agree with algorithm 1
(NEE at every reflection, no roulette) at the same K within their standard errors.
"""

import json

import numpy as np
import pytest

from owcsim.api import simulate
from owcsim.cli import main
from tests.scenes import barry_doc, within


def _agree(result, reference):
    link, ref = result.links[0], reference.links[0]
    se = float(np.hypot(link.dc_gain_stderr, ref.dc_gain_stderr))
    assert within(link.dc_gain, ref.dc_gain, se), (link.dc_gain, ref.dc_gain, se)
    assert not within(1.05 * link.dc_gain, ref.dc_gain, se)  # a 5 % error would be seen
    assert not within(0.95 * link.dc_gain, ref.dc_gain, se)


@pytest.mark.parametrize("max_reflections", [None, 12], ids=["automatic K", "K = 12"])
def test_algorithm_5_without_a_medium_agrees_with_algorithm_1(max_reflections):
    doc = barry_doc(algorithm=5, paths=20_000, seed=3, pilot_paths=1024)
    del doc["simulation"]["t_max_s"], doc["simulation"]["max_reflections"]
    if max_reflections is not None:
        doc["simulation"]["max_reflections"] = max_reflections
    result = simulate(doc)  # raised AttributeError before
    modeled = result.modeled
    assert modeled.algorithm == 5 and modeled.max_scattering == 0
    assert modeled.max_scattering_reason.startswith("no medium")
    assert not any("scattering" in item for item in modeled.left_out)
    assert modeled.max_reflections >= 10 and result.warnings == []
    reference = simulate(
        barry_doc(
            algorithm=1,
            max_reflections=modeled.max_reflections,
            t_max_s=modeled.time_window_s[1],
            paths=20_000,
            seed=4,
        )
    )
    _agree(result, reference)


def test_algorithm_5_without_a_medium_runs_from_the_command_line(tmp_path, capsys):
    scene = tmp_path / "clear.json"
    doc = barry_doc(algorithm=5, paths=2000, pilot_paths=256)
    del doc["simulation"]["t_max_s"], doc["simulation"]["max_reflections"]
    scene.write_text(json.dumps(doc))
    assert main(["run", str(scene), "--out", str(tmp_path / "out")]) == 0  # exit 1 with a traceback before
    assert "H0 = " in capsys.readouterr().out
