"""Timeline jobs (issue 26): frames as runs, trajectories, the timeline's errors and outage intervals.

References: a frame run against the same grid given as a static medium (bit for bit); a field constant in time
(bit-equal frames); pure absorption on a line of sight, H0(t) = H_LOS exp(-sigma_a(t) d) in closed form, with
the crossing times of a threshold solved by hand; trajectories against hand-computed walks.
"""

import copy
import math

import numpy as np
import pytest
from pydantic import ValidationError

from owcsim.engine.core.errors import SceneError
from owcsim.engine.media.frames import MediumFrames
from owcsim.engine.results.timeline import diff_stderr, outage_intervals
from owcsim.engine.run.frames import FrameMethod, frame_medium, simulate_frames
from owcsim.engine.run.simulate import simulate
from owcsim.engine.run.timeline import frames_at, run_timeline
from owcsim.engine.scene.trajectory import knots, normals_at, positions_at
from owcsim.schemas.timeline import TrajectorySpec
from tests.scenes import open_doc, room_doc, spec

SMOKY = dict(paths=3000, algorithm=5, max_reflections=2, max_scattering=2, batch_size=1000)


def _links(result):
    return [link.model_dump() for link in result.links]


def _random_frames(n=2, shape=(3, 2, 2), seed=3):
    rng = np.random.default_rng(seed)
    a = rng.uniform(0.0, 0.2, (n, *shape))
    s = rng.uniform(0.0, 0.3, (n, *shape))
    return MediumFrames(np.arange(n) * 10.0, [0, 0, 0], [5, 5, 3], a, s)


def test_a_frame_equals_the_static_grid_bit_for_bit():
    sp = spec(room_doc(**SMOKY))
    frames = _random_frames()
    out = simulate_frames(sp, frames)
    assert out.method is FrameMethod.INDEPENDENT and len(out.results) == 2
    for f in range(2):
        static = simulate(sp.model_copy(update={"medium": frame_medium(frames, f)}))
        assert _links(out.results[f]) == _links(static)
    assert _links(out.results[0]) != _links(out.results[1])  # the frames differ: so would a wrong frame


def test_a_field_constant_in_time_gives_a_constant_channel():
    sp = spec(room_doc(**SMOKY))
    one = _random_frames(1)
    frames = MediumFrames([0.0, 5.0, 9.0], one.lo, one.hi, np.repeat(one.sigma_a, 3, 0), np.repeat(one.sigma_s, 3, 0))
    out = simulate_frames(sp, frames)
    first = _links(out.results[0])
    assert first[0]["dc_gain"] > first[0]["los_gain"]  # scattered and reflected light: Monte Carlo counts
    assert all(_links(r) == first for r in out.results[1:])
    assert np.array_equal(out.dc_gain_groups[0], out.dc_gain_groups[2])
    assert np.all(diff_stderr(out.dc_gain_groups[:, 0], out.group_paths[:, 0]) == 0.0)


def _small_change(seed=7, algorithm=2):
    """Two frames 5 % apart in absorption; algorithm 2 (single scattering on segments) keeps the paths of both
    frames alike, so the shared random numbers correlate them strongly."""
    sp = spec(room_doc(paths=3000, algorithm=algorithm, max_reflections=2, batch_size=1000, seed=seed))
    base = _random_frames(1)
    a = np.concatenate([base.sigma_a, base.sigma_a * 1.05])
    frames = MediumFrames([0.0, 1.0], base.lo, base.hi, a, np.repeat(base.sigma_s, 2, 0))
    out = simulate_frames(sp, frames)
    h0 = [r.links[0].dc_gain for r in out.results]
    se = [r.links[0].dc_gain_stderr for r in out.results]
    return h0[1] - h0[0], diff_stderr(out.dc_gain_groups[:, 0], out.group_paths[:, 0])[0], math.hypot(*se)


def test_common_random_numbers_make_differences_precise():
    """The difference's error from shared groups is well below the frames' own errors combined as independent
    (what separate seeds would give)."""
    _, d, independent = _small_change()
    assert 0 < d < 0.8 * independent


