"""Scrambled Sobol first dimensions (KernelSettings.qmc_first_dimensions) against an independent reference.

With quasi-random first dimensions the paths of a batch are not independent, so the error comes from
the spread of independent batches (each with its own scrambling), not from the per-path formula.
"""

import dataclasses
import math

import numpy as np
import pytest

from owcsim.engine.kernel import WorkItem, trace_batch
from owcsim.engine.scene import build_scene
from owcsim.engine.simulate import kernel_settings
from owcsim.schemas import SceneSpec
from tests.scenes import barry_first_bounce, room_doc, within


@pytest.mark.parametrize("direction", ["forward", "backward"])
def test_first_bounce_with_sobol_first_dimensions(direction):
    """k = 1 (the bounce the Sobol points drive) against the patch integral of the box room (Barry 1993)."""
    rx, fov = (0.5, 1.0, 0.0), 85.0
    spec = SceneSpec.model_validate(room_doc(rx=rx, fov_deg=fov, max_reflections=1, paths=4096))
    scene = build_scene(spec)
    settings = dataclasses.replace(kernel_settings(spec, scene), qmc_first_dimensions=True)
    n, replicates = 4096, 24
    means = np.array(
        [trace_batch(scene, WorkItem(direction, 0, (0,), b, n, 5), settings).s1[0, 0] / n for b in range(replicates)]
    )
    h1 = barry_first_bounce(rx, fov)
    se = means.std(ddof=1) / math.sqrt(replicates)
    assert se < 0.01 * h1  # power: a 4-sigma band narrower than 4 %, so a 5 % bias would fail
    assert within(means.mean(), h1, se, bias=1e-3 * h1), (means.mean(), h1, se)
