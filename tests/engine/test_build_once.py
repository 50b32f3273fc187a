"""Each scene and medium is built once per job: the automatic settings, their pilot and the run share it.

Counters wrap the builders where the engine calls them (engine.run.simulate.build_scene, the medium
builder engine.scene.scene.medium_from_spec, and the pre-flight's engine.scene.scene.build_scene). Before this
change an automatic job on the smoky room built the scene 3 times and the medium 4 times (issue 10),
so a counter that missed a build path would show it here as a count above 1.
"""

from __future__ import annotations

import json

import pytest

from owcsim.engine.run import simulate as simulate_module
from owcsim.engine.scene import scene as scene_module
from owcsim.schemas import SceneSpec
from owcsim.schemas.algorithms import ALGORITHMS, Direction
from owcsim.schemas.results import SimulationResultPublic, StopReason
from tests.scenes import EXAMPLES


def _count(monkeypatch, module, name: str) -> list[int]:
    calls = [0]
    real = getattr(module, name)

    def counted(*args, **kwargs):
        calls[0] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(module, name, counted)
    return calls


def _smoky(**simulation) -> SceneSpec:
    doc = json.loads((EXAMPLES / "smoky_room.json").read_text())
    doc["simulation"] = {"paths": 2048, "pilot_paths": 256, "seed": 1, **simulation}  # K, S, window automatic
    return SceneSpec.model_validate(doc)


def test_an_automatic_smoky_job_builds_its_scene_and_medium_once(monkeypatch):
    scenes = _count(monkeypatch, simulate_module, "build_scene")
    media = _count(monkeypatch, scene_module, "medium_from_spec")
    res = simulate_module.simulate(_smoky())
    assert isinstance(res, SimulationResultPublic)
    assert res.algorithm == 5 and res.modeled.pilot is not None  # the truncation pilot ran
    assert (scenes[0], media[0]) == (1, 1)


def test_a_given_scene_is_not_built_again(monkeypatch):
    spec = _smoky()
    built = scene_module.build_scene(spec)
    scenes = _count(monkeypatch, simulate_module, "build_scene")
    media = _count(monkeypatch, scene_module, "medium_from_spec")
    simulate_module.simulate(spec, scene=built)
    assert (scenes[0], media[0]) == (0, 0)


def test_the_server_preflight_builds_the_scene_once(monkeypatch):
    from owcsim.server.preflight import preflight

    scenes = _count(monkeypatch, scene_module, "build_scene")  # the pre-flight imports it from engine.scene.scene
    inner = _count(monkeypatch, simulate_module, "build_scene")
    media = _count(monkeypatch, scene_module, "medium_from_spec")
    assert preflight(_smoky()) == 12
    assert (scenes[0], inner[0], media[0]) == (1, 0, 1)


def test_typed_result_fields_and_enums():
    res = simulate_module.simulate(_smoky(algorithm=2, max_reflections=1, t_max_s=1e-7))
    assert res.run.stop_reason is StopReason.PATHS
    assert res.links[0].direction is Direction.BOTH  # algorithms 2-4 in a medium: from both devices
    assert res.families == ALGORITHMS[2].families
    assert Direction.FORWARD == "forward" and {"forward": 1}[Direction.FORWARD] == 1  # str enum, hashes as str
    assert [Direction.of_code(d.code) for d in Direction] == list(Direction)
    doc = json.loads(res.model_dump_json())  # JSON only at the edge: plain strings there
    assert doc["links"][0]["direction"] == "both" and doc["run"]["stop_reason"] == "paths"


@pytest.mark.parametrize("number", sorted(ALGORITHMS))
def test_the_registry_is_what_the_planner_runs(number):
    """Each record's kernel flags and fixed S are the KernelSettings the planner builds for that algorithm."""
    from owcsim.engine.scene.scene import build_scene

    alg = ALGORITHMS[number]
    given = min(3, alg.scattering_range[1])  # the highest S it honours, up to 3 (others are refused)
    spec = _smoky(algorithm=number, max_reflections=1, max_scattering=given, t_max_s=1e-7, direction="forward")
    settings = simulate_module.kernel_settings(spec, build_scene(spec), both_devices=False)
    assert {k: getattr(settings, k) for k in alg.kernel} == dict(alg.kernel)
    assert settings.max_scattering == {1: 0, 2: 1, 3: 1, 4: 2, 5: 3}[number]