@pytest.mark.slow
def test_difference_error_matches_the_spread_over_seeds():
    """The reported error of H0(t1) - H0(t0) against the spread of the difference over 16 seeds: the sample sd
    of 16 values has a relative error of 1 / sqrt(30) = 18 %, so the ratio must lie within 1 +- 4 x 0.18; the
    error of independent frames (about 2.2 x larger here) fails it."""
    runs = np.array([_small_change(seed) for seed in range(16)])
    spread = np.std(runs[:, 0], ddof=1)
    reported = np.sqrt(np.mean(runs[:, 1] ** 2))
    assert abs(reported / spread - 1) < 4 * 0.18
    assert abs(np.sqrt(np.mean(runs[:, 2] ** 2)) / spread - 1) > 4 * 0.18  # power: the independent error fails


def test_difference_error_formula_by_hand():
    x = np.array([[1.0, 2.0, 3.0, 6.0], [1.5, 2.0, 3.5, 6.0]])
    w = np.ones_like(x)
    a = (x - x.mean(axis=1, keepdims=True)) / 4
    ref = math.sqrt(((a[1] - a[0]) ** 2).sum() * 4 / 3)
    assert diff_stderr(x, w)[0] == pytest.approx(ref, rel=1e-12)
    # the same as the standard error of the mean of the paired differences
    assert ref == pytest.approx(np.std(x[1] - x[0], ddof=1) / 2, rel=1e-12)
    assert np.isnan(diff_stderr(x, np.array([[1, 0, 0, 0], [1, 1, 1, 1.0]]))[0])  # one shared group


def _los_timeline(sigma, times, threshold, quantity="dc_gain", method="auto", **extra):
    """Pure absorption on a 3 m line of sight (no surfaces, K = 0): H0 in closed form."""
    doc = open_doc(D=3.0, medium=None, algorithm=1)
    doc["timeline"] = {
        "frames": {
            "type": "inline",
            "times": [0.0, 50.0, 100.0],
            "min": [-1, -1, -1],
            "max": [4, 1, 1],
            "shape": [2, 1, 1],
            "sigma_a": sigma,
            "sigma_s": [0.0, 0.0, 0.0],
        },
        "times_s": times,
        "outage": {"quantity": quantity, "threshold": threshold},
        "method": method,
    }
    doc.update(extra)
    return run_timeline(spec(doc))


H_LOS = 2.0 / (2.0 * math.pi * 3.0**2) * 1e-4  # (m + 1) / (2 pi d^2) A, m = 1, facing each other


@pytest.mark.parametrize("method", ["independent", "reweighted"])
def test_outage_intervals_of_pure_absorption_in_closed_form(method):
    times = list(range(0, 101, 10))
    threshold = 1e-6
    result = _los_timeline([0.0, 1.0, 0.0], times, threshold, method=method)
    link = result.timeline.links[0]
    sigma = np.minimum(np.array(times) / 50.0, 2.0 - np.array(times) / 50.0)
    np.testing.assert_allclose(link.dc_gain, H_LOS * np.exp(-3.0 * sigma), rtol=1e-12)
    # sigma(t) = t / 50 rises to 1 at 50 s and falls back: H0 = threshold at sigma* = ln(H_LOS / thr) / 3
    s_star = math.log(H_LOS / threshold) / 3.0
    (interval,) = link.outages
    assert interval.start_s == pytest.approx(50.0 * s_star, rel=1e-9)
    assert interval.end_s == pytest.approx(100.0 - 50.0 * s_star, rel=1e-9)
    assert not interval.uncertain  # exact values: no error bar
    assert link.time_to_first_outage_s == pytest.approx(50.0 * s_star, rel=1e-9)
    assert result.timeline.frames_source and result.timeline.method == method


def test_outage_on_ber_through_the_link_budget():
    budget = {"link_budget": {"bit_rate": 1e6}}
    result = _los_timeline([0.0, 1.0, 0.0], list(range(0, 101, 10)), 1e-6, "ber", **budget)
    link = result.timeline.links[0]
    ber = np.array(link.ber)
    assert len(link.outages) == 1 and link.outages[0].end_s is not None and ber[0] < 1e-6
    out = np.array([any(o.start_s <= t <= (o.end_s or 1e9) for o in link.outages) for t in result.timeline.times_s])
    np.testing.assert_array_equal(out, ber > 1e-6)


