"""The memory estimate of a timeline (engine/run/budget.py `_frames`): its frames, and one tally per time when
the frames are reweighted."""

import numpy as np

from owcsim.engine.media.frame_sources import frames_from_spec
from owcsim.engine.run.budget import memory_estimate
from owcsim.engine.run.timeline import frames_at
from tests.scenes import room_doc, spec

SHAPE = (20, 10, 6)


def _doc(method, n_frames=6, trajectories=False):
    doc = room_doc(algorithm=5, max_reflections=1, max_scattering=1, paths=1000)
    cells = int(np.prod(SHAPE))
    doc["timeline"] = {
        "frames": {
            "type": "inline",
            "times": list(range(n_frames)),
            "min": [0, 0, 0],
            "max": [5, 5, 3],
            "shape": list(SHAPE),
            "sigma_a": [[0.1] * cells] * n_frames,
            "sigma_s": [[0.2] * cells] * n_frames,
        },
        "method": method,
    }
    if trajectories:
        doc["timeline"]["trajectories"] = [{"device": "rx", "waypoints": [[1, 1, 0], [2, 1, 0]], "speed_m_s": 0.1}]
    return spec(doc)


def test_the_frames_term_covers_the_arrays_a_timeline_holds():
    sp = _doc("independent")
    est = memory_estimate(sp)
    frames = frames_from_spec(sp.timeline.frames)
    at_times = frames_at(frames, frames.times)
    held = sum(a.nbytes for a in (frames.sigma_a, frames.sigma_s, at_times.sigma_a, at_times.sigma_s))
    assert held <= est.frames <= 1.5 * held  # the frames, their copies at the times (and the carrier)
    assert memory_estimate(_doc("independent", n_frames=12)).frames > 1.9 * est.frames


def test_reweighted_timelines_count_one_tally_per_time():
    independent, reweighted = memory_estimate(_doc("independent")), memory_estimate(_doc("reweighted"))
    assert reweighted.accumulators == 6 * independent.accumulators
    assert memory_estimate(_doc("auto")).accumulators == reweighted.accumulators  # auto reweights here
    walker = memory_estimate(_doc("auto", trajectories=True))
    assert walker.accumulators == independent.accumulators  # a moving receiver: independent runs
