"""MediumFrames (engine/media/frames.py): a frame is the static grid, bit for bit; bad frames are refused."""

import numpy as np
import pytest

from owcsim.engine.media.frames import MediumFrames
from owcsim.engine.media.grid import GridMedium


def _frames(n=3):
    rng = np.random.default_rng(1)
    a = rng.uniform(0, 0.5, (n, 4, 3, 2))
    s = rng.uniform(0, 0.5, (n, 4, 3, 2))
    return MediumFrames(np.arange(n) * 5.0, [0, 0, 0], [6, 4, 3], a, s), a, s


def test_frame_is_the_static_grid():
    frames, a, s = _frames()
    o = np.array([[0.1, 0.2, 0.3], [5.0, 3.5, 2.9]])
    d = np.array([[1.0, 0.5, 0.2], [-1.0, -1.0, -0.5]])
    d /= np.linalg.norm(d, axis=1)[:, None]
    L = np.array([5.0, 4.0])
    for f in range(frames.n_frames):
        static = GridMedium([0, 0, 0], [6, 4, 3], (4, 3, 2), a[f].ravel(), s[f].ravel())
        assert np.array_equal(frames.frame(f).optical_depth(o, d, L), static.optical_depth(o, d, L))
    assert frames.select([0, 2]).n_frames == 2
    assert frames.shape == (4, 3, 2)


def test_bad_frames_are_refused():
    frames, a, s = _frames()
    with pytest.raises(ValueError, match="strictly increasing"):
        MediumFrames([0.0, 0.0, 1.0], [0, 0, 0], [6, 4, 3], a, s)
    with pytest.raises(ValueError, match="F = 2"):
        MediumFrames([0.0, 1.0], [0, 0, 0], [6, 4, 3], a, s)
    with pytest.raises(ValueError, match="finite"):
        MediumFrames([0.0, 1.0, 2.0], [0, 0, 0], [6, 4, 3], a * np.nan, s)
