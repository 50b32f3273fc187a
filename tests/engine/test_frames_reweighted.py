"""Frames by reweighting (engine/run/frames_reweighted.py, engine/media/frame_ratios.py; issue 26 item 4).

References are independent plain runs of each frame (`simulate` on the document holding that frame's
grid, other seeds), compared within 4 sigma of the combined standard errors; each comparison has a
power check (a reference 10 % off fails). Fixed seeds throughout.
"""

import math

import numpy as np
import pytest

from owcsim.engine.core.errors import SceneError
from owcsim.engine.media.frame_ratios import FrameRatios, carrier_grid, effective_fraction
from owcsim.engine.media.frames import MediumFrames
from owcsim.engine.run import frames_reweighted as fr
from owcsim.engine.run.frames_reweighted import simulate_reweighted
from owcsim.engine.run.simulate import simulate
from tests.scenes import room_doc, spec

SHAPE = (5, 5, 3)  # 1 m cells over the 5 x 5 x 3 m room
LO, HI = [0.0, 0.0, 0.0], [5.0, 5.0, 3.0]


def _frames(sigma_a, sigma_s, phase=None) -> MediumFrames:
    kw = {} if phase is None else {"phase": phase}
    return MediumFrames(np.arange(len(sigma_a)) * 10.0, LO, HI, np.asarray(sigma_a), np.asarray(sigma_s), **kw)


def _layer(depth_cells: int, value: float) -> np.ndarray:
    """A ceiling layer: the top `depth_cells` cells in z hold `value` [1/m], the rest 0."""
    out = np.zeros(SHAPE)
    if depth_cells:
        out[:, :, SHAPE[2] - depth_cells :] = value
    return out


def _doc(algorithm=5, paths=8192, seed=2, **kw):
    sim = {"max_scattering": 3 if algorithm == 5 else (1 if algorithm > 1 else 0), "max_reflections": 2}
    sim.update(kw)
    return spec(room_doc(algorithm=algorithm, paths=paths, seed=seed, **sim))


def _plain(doc, frames, f, seed, paths=None):
    return simulate(fr._with_medium(doc, frames, f).model_copy(update={"simulation": _seeded(doc, seed, paths)}))


def _seeded(doc, seed, paths=None):
    return doc.simulation.model_copy(update={"seed": seed, "paths": paths or doc.simulation.paths})


def _agree(a, sa, b, sb, k=4.0):
    return abs(a - b) <= k * math.hypot(sa, sb)