def test_open_ended_and_uncertain_intervals():
    t = np.arange(6.0)
    y = np.array([3.0, 2.0, 0.5, 0.4, 2.0, 0.0])
    intervals = outage_intervals(t, y, y - 0.1, y + 0.1, 1.0)
    assert [(i.start_s, i.end_s) for i in intervals] == [
        (pytest.approx(1 + 1 / 1.5), pytest.approx(3 + 0.6 / 1.6)),
        (4.5, None),
    ]
    assert not intervals[0].uncertain
    wide = outage_intervals(t, y, y - 0.6, y + 0.6, 1.0)  # time 3's bar (-0.2..1.0) straddles the threshold
    assert wide[0].uncertain


def test_frames_interpolated_linearly_in_time():
    frames = _random_frames(3)
    mid = frames_at(frames, [0.0, 2.5, 10.0, 20.0])
    assert np.array_equal(mid.sigma_a[0], frames.sigma_a[0]) and np.array_equal(mid.sigma_a[3], frames.sigma_a[2])
    assert np.array_equal(mid.sigma_s[2], frames.sigma_s[1])
    np.testing.assert_allclose(mid.sigma_a[1], 0.75 * frames.sigma_a[0] + 0.25 * frames.sigma_a[1], rtol=1e-15)
    from owcsim.engine.core.errors import SceneError

    with pytest.raises(SceneError, match=r"\[25\.0\] lie outside the frames' times 0\.\.20 s"):
        frames_at(frames, [0.0, 25.0])  # frames from files: their times are known only once read


def test_waypoints_at_speed_by_hand():
    traj = TrajectorySpec(
        device="rx", waypoints=[(0, 0, 1), (3, 0, 1), (3, 4, 1)], speed_m_s=0.5, start_s=2.0, pause_s=1.0
    )
    t, p = knots(traj)
    # 3 m at 0.5 m/s: 6 s (2 -> 8), a 1 s pause (8 -> 9), 4 m: 8 s (9 -> 17)
    np.testing.assert_allclose(t, [2.0, 8.0, 9.0, 17.0])
    at = positions_at(traj, np.array([0.0, 5.0, 8.5, 13.0, 30.0]))
    np.testing.assert_allclose(at, [[0, 0, 1], [1.5, 0, 1], [3, 0, 1], [3, 2, 1], [3, 4, 1]])
    heading = TrajectorySpec(**(traj.model_dump() | {"orientation": "heading"}))
    n = normals_at(heading, (1.0, 0.0, 1.0), np.array([5.0, 8.5, 13.0]))
    s = 1 / math.sqrt(2)
    np.testing.assert_allclose(n, [[s, 0, s], [s, 0, s], [0, s, s]], atol=1e-15)  # +x, paused (still +x), then +y
    fixed = normals_at(traj, (0.0, 0.0, 2.0), np.array([5.0, 13.0]))
    np.testing.assert_allclose(fixed, [[0, 0, 1], [0, 0, 1]])


def test_table_trajectory_by_hand():
    traj = TrajectorySpec(
        device="rx", times_s=[0, 10], positions=[(0, 0, 0), (2, 1, 0)], normals=[(0, 0, 1), (1, 0, 0)]
    )
    np.testing.assert_allclose(positions_at(traj, np.array([-1.0, 5.0, 11.0])), [[0, 0, 0], [1, 0.5, 0], [2, 1, 0]])
    s = 1 / math.sqrt(2)
    np.testing.assert_allclose(normals_at(traj, (0, 0, 1), np.array([5.0])), [[s, 0, s]])


def test_a_walking_receiver_in_a_static_room_is_one_run():
    doc = room_doc(paths=2000, max_reflections=1, rx=(1.0, 1.0, 0.5))
    doc["timeline"] = {
        "times_s": [0.0, 2.0, 4.0],
        "trajectories": [{"device": "rx", "waypoints": [[1, 1, 0.5], [3, 1, 0.5]], "speed_m_s": 0.5}],
    }
    result = run_timeline(spec(doc))
    link = result.timeline.links[0]
    np.testing.assert_allclose(link.receiver_position, [[1, 1, 0.5], [2, 1, 0.5], [3, 1, 0.5]])
    # the line of sight in closed form at each position: tx at (2.5, 2.5, 3) facing down, m = 1, A = 1e-4
    for (x, y, z), los in zip(link.receiver_position, link.los_gain):
        d2 = (x - 2.5) ** 2 + (y - 2.5) ** 2 + (3 - z) ** 2
        assert los == pytest.approx(2 / (2 * math.pi * d2) * 1e-4 * ((3 - z) ** 2 / d2), rel=1e-12)
    assert result.timeline.method == "one_run" and len(result.links) == 3  # the result: every time's receivers