#: What a run from both devices sets, per algorithm, in a medium and in vacuum (integrator/weights.py's partition
#: of unity; the values of the former medium_nee.two_sided_settings).
BOTH_DEVICES = {
    2: ({"mis": True, "scatter_then_reflect": True, "reflect_then_scatter": False},) * 2,
    3: ({"mis": True, "scatter_then_reflect": False, "reflect_then_scatter": True},) * 2,
    4: ({"mis": True, "scatter_then_reflect": True, "reflect_then_scatter": True},) * 2,
    5: ({"both_sides": True}, {"mis": True}),
}


@pytest.mark.parametrize("number", sorted(ALGORITHMS))
def test_the_registry_says_what_a_run_from_both_devices_sets(number):
    """The planner's two-sided settings are the record's `both_devices` flags on top of its own; algorithm 1 has
    none (simulate_two_sided refuses it from both sides)."""
    from owcsim.engine.scene.scene import build_scene

    alg = ALGORITHMS[number]
    if number not in BOTH_DEVICES:
        assert alg.both_devices is None
        with pytest.raises(ValueError, match="one direction"):
            simulate_module.simulate_two_sided(_smoky(algorithm=number, max_reflections=1, t_max_s=1e-7))
        return
    for has_medium, flags in zip((True, False), BOTH_DEVICES[number]):
        spec = _smoky(algorithm=number, max_reflections=1, t_max_s=1e-7)
        if not has_medium:
            spec = spec.model_copy(update={"medium": None})
        settings = simulate_module.kernel_settings(spec, build_scene(spec), both_devices=True)
        assert dict(alg.both_devices_kernel(has_medium)) == flags
        assert {k: getattr(settings, k) for k in flags} == flags


def test_an_automatic_window_over_the_bin_budget_is_a_located_error():
    """The line-of-sight window is chosen without a pilot; the budget is still checked (not by re-validation)."""
    from owcsim.engine.core.errors import SceneError

    doc = json.loads((EXAMPLES / "barry_config_a.json").read_text())
    doc["simulation"] = {"algorithm": 1, "max_reflections": 0, "time_bin_s": 1e-15, "paths": 64}
    with pytest.raises(SceneError, match=r"automatic time window 0\.\.[0-9.e-]+ s at 1e-15 s per bin"):
        simulate_module.simulate(SceneSpec.model_validate(doc))


def test_a_worker_builds_a_job_and_its_pilot_once(monkeypatch, tmp_path):
    """A process worker's scene cache: the pilot's document (other receivers and settings, same surfaces,
    transmitters and medium) reuses the geometry built for the job; another geometry is built."""
    from owcsim.engine.run import execution

    monkeypatch.setattr(execution, "_SCENES", type(execution._SCENES)())
    monkeypatch.setattr(execution, "_BUILT", {})
    builds = _count(monkeypatch, execution, "build_scene")
    job = _smoky(algorithm=5, max_reflections=2, max_scattering=2, t_max_s=1e-7)
    pilot = job.model_copy(
        update={
            "receivers": [job.receivers[0].model_copy(update={"position": (1.0, 2.0, 0.0)})],
            "simulation": job.simulation.model_copy(update={"max_reflections": 9}),
        }
    )
    other = job.model_copy(update={"medium": None})
    refs = [execution.job_ref(scene_module.build_scene(s), None, str(tmp_path)) for s in (job, pilot, other)]
    scenes = [execution._worker_scene(r.key, r.spec_path, None) for r in refs]
    assert builds[0] == 2  # the job's and the medium-free one's; the pilot's is derived
    assert scenes[1].geometry is scenes[0].geometry and scenes[1].spec is not scenes[0].spec
    fresh = scene_module.build_scene(pilot)
    assert (scenes[1].receivers.positions == fresh.receivers.positions).all()
    assert scenes[1].medium_far_distance == fresh.medium_far_distance and scenes[2].medium is None