# --- the ratio part ----------------------------------------------------------------------------------------------
def test_depths_of_every_frame_equal_each_frame_walked_alone():
    rng = np.random.default_rng(3)
    a, s = rng.uniform(0, 0.5, (4,) + SHAPE), rng.uniform(0, 0.5, (4,) + SHAPE)
    frames = _frames(a, s)
    ratios = FrameRatios(frames, carrier_grid(frames))
    o = rng.uniform(0, 1, (200, 3)) * HI
    d = rng.normal(size=(200, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    L = rng.uniform(0, 7, 200)
    tau = ratios.depths((o, d, L))
    for f in range(4):
        assert np.array_equal(tau[:, f], frames.frame(f).optical_depth(o, d, L))
    assert np.array_equal(tau[:, -1], carrier_grid(frames).optical_depth(o, d, L))
    # T_f / T_c and sigma_s,f / sigma_s,c at the end of the segments
    r = ratios.scatter(np.ones((4, 200)), np.zeros(200), (o, d, L))
    end = o + L[:, None] * d
    inside = np.all((end >= LO) & (end <= HI), axis=1)
    for f in range(4):
        want = np.exp(-(tau[:, f] - tau[:, -1])) * frames.frame(f).sigma_s_at(end)
        want = np.where(inside, want / np.where(inside, carrier_grid(frames).sigma_s_at(end), 1.0), 0.0)
        assert np.allclose(r[f], want, rtol=1e-12, atol=0)


def test_support_condition_and_bad_input_are_refused():
    s = np.stack([_layer(1, 0.3), _layer(2, 0.3)])
    frames = _frames(np.zeros_like(s), s)
    clear_carrier = frames.frame(0)  # does not scatter in the layer frame 1 adds
    with pytest.raises(ValueError, match="support condition"):
        FrameRatios(frames, clear_carrier)
    doc = _doc()
    with pytest.raises(SceneError, match="frame_of_receiver"):
        simulate_reweighted(doc, frames, frame_of_receiver=np.array([5]))
    spectral = spec(
        {**room_doc(algorithm=5, paths=1024), "spectral": {"band_edges": [400e-9, 500e-9, 600e-9]}},
    )
    with pytest.raises(SceneError, match="spectral scene"):
        simulate_reweighted(spectral, frames)


def test_effective_fraction():
    assert np.allclose(effective_fraction(np.array([0.5]), np.array([[0.5], [2.0]]))[:, 0], [1.0, 0.5])


# --- one frame, and a frame that is the carrier: the plain run ---------------------------------------------------
def test_one_frame_equals_the_plain_run_bit_for_bit():
    rng = np.random.default_rng(5)
    frames = _frames(rng.uniform(0, 0.1, (1,) + SHAPE), rng.uniform(0, 0.4, (1,) + SHAPE))
    doc = _doc(algorithm=5)
    (res,), groups, _ = simulate_reweighted(doc, frames)
    plain = simulate(fr._with_medium(doc, frames, 0))
    a, b = res.links[0], plain.links[0]
    assert a.dc_gain == b.dc_gain and a.dc_gain_stderr == b.dc_gain_stderr and a.los_gain == b.los_gain
    assert a.cir.total == b.cir.total
    assert groups is not None and groups.shape == (1, 1, 16)
    assert groups[0, 0].mean() == pytest.approx(a.dc_gain, rel=1e-9)


def test_a_frame_that_is_the_carrier_gives_its_plain_run(monkeypatch):
    """Dyadic coefficients: frame 1 is exactly the mean of the three, so the carrier is frame 1 itself (one window:
    the window rules switched off)."""
    monkeypatch.setattr(fr, "MAX_DEPTH_SPREAD", math.inf)
    monkeypatch.setattr(fr, "PILOT_PATHS", 0)
    rng = np.random.default_rng(6)
    a0, a1 = rng.integers(0, 8, SHAPE) / 64, rng.integers(0, 8, SHAPE) / 64
    s0, s1 = rng.integers(1, 32, SHAPE) / 64, rng.integers(1, 32, SHAPE) / 64
    a = np.stack([a0 + 0.125, a1 + 0.125, 2 * a1 - a0 + 0.125])
    frames = _frames(a, np.stack([s0 + 0.5, s1 + 0.5, 2 * s1 - s0 + 0.5]))
    assert np.array_equal(frames.sigma_a.mean(axis=0), frames.sigma_a[1])
    assert np.array_equal(frames.sigma_s.mean(axis=0), frames.sigma_s[1])
    doc = _doc(algorithm=5)
    res, _, _ = simulate_reweighted(doc, frames)
    plain = simulate(fr._with_medium(doc, frames, 1))
    assert res[1].links[0].dc_gain == pytest.approx(plain.links[0].dc_gain, rel=1e-12)
    assert res[1].links[0].dc_gain_stderr == pytest.approx(plain.links[0].dc_gain_stderr, rel=1e-12)


# --- frames against independent runs ------------------------------------------------------------------------------
def _one_window(monkeypatch):
    """The window rules off: every frame reweighted from one carrier (the ratio rows do all the work)."""
    monkeypatch.setattr(fr, "MAX_DEPTH_SPREAD", math.inf)
    monkeypatch.setattr(fr, "PILOT_PATHS", 0)


def _check_against_plain(doc, frames, seed=101, ref_paths=None):
    res, _, _ = simulate_reweighted(doc, frames)
    for f in range(frames.n_frames):
        a = res[f].links[0]
        b = _plain(doc, frames, f, seed + f, ref_paths).links[0]
        assert a.los_gain == pytest.approx(b.los_gain, rel=1e-12)
        mc_a, mc_b = a.dc_gain - a.los_gain, b.dc_gain - b.los_gain
        assert _agree(mc_a, a.dc_gain_stderr, mc_b, b.dc_gain_stderr), (f, mc_a, mc_b)
        # power: a reference 10 % off is told apart
        assert not _agree(mc_a, a.dc_gain_stderr, 1.1 * mc_b, b.dc_gain_stderr), (f, mc_a, mc_b)
    return res


def test_absorption_only_frames_agree_with_independent_runs(monkeypatch):
    """Absorption grows everywhere and most in a ceiling layer; the same scattering in every frame."""
    _one_window(monkeypatch)
    s = _layer(3, 0.05)
    a = np.stack([_layer(1, 0.2) + 0.02, _layer(2, 0.3) + 0.1, _layer(3, 0.4) + 0.2])
    _check_against_plain(_doc(algorithm=5, paths=16384), _frames(a, np.stack([s, s, s])))


@pytest.mark.slow
def test_frames_in_windows_agree_with_independent_runs():
    """The default window rules on frames from clear to thick smoke."""
    t = np.stack([_layer(1, 0.05), _layer(2, 0.6), _layer(3, 1.5)])
    _check_against_plain(_doc(algorithm=5, paths=8192), _frames(t * 0.5, t * 0.5), ref_paths=32768)


@pytest.mark.parametrize("algorithm", [1, *(pytest.param(a, marks=pytest.mark.slow) for a in (2, 3, 4)), 5])
def test_scattering_frames_agree_with_independent_runs(algorithm, monkeypatch):
    """A small grid whose albedo goes 0.5 -> 0.9 and whose ceiling layer thickens."""
    _one_window(monkeypatch)
    rng = np.random.default_rng(algorithm)
    t = np.stack([_layer(2, 0.3) + 0.1, _layer(2, 0.5) + 0.15, _layer(3, 0.6) + 0.2]) * rng.uniform(0.8, 1.2, SHAPE)
    albedo = np.array([0.5, 0.7, 0.9])[:, None, None, None]
    frames = _frames(t * (1 - albedo), t * albedo, phase={"type": "hg", "g": 0.5})
    paths = 16384 if algorithm in (2, 3, 4) else 8192
    _check_against_plain(_doc(algorithm=algorithm, paths=paths), frames)


# --- errors of differences ----------------------------------------------------------------------------------------
def _difference_run(seed):
    a = np.stack([_layer(2, 0.3), _layer(2, 0.33)])
    s = np.stack([_layer(2, 0.3), _layer(2, 0.31)]) + 0.02
    frames = _frames(a, s)
    res, groups, _ = simulate_reweighted(_doc(algorithm=5, paths=2048, seed=seed, max_reflections=2), frames)
    d_g = groups[1, 0] - groups[0, 0]
    return res[1].links[0].dc_gain - res[0].links[0].dc_gain, d_g.std(ddof=1) / math.sqrt(len(d_g)), res


@pytest.mark.slow
def test_difference_errors_from_shared_groups_match_the_seed_spread():
    runs = [_difference_run(seed) for seed in range(30)]
    diffs = np.array([r[0] for r in runs])
    reported = np.sqrt(np.mean([r[1] ** 2 for r in runs]))
    ratio = reported / diffs.std(ddof=1)
    assert 0.7 <= ratio <= 1.4, ratio
    # much smaller than independent runs' errors of the two frames
    res = runs[0][2]
    independent = math.hypot(res[0].links[0].dc_gain_stderr, res[1].links[0].dc_gain_stderr)
    assert reported < 0.25 * independent, (reported, independent)


def test_difference_error_is_much_smaller_than_independent_errors():
    _, se, res = _difference_run(3)
    assert se < 0.25 * math.hypot(res[0].links[0].dc_gain_stderr, res[1].links[0].dc_gain_stderr)


# --- receivers of one frame, windows -----------------------------------------------------------------------------
def test_frame_of_receiver_tallies_each_receiver_in_its_frame_only():
    doc = _doc(algorithm=5, paths=4096)
    two = doc.model_copy(
        update={
            "receivers": [
                doc.receivers[0],
                doc.receivers[0].model_copy(update={"id": "rx2", "position": (3.0, 2.0, 0.0)}),
            ]
        }
    )
    a = np.stack([_layer(1, 0.2), _layer(2, 0.3)])
    frames = _frames(a, a)
    res, _, _ = simulate_reweighted(two, frames, frame_of_receiver=np.array([0, 1]))
    full, _, _ = simulate_reweighted(two, frames)
    # receiver 0 in frame 0 and receiver 1 in frame 1: the same estimates as without the restriction
    assert res[0].links[0].dc_gain == pytest.approx(full[0].links[0].dc_gain, rel=1e-12)
    assert res[1].links[1].dc_gain == pytest.approx(full[1].links[1].dc_gain, rel=1e-12)
    # the others: line of sight only
    assert res[0].links[1].dc_gain == res[0].links[1].los_gain
    assert res[1].links[0].dc_gain == res[1].links[0].los_gain


def test_frames_far_from_their_carrier_are_split_into_windows(monkeypatch):
    a = np.stack([_layer(0, 0.0) + 0.01, _layer(3, 3.0), _layer(3, 3.0) + 0.01, _layer(3, 0.02)])
    frames = _frames(a, a * 0.5)
    doc = _doc(algorithm=5, paths=2048)
    windows = fr._windows(doc, frames, None, None)
    assert len(windows) > 1 and sorted(np.concatenate(windows).tolist()) == [0, 1, 2, 3]
    monkeypatch.setattr(fr, "MAX_DEPTH_SPREAD", math.inf)  # the probe rule off: the pilot alone splits
    assert len(fr._windows(doc, frames, None, None)) > 1
    monkeypatch.setattr(fr, "MIN_EFFECTIVE_FRACTION", 0.0)  # neither rule: one window
    assert len(fr._windows(doc, frames, None, None)) == 1


def test_depth_windows_rule():
    tau = np.array([[0.0, 0.2, 0.4, 2.0, 2.1, 5.0]])
    assert [w.tolist() for w in fr.depth_windows(tau, 0.5)] == [[0, 1, 2], [3, 4], [5]]
    assert [w.tolist() for w in fr.depth_windows(tau, 0.15)] == [[0, 1], [2], [3, 4], [5]]