def _doc_with(timeline, medium=None):
    doc = room_doc()
    doc["timeline"] = timeline
    if medium is not None:
        doc["medium"] = medium
    return copy.deepcopy(doc)


FRAMES = {
    "type": "inline",
    "times": [0, 10],
    "min": [0, 0, 0],
    "max": [5, 5, 3],
    "shape": [1, 1, 1],
    "sigma_a": [0, 1],
    "sigma_s": [0, 0],
}


@pytest.mark.parametrize(
    "timeline,medium,message",
    [
        ({"frames": FRAMES}, {"type": "homogeneous", "sigma_a": 0.1, "sigma_s": 0.1}, "remove the static `medium`"),
        ({"frames": FRAMES, "times_s": [5, 20]}, None, r"lie outside the frames' times 0\.\.10 s"),
        (
            {"times_s": [0, 1], "trajectories": [{"device": "nobody", "times_s": [0], "positions": [[1, 1, 1]]}]},
            None,
            r"trajectories\[0\] \(nobody\): no receiver",
        ),
        (
            {"times_s": [0, 1], "trajectories": [{"device": "tx", "times_s": [0], "positions": [[1, 1, 1]]}]},
            None,
            "moving transmitters",
        ),
        (
            {
                "times_s": [0, 1],
                "trajectories": [{"device": "rx", "waypoints": [[1, 1, 1], [9, 1, 1]], "speed_m_s": 1}],
            },
            None,
            "outside the room",
        ),
        (
            {"times_s": [0, 1], "trajectories": [{"device": "rx", "waypoints": [[1, 1, 1], [2, 1, 1]]}]},
            None,
            "need `speed_m_s`",
        ),
        ({"times_s": [0, 1]}, None, "needs `frames`"),
        ({"frames": FRAMES, "outage": {"quantity": "ber", "threshold": 0.7}}, None, "ber threshold"),
    ],
)
def test_bad_timelines_are_refused_with_located_messages(timeline, medium, message):
    with pytest.raises(ValidationError, match=message):
        spec(_doc_with(timeline, medium))


def _walker_doc(method, seed=7):
    doc = room_doc(**{**SMOKY, "seed": seed, "paths": 4000}, rx=(1.0, 1.0, 0.5))
    doc["receivers"].append({"id": "desk", "position": [4.0, 4.0, 0.8], "normal": [0, 0, 1], "area": 1e-4})
    doc["timeline"] = {
        "frames": {
            "type": "inline",
            "times": [0.0, 20.0],
            "min": [0, 0, 0],
            "max": [5, 5, 3],
            "shape": [1, 1, 2],
            "sigma_a": [0.05, [0.05, 0.2]],
            "sigma_s": [0.1, [0.1, 0.25]],
        },
        "times_s": [0.0, 10.0, 20.0],
        "trajectories": [{"device": "rx", "waypoints": [[1, 1, 0.5], [4, 1, 0.5]], "speed_m_s": 0.1}],
        "method": method,
    }
    return spec(doc)


def test_a_reweighted_timeline_agrees_with_independent_runs_and_its_differences_are_sharper():
    """method reweighted (one set of paths, frame ratios; engine/run/frames_reweighted.py) through the whole
    timeline, a walker and a static receiver in smoke frames: every time's H0 within 4 sigma of the
    independent runs' (each its own error; a 10 %-off reference fails), the static receiver's frame-to-frame
    differences with a smaller error than the independent runs' combined errors."""
    rew = run_timeline(_walker_doc("reweighted")).timeline
    ind = run_timeline(_walker_doc("independent", seed=11)).timeline
    assert rew.method == "reweighted" and ind.method == "independent"
    for rx in ("rx", "desk"):
        a, b = rew.link("tx", rx), ind.link("tx", rx)
        np.testing.assert_allclose(a.receiver_position, b.receiver_position)
        h_a, h_b = np.array(a.dc_gain), np.array(b.dc_gain)
        s = np.hypot(a.dc_gain_stderr, b.dc_gain_stderr)
        assert np.all(np.abs(h_a - h_b) < 4 * s), (rx, h_a, h_b, s)
        assert np.any(np.abs(h_a - 1.1 * h_b) > 4 * s), rx  # the power to see a 10 % error
        assert np.all(np.array(a.los_gain) == np.array(b.los_gain))  # exact through each frame in both
    desk_rew, desk_ind = rew.link("tx", "desk"), ind.link("tx", "desk")
    combined = np.hypot(desk_ind.dc_gain_stderr[1:], desk_ind.dc_gain_stderr[:-1])
    assert np.all(np.array(desk_rew.dc_gain_diff_stderr) < combined), (desk_rew.dc_gain_diff_stderr, combined)


