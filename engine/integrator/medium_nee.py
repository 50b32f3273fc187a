"""Runs from both devices under the partition of unity (weights.py): their kernel settings and a job runner.

The physics moved to the integrator's parts: the device factors and the partition of unity
(weights.py), the phase lobe (lobe.py), the branch from the first segment of algorithms 2-4 and their
double-scattering family (single_scatter.py), the third strategy for Tx -> x_1 -> x_2 -> Rx
(events.connect_from_target). What stays here is for the planner (engine/run), which takes it over:
`two_sided_settings` and `simulate_two_sided`.
"""

from __future__ import annotations

import numpy as np


def two_sided_settings(settings, algorithm: int, has_medium: bool):
    """KernelSettings for links run from both devices (the planner must then run every such link both ways).

    Algorithms 2-4: `mis` and the families (`scatter_then_reflect`, `reflect_then_scatter`); algorithm 5
    with a medium: `both_sides`
    (the partition on every connection); algorithm 5 without one: `mis` (each side
    counts half of the surface paths). A run whose partner run is missing would count
    about half: never use these settings for a link served from one side.
    """
    import dataclasses

    if algorithm in (2, 3, 4):  # algorithm 2: Tx -> p -> (k) -> Rx, 3: Tx -> (k) -> p -> Rx, 4: both
        return dataclasses.replace(
            settings, mis=True, scatter_then_reflect=algorithm != 3, reflect_then_scatter=algorithm != 2
        )
    if algorithm == 5:
        return dataclasses.replace(settings, **({"both_sides": True} if has_medium else {"mis": True}))
    raise ValueError(f"algorithm {algorithm} has no two-sided form")


def simulate_two_sided(spec, *, base_dir=None, executor=None, direction: str = "both", **overrides):
    """`simulate` with every link run from both devices under the partition of unity (module docstring).

    A stand-in until the planner (engine/run/simulate.py) offers it: the spec must be
    resolved (algorithm 2-5, explicit K, S and window). Algorithms 2-4: `mis` and
    the families; algorithm 5: `both_sides`. `direction` "forward" / "backward" runs
    one side only (as `simulate` does, for comparisons); `overrides` replace KernelSettings
    fields (e.g. rr_start_depth, rr_threshold). Returns the result document.
    """
    import dataclasses
    import time

    from owcsim.engine.results.result import build_result
    from owcsim.engine.run import simulate as sim_mod
    from owcsim.engine.run.execution import JobRef, SerialExecutor
    from owcsim.engine.scene.los import line_of_sight
    from owcsim.engine.scene.scene import build_scene

    t0 = time.perf_counter()
    a = spec.simulation.algorithm
    if a not in (1, 2, 3, 4, 5) or not spec.simulation.is_resolved or (a == 1 and direction == "both"):
        raise ValueError("simulate_two_sided needs a resolved document (algorithm 1: one direction)")
    scene = build_scene(spec, base_dir)
    settings = sim_mod.kernel_settings(spec, scene, both_devices=direction == "both")
    settings = dataclasses.replace(settings, **overrides)
    los_gain, los_delay = line_of_sight(scene)
    executor = executor or SerialExecutor()
    info = sim_mod.RunInfo(workers=executor.workers)
    info.pilot = {"rule": f"algorithm {a} from both devices, partition of unity (engine/integrator/medium_nee.py)"}
    directions = np.full(
        scene.n_links, {"both": sim_mod.BOTH, "forward": sim_mod.FORWARD, "backward": sim_mod.BACKWARD}[direction]
    )
    accs = sim_mod._run(
        scene, spec, settings, executor, JobRef(scene, "", "", None), directions, los_gain, info, None, None, t0
    )
    info.wall_time_s = time.perf_counter() - t0
    return build_result(spec, scene, accs, settings, los_gain, los_delay, directions, info)