def test_a_walker_in_frames_is_each_time_a_run_of_that_frame_with_the_receiver_there():
    """Smoke frames and a moving receiver on one time axis: time i's link is, bit for bit, the run of the
    medium at t_i (frames interpolated) with the receiver placed where the trajectory puts it then."""
    doc = room_doc(**SMOKY, rx=(1.0, 1.0, 0.5))
    doc["receivers"].append({"id": "desk", "position": [4.0, 4.0, 0.8], "normal": [0, 0, 1], "area": 1e-4})
    doc["timeline"] = {
        "frames": {
            "type": "inline",
            "times": [0.0, 20.0],
            "min": [0, 0, 0],
            "max": [5, 5, 3],
            "shape": [1, 1, 2],
            "sigma_a": [0.05, [0.05, 0.4]],
            "sigma_s": [0.1, [0.1, 0.3]],
        },
        "times_s": [0.0, 10.0, 20.0],
        "trajectories": [
            {"device": "rx", "waypoints": [[1, 1, 0.5], [4, 1, 0.5]], "speed_m_s": 0.1, "orientation": "heading"}
        ],
        "method": "independent",
    }
    sp = spec(doc)
    result = run_timeline(sp)
    tl = result.timeline
    walker, desk = tl.link("tx", "rx"), tl.link("tx", "desk")
    np.testing.assert_allclose(walker.receiver_position, [[1, 1, 0.5], [2, 1, 0.5], [3, 1, 0.5]])
    assert desk.receiver_position == [(4.0, 4.0, 0.8)] * 3
    frames = frames_at(_inline(sp), np.array([0.0, 10.0, 20.0]))
    for i, x in enumerate((1.0, 2.0, 3.0)):
        moved = [sp.receivers[0].model_copy(update={"position": (x, 1.0, 0.5)}), sp.receivers[1]]
        alone = simulate(
            sp.model_copy(update={"medium": frame_medium(frames, i), "timeline": None, "receivers": moved})
        )
        assert alone.links[0].dc_gain == walker.dc_gain[i] and alone.links[1].dc_gain == desk.dc_gain[i]
        assert alone.links[0].dc_gain_stderr == walker.dc_gain_stderr[i]
    assert all(d is not None and d > 0 for d in walker.dc_gain_diff_stderr + desk.dc_gain_diff_stderr)
    assert len(result.links) == 2  # the first time's run: the desk and the walker at t = 0


def _inline(sp):
    from owcsim.engine.media.frame_sources import frames_from_spec

    return frames_from_spec(sp.timeline.frames)


def test_auto_settings_are_resolved_once_on_the_heaviest_frame():
    doc = room_doc()
    for key in ("algorithm", "max_reflections", "t_max_s", "paths"):
        doc["simulation"].pop(key)
    doc["simulation"]["target_rel_error"] = 0.05
    sp = spec(doc)
    frames = _random_frames(2)
    frames = MediumFrames(frames.times, frames.lo, frames.hi, frames.sigma_a * [[[[0.5]]], [[[2.0]]]], frames.sigma_s)
    out = simulate_frames(sp, frames)
    resolved = out.results[0].scene.simulation  # frame 0 ran with the settings frame 1 (heavier) chose
    assert resolved.is_resolved and not out.results[1].scene.simulation.is_resolved
    again = simulate(sp.model_copy(update={"simulation": resolved, "medium": frame_medium(frames, 1)}))
    assert _links(again) == _links(out.results[1])  # the heavy frame's auto run is the resolved run, bit for bit


def test_auto_reweights_from_three_times_and_runs_grids_and_short_timelines_on_their_own():
    from owcsim.engine.run.frames import FrameMethod
    from owcsim.engine.run.timeline import frames_method

    walker = _walker_doc("auto")
    assert frames_method(walker, 3) is FrameMethod.INDEPENDENT  # a moving receiver shares no paths between times
    doc = walker.model_dump(mode="json", by_alias=True, exclude_none=True)
    doc["timeline"].pop("trajectories")
    sp = spec(doc)
    assert frames_method(sp, 3) is FrameMethod.REWEIGHTED and frames_method(sp, 2) is FrameMethod.INDEPENDENT
    doc["receiver_grids"] = [{"origin": [1, 1, 0.8], "size": [2, 2], "shape": [2, 2], "area": 1e-4}]
    assert frames_method(spec(doc), 3) is FrameMethod.INDEPENDENT
    assert run_timeline(sp).timeline.method == "reweighted"


@pytest.mark.parametrize(
    "waypoints,refused",
    [
        ([[1, 2.5, 0.5], [4, 2.5, 0.5]], True),  # straight through the desk (its interior at t = 5 s)
        ([[1, 2.5, 0.5], [2.5, 2.5, 0.5]], True),  # ends inside it
        ([[1, 2.5, 0.8], [4, 2.5, 0.8]], False),  # slides over its top face
        ([[1, 1.5, 0.5], [4, 1.5, 0.5]], False),  # passes beside it
        ([[1, 1.5, 0.5], [4, 3.5, 0.5]], True),  # diagonal: through its middle
    ],
)
def test_a_trajectory_through_furniture_is_refused_before_the_run(waypoints, refused):
    """A walker's leg that crosses a furniture box's interior (review of issue 26): before, the document was
    accepted, every time ran, and the result failed to build (a receiver copy inside the box)."""
    doc = room_doc(paths=500, rx=(1.0, 2.5, 0.5))
    doc["furniture"] = [{"min": [2.0, 2.0, 0.0], "max": [3.0, 3.0, 0.8], "reflectance": 0.5, "name": "desk"}]
    doc["timeline"] = {
        "times_s": [0.0, 5.0],
        "trajectories": [{"device": "rx", "waypoints": waypoints, "speed_m_s": 0.3}],
    }
    if refused:
        with pytest.raises(
            ValidationError, match=r"trajectories\[0\] \(rx\): the leg .* passes through furniture\[0\] \(desk\)"
        ):
            spec(doc)
    else:
        spec(doc)


def test_opposite_consecutive_normals_are_refused():
    """Normals interpolated linearly then normalized: between opposite rows the mean is the zero vector
    (review of issue 26: before, the receiver's normal at the midpoint was NaN)."""
    row = {"device": "rx", "times_s": [0, 2], "positions": [[1, 1, 1], [1, 1, 1]]}
    with pytest.raises(ValidationError, match=r"`normals` rows 0 and 1 are opposite"):
        TrajectorySpec(**row, normals=[[1, 0, 0], [-2, 0, 0]])
    turn = TrajectorySpec(
        device="rx", times_s=[0, 1, 2], positions=[[1, 1, 1]] * 3, normals=[[1, 0, 0], [0, 1, 0], [-1, 0, 0]]
    )
    n = normals_at(turn, (0, 0, 1), np.linspace(0, 2, 9))
    assert np.all(np.isfinite(n)) and np.allclose(np.linalg.norm(n, axis=1), 1.0)


def test_a_walker_turned_into_a_wall_is_refused_before_any_run(monkeypatch):
    """Heading orientation along the west wall (x = 0) turns the normal (0, 1, 0) of the walker's frame to
    (-1, 0, 0): into the wall (review of issue 26). Before, every time ran and the result then failed to build
    (a pydantic error naming the copy rx@t0); now a SceneError names the trajectory and the time, before any run."""
    import owcsim.engine.run.timeline as tl_mod

    def no_run(*args, **kwargs):
        raise AssertionError("the timeline ran")

    monkeypatch.setattr(tl_mod, "simulate", no_run)
    doc = room_doc(paths=500, rx=(0.0, 1.0, 1.0), rx_normal=(0, 1, 0))
    walk = {"device": "rx", "waypoints": [[0, 1, 1], [0, 4, 1]], "speed_m_s": 1.0, "orientation": "heading"}
    doc["timeline"] = {"times_s": [0.0, 2.0], "trajectories": [walk]}
    with pytest.raises(SceneError, match=r"trajectories \(rx\): at t = 0 s the receiver sits on a room face at x = 0"):
        run_timeline(spec(doc))
